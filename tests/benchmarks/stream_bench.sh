#!/usr/bin/env bash
# Streaming benchmark: for each radius the server is started on loopback
# once per policy (visibility, radius), vistream-loadtest walks the clients
# along one generated path (each starting at a different point of it) at
# speed 1.0, and one row prints both policies side by side: faces and bytes
# per client per second, bytes per face, misses, and how many times fewer
# bytes the visibility policy sent; then, per policy, bytes per client per
# second by message type and bytes per face in Geometry frames alone. Usage:
#   tests/benchmarks/stream_bench.sh [SCENE] [CLIENTS] [DURATION_S] [RADII]
# e.g. tests/benchmarks/stream_bench.sh city1 500 40 "100 200 400 800"
#      tests/benchmarks/stream_bench.sh ../shared/data/delfshaven.obj 40 20 200
# SCENE is a built-in name or a scene file. Extra server options via
# SERVER_ARGS (e.g. SERVER_ARGS="--cell-size 4"); results go to WORK
# (default build/stream_bench), so two runs can use two directories.
set -euo pipefail
cd "$(dirname "$0")/../.."
bin=${BIN:-build/bin}
scene=${1:-city1}
clients=${2:-100}
duration=${3:-30}
radii=${4:-"100 200 400"}
work=${WORK:-build/stream_bench}
mkdir -p "$work"
name=$(basename "$scene")
name=${name%.*}
"$bin/vistream-scene" path --scene "$scene" --frames 2700 --seed 3 --out "$work/$name.csv" --log-level warn
run() {  # policy radius -> $work/<policy>_<radius>.json
  local policy=$1 radius=$2
  rm -f "$work/port"
  "$bin/vistream-server" --scene "$scene" --policy "$policy" --radius "$radius" --port 0 --port-file "$work/port" ${SERVER_ARGS:-} \
    --log-level "${SERVER_LOG:-warn}" > "$work/server_${policy}_${radius}.log" 2>&1 &
  local server=$!
  for _ in $(seq 1 600); do [ -s "$work/port" ] && break; kill -0 $server 2>/dev/null || break; sleep 0.25; done
  "$bin/vistream-loadtest" --port "$(cat "$work/port")" --clients "$clients" --path "$work/$name.csv" \
    --duration "$duration" --scene "$scene" --no-avatars --log-level warn --json > "$work/${policy}_${radius}.json" || true
  kill -INT $server; wait $server || true
}
printf "%-12s %7s %7s | %-46s | %-46s | %8s\n" scene radius clients \
  "visibility: faces/cl/s bytes/cl/s bytes/face miss" "radius: faces/cl/s bytes/cl/s bytes/face miss" "bytes x"
for radius in $radii; do
  for policy in visibility radius; do run "$policy" "$radius"; done
  python3 - "$work/visibility_${radius}.json" "$work/radius_${radius}.json" "$name" "$radius" <<'PY'
import json, sys
v, r = (json.load(open(p)) for p in sys.argv[1:3])
def cols(d):
    faces = d["faces_received"] / max(1, d["clients"]) / max(1e-9, d["duration_s"])
    return f"{faces:>10.1f} {d['bytes_per_client_per_s']:>11.0f} {d['bytes_per_face']:>10.1f} {d['visibility_misses']:>5}"
ratio = r["bytes_per_client_per_s"] / max(1e-9, v["bytes_per_client_per_s"])
print(f"{sys.argv[3]:<12} {sys.argv[4]:>7} {v['clients']:>7} | {cols(v):<46} | {cols(r):<46} | {ratio:>7.2f}x")
for d, p in ((v, "visibility"), (r, "radius")):
    total = max(1, d.get("bytes_received", 0))
    by_type = sorted(d.get("bytes_by_type", {}).items(), key=lambda kv: -kv[1])
    share = " ".join(f"{k} {b / total * d['bytes_per_client_per_s']:.0f}" for k, b in by_type)
    print(f"  {p:<10} bytes/cl/s by type: {share}; Geometry bytes/face "
          f"{d.get('geometry_bytes_per_face', 0):.1f}, of which lighting "
          f"{d.get('lighting_bytes_per_face', 0):.1f}")
    if d["errors"]:
        print(f"  {p}: {d['errors']} errors, first: {d['first_error']}")
PY
done
