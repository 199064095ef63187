#!/usr/bin/env bash
# The main job on the built-in default scene: installs what is missing,
# builds Release, generates the default city (city1), prints its statistics
# and the effects it calls for, then the sampled visible set of one street
# view cell, with timings.
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
"$bin/vistream-scene" visible --scene "$work/city1.obj" --cell "$cell" --points 32 --res 128 \
  | awk 'NR == 1 { print; next } { n = split($0, ids, " "); printf "face IDs (first 40 of %d): ", n; for (i = 1; i <= n && i <= 40; ++i) printf "%s ", ids[i]; print "" }'
