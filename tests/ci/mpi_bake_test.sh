#!/usr/bin/env bash
# `mpirun -n 2 vistream-pvs bake --mpi` against one process, on loopback:
#  1. the two ranks' merged database is byte for byte the one-process bake;
#  2. a rank killed mid-bake takes the job down, and the same command run
#     again resumes the shards from their journals to the same bytes;
#  3. the impostor bake over two ranks gives the one-process bytes too;
#  4. --mpi with --shard is refused before anything is baked.
# Usage: mpi_bake_test.sh VISTREAM_PVS   (run by ctest, label mpi)
set -euo pipefail
pvs=$1
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
mpi=(mpirun --allow-run-as-root --oversubscribe -n 2)
bake=(bake --scene city1 --cell-size 4 --region -24,0,-24,24,4,24 --json)

"$pvs" "${bake[@]}" --out "$dir/one.db" >"$dir/one.json" 2>"$dir/one.log"
"${mpi[@]}" "$pvs" "${bake[@]}" --mpi --out "$dir/two.db" >"$dir/two.json" 2>"$dir/two.log"
cmp "$dir/one.db" "$dir/two.db"
grep -q '"ranks": 2' "$dir/two.json"
if ls "$dir"/two.db.shard-* >/dev/null 2>&1; then
  echo "shard files left behind" >&2
  exit 1
fi
echo "1. two ranks give the one-process bytes"

# 2. Kill rank 1 once its shard journal holds some cells.
"${mpi[@]}" "$pvs" "${bake[@]}" --mpi --threads 1 --out "$dir/killed.db" >"$dir/killed.json" 2>"$dir/killed.log" &
job=$!
journal="$dir/killed.db.shard-1-of-2.journal"
for _ in $(seq 1 600); do
  if [ -f "$journal" ] && [ "$(stat -c %s "$journal")" -gt 4096 ]; then break; fi
  sleep 0.05
done
rank1=$(pgrep -f -- "--out $dir/killed.db" | while read -r pid; do
  if grep -q "OMPI_COMM_WORLD_RANK=1" "/proc/$pid/environ" 2>/dev/null; then echo "$pid"; fi
done | head -1)
if [ -z "$rank1" ]; then
  echo "could not find rank 1 while it baked (journal $(stat -c %s "$journal" 2>/dev/null || echo missing) bytes)" >&2
  wait "$job" || true
  exit 1
fi
kill -9 "$rank1"
if wait "$job"; then
  echo "the job survived a killed rank" >&2
  exit 1
fi
[ ! -f "$dir/killed.db" ] || { echo "a killed job wrote its output" >&2; exit 1; }
[ -f "$journal" ] || { echo "the killed rank left no journal" >&2; exit 1; }
"${mpi[@]}" "$pvs" "${bake[@]}" --mpi --threads 1 --out "$dir/killed.db" >"$dir/resumed.json" 2>"$dir/resumed.log"
cmp "$dir/one.db" "$dir/killed.db"
grep -Eq '"resumed_cells": [1-9]' "$dir/resumed.json" || { cat "$dir/resumed.json" >&2; exit 1; }
echo "2. a killed rank's shard resumes from its journal to the same bytes"

# 3. Impostors the same way: two ranks' merged database is the one-process bake.
imp=(impostors --scene city1 --db "$dir/one.db" --cells -3,1,-3,3,3,-1 --near-distance 40
  --min-triangles 60 --max-rays 8 --texture 1x1 --visibility-views 8 --screen 120x90 --json)
"$pvs" "${imp[@]}" --out "$dir/one.impdb" >"$dir/imp1.json" 2>"$dir/imp1.log"
"${mpi[@]}" "$pvs" "${imp[@]}" --mpi --out "$dir/two.impdb" >"$dir/imp2.json" 2>"$dir/imp2.log"
cmp "$dir/one.impdb" "$dir/two.impdb"
grep -q '"ranks": 2' "$dir/imp2.json"
echo "3. impostors on two ranks give the one-process bytes"

# 4. Refused before baking.
if "$pvs" "${bake[@]}" --mpi --shard 0/2 --out "$dir/bad.db" 2>"$dir/bad.log"; then
  echo "--mpi with --shard was accepted" >&2
  exit 1
fi
grep -q -- "--shard" "$dir/bad.log"
[ ! -e "$dir/bad.db" ]
if "$pvs" "${imp[@]}" --mpi --shard 0/2 --out "$dir/bad.impdb" 2>"$dir/bad2.log"; then
  echo "impostors --mpi with --shard was accepted" >&2
  exit 1
fi
grep -q -- "--shard" "$dir/bad2.log"
echo "4. --mpi with --shard is refused"
