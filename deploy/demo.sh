#!/usr/bin/env bash
# The main job on the built-in default scene: installs what is missing,
# builds Release, generates the default city (city1), prints its statistics
# and the effects it calls for, the sampled visible set of one street view
# cell and its conservative PVS (checked against each other), bakes the PVS
# database of a district and answers a query from it, then runs the main job:
# the streaming server on the city over loopback with simulated users walking
# through it (vistream-loadtest), and prints what they measured.
set -euo pipefail
cd "$(dirname "$0")/.."

deploy/install-deps.sh
cmake --preset release >/dev/null
cmake --build --preset release

bin=build/bin
work=build/demo
mkdir -p "$work"

echo
echo "== 1. generate the default city (city1, seed 1) =="
"$bin/vistream-scene" generate city --preset city1 --seed 1 --out "$work/city1.obj"

echo
echo "== 2. scene statistics and the effects it calls for =="
"$bin/vistream-scene" info "$work/city1.obj"

echo
echo "== 3. a view cell in a street =="
"$bin/vistream-scene" path --scene "$work/city1.obj" --frames 1 --seed 3 --out "$work/start.csv" --log-level warn
IFS=, read -r _ x y z _ _ < <(tail -n 1 "$work/start.csv")
# One quarter of a typical building (about 4 m), from 0.5 m above the ground to eye height.
cell=$(awk -v x="$x" -v y="$y" -v z="$z" 'BEGIN { printf "%.3f,%.3f,%.3f,%.3f,%.3f,%.3f", x-2, y-1.2, z-2, x+2, y, z+2 }')
echo "cell: $cell"

echo
echo "== 4. sampled visible set from that cell (ground truth) =="
"$bin/vistream-scene" visible --scene "$work/city1.obj" --cell "$cell" --points 32 --res 128 --json > "$work/seen.json"
"$bin/vistream-scene" visible --scene "$work/city1.obj" --cell "$cell" --points 32 --res 128 \
  | awk 'NR == 1 { print; next } { n = split($0, ids, " "); printf "face IDs (first 40 of %d): ", n; for (i = 1; i <= n && i <= 40; ++i) printf "%s ", ids[i]; print "" }'

echo
echo "== 5. conservative PVS of the cell (Cohen-Or and Zadicario 1998) =="
"$bin/vistream-pvs" cell --scene "$work/city1.obj" --cell "$cell"
"$bin/vistream-pvs" cell --scene "$work/city1.obj" --cell "$cell" --json > "$work/pvs.json"
python3 - "$work/seen.json" "$work/pvs.json" <<'PY'
import json, sys
seen = set(json.load(open(sys.argv[1]))["faces"])
pvs = set(json.load(open(sys.argv[2]))["faces"])
print(f"  seen faces {len(seen)}, PVS faces {len(pvs)}, seen but not in PVS: {len(seen - pvs)} (must be 0)")
PY

echo
echo "== 6. bake the PVS database of the district around the cell, then query it =="
region=$(awk -v x="$x" -v y="$y" -v z="$z" 'BEGIN { printf "%.3f,%.3f,%.3f,%.3f,%.3f,%.3f", x-60, y-1.5, z-60, x+60, y+0.5, z+60 }')
rm -f "$work/district.db"
"$bin/vistream-pvs" bake --scene "$work/city1.obj" --cell-size 4,2,4 --region "$region" --out "$work/district.db"
"$bin/vistream-pvs" query --db "$work/district.db" --point "$x,$y,$z"

echo
echo "== 7. the main job: stream the city to 20 walking users over loopback =="
"$bin/vistream-scene" path --scene city1 --frames 900 --seed 3 --out "$work/walk.csv" --log-level warn
# Without a database the server computes each cell's PVS when the first user
# enters it, and those users wait. Bake the cells around the walk first (40 m
# beyond it, at eye height: about 500 cells, 10 s on 2 cores); the whole city
# at 4 m is about 100,000 cells, several minutes. Cells the database lacks are
# still computed on demand.
walk_region=$(awk -F, 'NR > 1 { if (n++ == 0) { x0 = x1 = $2; y = $3; z0 = z1 = $4 }
  if ($2 < x0) x0 = $2; if ($2 > x1) x1 = $2; if ($4 < z0) z0 = $4; if ($4 > z1) z1 = $4 }
  END { printf "%.3f,%.3f,%.3f,%.3f,%.3f,%.3f", x0-40, y-1.5, z0-40, x1+40, y+0.5, z1+40 }' "$work/walk.csv")
rm -f "$work/walk.db"
"$bin/vistream-pvs" bake --scene city1 --cell-size 4,2,4 --region "$walk_region" --out "$work/walk.db"
rm -f "$work/port"
"$bin/vistream-server" --scene city1 --pvs-db "$work/walk.db" --port 0 --port-file "$work/port" \
  --stats-interval 5 --log-level info > "$work/server.log" 2>&1 &
server=$!
trap 'kill $server 2>/dev/null || true' EXIT
for _ in $(seq 1 240); do [ -s "$work/port" ] && break; kill -0 $server 2>/dev/null || break; sleep 0.25; done
if [ ! -s "$work/port" ]; then echo "demo: the server did not start:"; cat "$work/server.log"; exit 1; fi
"$bin/vistream-loadtest" --port "$(cat "$work/port")" --clients 20 --path "$work/walk.csv" --duration 15 \
  --scene city1 --log-level warn

echo
echo "== 8. a rendering client on the same server: near field as polygons, far field by horizon tracing,"
echo "==    image cache and ray casting (Wimmer 2001, chapter 4); PNG frames in $work/frames =="
"$bin/vistream-client" --host 127.0.0.1 --port "$(cat "$work/port")" --headless --path "$work/walk.csv" \
  --frames 60 --size 640x480 --near-distance 60 --stream-radius 400 --polygon-budget 0 --out "$work/frames" \
  --log-level warn
kill -INT $server
wait $server || true
trap - EXIT

echo
echo "== 9. a contact sheet: frames of city1 and of the real city model (../shared/data/delfshaven.obj),"
echo "==    lit by the baked environment light, sun shadows and ambient occlusion, with distance haze =="
sheet="$work/frames/contact_sheet.png"
rm -f "$sheet"
"$bin/vistream-client" --scene city1 --headless --path "$work/walk.csv" --frames 120 --size 320x240 \
  --sheet "$sheet" --log-level warn > /dev/null
delfshaven=../shared/data/delfshaven.obj
if [ -f "$delfshaven" ]; then
  "$bin/vistream-scene" path --scene "$delfshaven" --frames 300 --seed 3 --out "$work/delfshaven.csv" --log-level error
  "$bin/vistream-client" --scene "$delfshaven" --headless --path "$work/delfshaven.csv" --frames 120 \
    --size 320x240 --sheet "$sheet" --log-level error > /dev/null
fi
echo "contact sheet: $sheet"
echo "server log (last lines):"
tail -n 4 "$work/server.log"
