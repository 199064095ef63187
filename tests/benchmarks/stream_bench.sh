#!/usr/bin/env bash
# Streaming benchmark: for each (scene, policy, radius, clients) the server
# is started on loopback, vistream-loadtest walks the clients along one
# generated path (each starting at a different point of it) at speed 1.0,
# and one row is printed. Policies are compared at equal radius in the same
# run. Usage:
#   tests/benchmarks/stream_bench.sh [SCENE] [CLIENTS] [DURATION_S] [RADII]
# e.g. tests/benchmarks/stream_bench.sh city1 500 40 "100 200 400 800"
# Extra server options via SERVER_ARGS (e.g. SERVER_ARGS="--cell-size 4").
set -euo pipefail
cd "$(dirname "$0")/../.."
bin=build/bin
scene=${1:-city1}
clients=${2:-100}
duration=${3:-30}
radii=${4:-"100 200 400"}
work=build/stream_bench
mkdir -p "$work"
"$bin/vistream-scene" path --scene "$scene" --frames 2700 --seed 3 --out "$work/$scene.csv" --log-level warn
printf "%-8s %-10s %7s %8s %14s %12s %22s %10s %12s %7s %12s\n" scene policy radius clients "bytes/client/s" "bytes/face" \
  "CellReady p50/p95/p99" misses checks errors "CPU ms/s/cl"
for radius in $radii; do
  for policy in visibility radius; do
    rm -f "$work/port"
    "$bin/vistream-server" --scene "$scene" --policy "$policy" --radius "$radius" --port 0 --port-file "$work/port" ${SERVER_ARGS:-} \
      --log-level warn > "$work/server_${policy}_${radius}.log" 2>&1 &
    server=$!
    for _ in $(seq 1 600); do [ -s "$work/port" ] && break; kill -0 $server 2>/dev/null || break; sleep 0.25; done
    "$bin/vistream-loadtest" --port "$(cat "$work/port")" --clients "$clients" --path "$work/$scene.csv" \
      --duration "$duration" --scene "$scene" --no-avatars --log-level warn --json > "$work/result.json" || true
    kill -INT $server; wait $server || true
    python3 - "$work/result.json" "$scene" "$policy" "$radius" <<'PY'
import json, sys
d = json.load(open(sys.argv[1])); lat = d["cell_ready_latency_ms"]
f = lambda v: "-" if v is None else f"{v:.1f}"
cpu = d["server_cpu_ms_per_s_per_client"]
print(f"{sys.argv[2]:<8} {sys.argv[3]:<10} {sys.argv[4]:>7} {d['clients']:>8} {d['bytes_per_client_per_s']:>14.0f} "
      f"{d['bytes_per_face']:>12.1f} {f(lat['p50'])+'/'+f(lat['p95'])+'/'+f(lat['p99']):>22} {d['visibility_misses']:>10} "
      f"{d['frames_checked']:>12} {d['errors']:>7} {('-' if cpu is None else f'{cpu:.2f}'):>12}")
PY
  done
done
