#!/usr/bin/env bash
# Self-shadowing benchmark over several models in one run: Table 1 of Kautz,
# Lehtinen and Aila 2004 (vertices, triangles, low-res triangles, blockers a
# vertex without and with the per-vertex PVS, frames a second without and
# with it, mean relative L2 error against converged Monte Carlo, and how many
# times faster than Embree Monte Carlo at the same error) and Table 2 (share
# of a frame in rasterization, integration, transform, other), one row per
# model, from `vistream-client-bench --shadows --json`, then the glossy
# transfer's row per model (error and speed against its own Monte Carlo
# reference). Usage:
#   tests/benchmarks/shadow_tables.sh [MODEL:SUBDIVIDE[:BY] ...]
# The default models are the Fox, the Fox split at centroids three times
# (7,778 vertices, near the paper's 8,636-vertex Hand), the Fox subdivided
# twice at midpoints, and the built-in walker plain and subdivided three
# times. MODEL is a skinned glTF or "walker"; BY is 4 (midpoints, the
# default) or 3 (centroids); a row's "1:3 x3" is three splits into three.
# QUICK=1 passes --quick (fewer knobs and rays: a smoke test). The JSON of
# each run goes to WORK (default build/shadow_tables).
set -euo pipefail
cd "$(dirname "$0")/../.."
bin=${BIN:-build/bin}
work=${WORK:-build/shadow_tables}
fox=${VISTREAM_SHARED_DIR:-../shared}/data/Fox.glb
models=("$@")
[ ${#models[@]} -gt 0 ] || models=("$fox:0" "$fox:3:3" "$fox:2" "walker:0" "walker:3")
mkdir -p "$work"
jsons=()
for spec in "${models[@]}"; do
  IFS=: read -r model subdivide by <<< "$spec"
  out="$work/$(basename "$model" .glb)_${subdivide:-0}_${by:-4}.json"
  echo "shadow_tables: $model, subdivide ${subdivide:-0} by ${by:-4}" >&2
  "$bin/vistream-client-bench" --shadows --model "$model" --subdivide "${subdivide:-0}" \
    --subdivide-by "${by:-4}" ${QUICK:+--quick} --json --log-level warn > "$out"
  jsons+=("$out")
done
python3 - "${jsons[@]}" <<'PY'
import json, os, sys
rows = [json.load(open(f)) for f in sys.argv[1:]]
def name(d):
    base = os.path.splitext(os.path.basename(d["model"]))[0]
    if d["subdivide"]:
        base += " 1:%d x%d" % (d.get("subdivide_by", 4), d["subdivide"])
    return base
print("Table 1 (in parentheses: with the per-vertex PVS)")
print("%-14s %8s %9s %8s %15s %17s %15s %17s" % ("model", "vertices", "triangles", "low-res",
      "blockers/vertex", "frames a second", "L2 error", "faster than MC"))
for d in rows:
    p = d["with_pvs"]
    print("%-14s %8d %9d %8s %6.1f (%6.1f) %7.1f (%7.1f) %5.2f%% (%5.2f%%) %6.1fx (%6.1fx)" % (
        name(d), d["vertices"], d["triangles"], d["lowres_triangles"] or "-",
        d["blockers_per_vertex"], p["blockers_per_vertex"], d["fps"], p["fps"],
        100 * d["l2_error"], 100 * p["l2_error"], d["speedup_vs_mc"], p["speedup_vs_mc"]))
print("\nTable 2 (share of a frame, without the PVS)")
print("%-14s %13s %11s %9s %6s" % ("model", "rasterization", "integration", "transform", "other"))
for d in rows:
    b = d["breakdown"]
    print("%-14s %12.1f%% %10.1f%% %8.1f%% %5.1f%%" % (name(d), 100 * b["rasterization"],
          100 * b["integration"], 100 * b["transform"], 100 * b["other"]))
glossy = [d for d in rows if "glossy" in d]
if glossy:
    print("\nGlossy transfer (Phong lobe about the figure's viewer, front-facing vertices)")
    print("%-14s %8s %7s %10s %13s %9s %15s %17s" % ("model", "exponent", "facing", "masks ms",
          "integrate ms", "L2 error", "faster than MC", "integration only"))
    for d in glossy:
        g = d["glossy"]
        print("%-14s %8g %7d %10.2f %13.2f %8.2f%% %14.1fx %16.1fx" % (name(d), g["exponent"],
              g["facing_vertices"], g["masks_ms_per_frame"], g["integrate_ms_per_frame"],
              100 * g["l2_error"], g["speedup_vs_mc"], g["speedup_vs_mc_integration_only"]))
PY
echo "shadow_tables: ${#jsons[@]} models, done" >&2
