#!/usr/bin/env bash
# Two vistream-server replicas behind HAProxy with shared presence through
# Redis, on loopback: walks simulated users through HAProxy, kills one
# replica mid-run and checks that
#   - clients landed on both replicas,
#   - every client saw avatars of users on the other replica,
#   - the killed replica's clients reconnected to the other one and held
#     their cell again within a few seconds,
#   - no visibility misses and no errors.
# Prints one JSON object (replicas, clients, avatars_seen_other_replica,
# reconnects, failover_s, visibility_misses, errors, and more) and exits
# non-zero if a check fails.
#
#   deploy/scale-test.sh [--scene S] [--clients N] [--duration S] [--kill-after S]
#                        [--replicas 1|2] [--no-kill] [--bin DIR] [--keep DIR]
#
# --replicas 1 and --no-kill measure baselines (one replica behind the same
# HAProxy; no failover): the checks that need them are then left out.
# Without --bin it installs what is missing and builds Release first; with
# --bin it uses the binaries there (ctest runs it so). HAProxy runs the
# shipped deploy/haproxy/haproxy.cfg with loopback addresses put in, no
# Docker resolver and maxconn 1000 (an unprivileged open-file limit).
set -euo pipefail
cd "$(dirname "$0")/.."

scene=city1
clients=40
duration=20
kill_after=8
replicas=2
kill=1
bin=""
keep=""
usage() { sed -n '2,19p' "$0"; }
while [ $# -gt 0 ]; do
  case "$1" in
    --scene) scene=${2:?--scene needs a value}; shift 2 ;;
    --clients) clients=${2:?--clients needs a value}; shift 2 ;;
    --duration) duration=${2:?--duration needs a value}; shift 2 ;;
    --kill-after) kill_after=${2:?--kill-after needs a value}; shift 2 ;;
    --replicas) replicas=${2:?--replicas needs 1 or 2}; shift 2 ;;
    --no-kill) kill=0; shift ;;
    --bin) bin=${2:?--bin needs a directory}; shift 2 ;;
    --keep) keep=${2:?--keep needs a directory}; shift 2 ;;
    -h|--help) usage; exit 0 ;;
    *) echo "scale-test.sh: unknown option '$1' (try --help)" >&2; exit 2 ;;
  esac
done
for n in "$clients" "$duration" "$kill_after"; do
  [[ "$n" =~ ^[0-9]+$ ]] || { echo "scale-test.sh: '$n' is not a whole number" >&2; exit 2; }
done
[ "$replicas" = 1 ] || [ "$replicas" = 2 ] || { echo "scale-test.sh: --replicas must be 1 or 2" >&2; exit 2; }
[ "$replicas" = 2 ] || kill=0
[ "$clients" -ge 2 ] || { echo "scale-test.sh: --clients must be at least 2" >&2; exit 2; }
[ "$kill_after" -lt "$duration" ] || { echo "scale-test.sh: --kill-after must be below --duration" >&2; exit 2; }

if [ -z "$bin" ]; then
  deploy/install-deps.sh >&2
  cmake --preset release >/dev/null
  cmake --build --preset release >&2
  bin=build/bin
fi
for tool in vistream-server vistream-loadtest vistream-pvs vistream-scene; do
  [ -x "$bin/$tool" ] || { echo "scale-test.sh: $bin/$tool is missing (build first or drop --bin)" >&2; exit 2; }
done
for tool in redis-server haproxy python3; do
  command -v "$tool" >/dev/null || { echo "scale-test.sh: $tool is missing (deploy/install-deps.sh installs it)" >&2; exit 2; }
done

if [ -n "$keep" ]; then mkdir -p "$keep"; work=$(cd "$keep" && pwd); else work=$(mktemp -d); fi
pids=()
cleanup() {
  for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done
  wait 2>/dev/null || true
  [ -n "$keep" ] || rm -rf "$work"
}
trap cleanup EXIT
log() { echo "scale-test: $*" >&2; }

free_port() { python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])'; }
wait_file() {  # file pid what
  for _ in $(seq 1 600); do
    [ -s "$1" ] && return 0
    kill -0 "$2" 2>/dev/null || break
    sleep 0.1
  done
  echo "scale-test.sh: $3 did not start; its log:" >&2
  tail -n 20 "$work/$3.log" >&2 || true
  exit 1
}

