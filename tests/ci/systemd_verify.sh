#!/usr/bin/env bash
# systemd-analyze verify on deploy/systemd/vistream-server.service, with its
# ExecStart pointed at the built binary (verify checks that it exists).
# Usage: systemd_verify.sh UNIT VISTREAM_SERVER
set -euo pipefail
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
sed "s|/usr/local/bin/vistream-server|$2|" "$1" >"$dir/vistream-server.service"
out=$(systemd-analyze verify "$dir/vistream-server.service" 2>&1) || { echo "$out" >&2; exit 1; }
# verify exits 0 on some warnings: none are acceptable for our unit.
if echo "$out" | grep -q "vistream-server.service"; then
  echo "$out" >&2
  exit 1
fi
echo "systemd-analyze verify: clean"