# The walk (clients spread along it, so they meet) and the PVS of the cells
# around it, baked once and shared by both replicas as in production.
"$bin/vistream-scene" path --scene "$scene" --frames 900 --seed 3 --out "$work/walk.csv" --log-level warn
region=$(awk -F, 'NR > 1 { if (n++ == 0) { x0 = x1 = $2; y = $3; z0 = z1 = $4 }
  if ($2 < x0) x0 = $2; if ($2 > x1) x1 = $2; if ($4 < z0) z0 = $4; if ($4 > z1) z1 = $4 }
  END { printf "%.3f,%.3f,%.3f,%.3f,%.3f,%.3f", x0-40, y-1.5, z0-40, x1+40, y+0.5, z1+40 }' "$work/walk.csv")
log "baking the PVS around the walk ($region)"
rm -f "$work/walk.db"
"$bin/vistream-pvs" bake --scene "$scene" --cell-size 4,2,4 --region "$region" --out "$work/walk.db" \
  --log-level warn >&2

redis_port=$(free_port)
redis-server --port "$redis_port" --bind 127.0.0.1 --save "" --appendonly no > "$work/redis.log" 2>&1 &
pids+=($!)
for _ in $(seq 1 100); do redis-cli -p "$redis_port" ping >/dev/null 2>&1 && break; sleep 0.1; done
redis-cli -p "$redis_port" ping >/dev/null || { echo "scale-test.sh: redis-server did not start" >&2; cat "$work/redis.log" >&2; exit 1; }

declare -a server_pid port http
rm -f "$work"/port? "$work"/http? "$work"/metrics?.txt "$work/loadtest.json"
for i in $(seq 1 "$replicas"); do
  "$bin/vistream-server" --scene "$scene" --pvs-db "$work/walk.db" --port 0 --port-file "$work/port$i" \
    --http-port 0 --http-port-file "$work/http$i" --presence "redis://127.0.0.1:$redis_port" \
    --workers 1 --log-level info > "$work/server$i.log" 2>&1 &
  server_pid[$i]=$!
  pids+=($!)
done
for i in $(seq 1 "$replicas"); do
  wait_file "$work/port$i" "${server_pid[$i]}" "server$i"
  wait_file "$work/http$i" "${server_pid[$i]}" "server$i"
  port[$i]=$(cat "$work/port$i")
  http[$i]=$(cat "$work/http$i")
done

lb_port=$(free_port)
stats_port=$(free_port)
sed -e "s/^\(    default-server.*\) resolvers docker/\1/" \
    -e "/^resolvers docker/,/^$/d" \
    -e "s/^    maxconn [0-9]*/    maxconn 1000/" \
    -e "s/bind :7070/bind 127.0.0.1:$lb_port/" \
    -e "s/bind :8404/bind 127.0.0.1:$stats_port/" \
    -e "s/^\(    log stdout.*\)/    log stderr format raw local0 info/" \
    -e "s/server vistream-1 vistream-1:7070 port 8080/server vistream-1 127.0.0.1:${port[1]} port ${http[1]}/" \
    -e "s/server vistream-2 vistream-2:7070 port 8080/server vistream-2 127.0.0.1:${port[2]:-0} port ${http[2]:-0}/" \
    deploy/haproxy/haproxy.cfg > "$work/haproxy.cfg"
[ "$replicas" = 2 ] || sed -i "/server vistream-2 /d" "$work/haproxy.cfg"
grep -q "127.0.0.1:${port[$replicas]}" "$work/haproxy.cfg" || { echo "scale-test.sh: could not adapt deploy/haproxy/haproxy.cfg" >&2; exit 1; }
haproxy -f "$work/haproxy.cfg" > "$work/haproxy.log" 2>&1 &
pids+=($!)
for _ in $(seq 1 100); do
  python3 -c "import socket,sys; socket.create_connection(('127.0.0.1', $lb_port), 0.2)" 2>/dev/null && break
  sleep 0.1
done

log "$clients clients through HAProxy (127.0.0.1:$lb_port) to $replicas replicas for $duration s$([ "$kill" = 1 ] && echo "; replica 1 dies after $kill_after s")"
"$bin/vistream-loadtest" --host 127.0.0.1 --port "$lb_port" --clients "$clients" --path "$work/walk.csv" \
  --duration "$duration" --scene "$scene" --json --log-level warn > "$work/loadtest.json" 2> "$work/loadtest.log" &
loadtest=$!
pids+=($loadtest)
sleep "$kill_after"
# Presence fan-out as the survivor measured it so far (the dead one cannot be asked after).
curl_metrics() { python3 -c "import urllib.request,sys; print(urllib.request.urlopen('http://127.0.0.1:$1/metrics', timeout=5).read().decode())"; }
curl_metrics "${http[1]}" > "$work/metrics1.txt" || true
sessions_before=$(awk '/^vistream_sessions /{print $2}' "$work/metrics1.txt")
if [ "$kill" = 1 ]; then
  disown "${server_pid[1]}"  # no job-control notice for the kill
  kill -9 "${server_pid[1]}"
  log "killed replica 1 (${sessions_before:-?} sessions)"
fi
loadtest_rc=0
wait "$loadtest" || loadtest_rc=$?
[ "$replicas" = 1 ] || curl_metrics "${http[2]}" > "$work/metrics2.txt" || true

python3 - "$work" "$clients" "$loadtest_rc" "${sessions_before:-0}" "$replicas" "$kill" <<'PY'
import json, sys
work, clients, rc, before = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), float(sys.argv[4])
replicas, kill = int(sys.argv[5]), sys.argv[6] == "1"
if not kill: before = 0
try:
    lt = json.load(open(f"{work}/loadtest.json"))
except Exception as e:
    print(f"scale-test.sh: the load test printed no JSON ({e}); its log:", file=sys.stderr)
    print(open(f"{work}/loadtest.log").read()[-2000:], file=sys.stderr)
    sys.exit(1)
def quantiles(path):
    q = {}
    for line in open(path):
        if line.startswith('vistream_presence_quantile_seconds{quantile="'):
            key = line.split('"')[1]
            q[key] = float(line.split()[-1]) * 1000.0
    return q
presence = {}
for i in (1, 2):
    try:
        presence[f"replica{i}"] = quantiles(f"{work}/metrics{i}.txt")
    except OSError:
        pass
ready = lt["failover_ready_ms"]
out = {
    "replicas": len(lt["clients_by_replica"]),
    "clients": lt["clients"],
    "clients_by_replica": lt["clients_by_replica"],
    "clients_by_replica_at_end": lt["clients_by_replica_at_end"],
    "sessions_on_killed_replica": int(before),
    "avatars_seen": lt["avatars_seen"],
    "avatars_seen_other_replica": lt["avatars_seen_other_replica"],
    "clients_seeing_other_replica": lt["clients_seeing_other_replica"],
    "reconnects": lt["reconnects"],
    "clients_reconnected": lt["clients_reconnected"],
    "failover_s": None if ready["max"] is None else ready["max"] / 1000.0,
    "failover_welcome_s": None if lt["failover_ms"]["max"] is None else lt["failover_ms"]["max"] / 1000.0,
    "failover_ready_ms": ready,
    "visibility_misses": lt["visibility_misses"],
    "visibility_misses_after_reconnect": lt["visibility_misses_after_reconnect"],
    "errors": lt["errors"],
    "first_error": lt["first_error"],
    "cell_ready_latency_ms": lt["cell_ready_latency_ms"],
    "initial_load_ms": lt["initial_load_ms"],
    "bytes_per_client_per_s": lt["bytes_per_client_per_s"],
    "server_cpu_ms_per_s_per_client": lt["server_cpu_ms_per_s_per_client"],
    "presence_latency_ms": presence,
    "loadtest_exit": rc,
}
print(json.dumps(out, indent=2))
problems = []
if out["replicas"] != replicas: problems.append(f"clients landed on {out['replicas']} replicas, not {replicas}")
if replicas == 2 and out["clients_seeing_other_replica"] != clients:
    problems.append(f"{clients - out['clients_seeing_other_replica']} clients saw no avatar of the other replica")
if kill and (out["reconnects"] < 1 or out["clients_reconnected"] < int(before)):
    problems.append(f"{out['clients_reconnected']} clients reconnected, {int(before)} were on the killed replica")
if lt["failover_ready_ms"]["count"] < out["clients_reconnected"]:
    problems.append("a reconnected client never held its cell again")
if out["failover_s"] is not None and out["failover_s"] > 5.0:
    problems.append(f"failover took {out['failover_s']:.1f} s (more than 5 s)")
if out["visibility_misses"] != 0: problems.append(f"{out['visibility_misses']} visibility misses")
if out["errors"] != 0: problems.append(f"{out['errors']} errors (first: {out['first_error']})")
if rc != 0: problems.append(f"vistream-loadtest exited with {rc}")
if problems:
    print("scale-test.sh: FAILED: " + "; ".join(problems), file=sys.stderr)
    sys.exit(1)
print("scale-test.sh: passed", file=sys.stderr)
PY
