#!/usr/bin/env bash
# Sixteen worker processes on loopback (one thread, --memory 64MiB each)
# render a scene whose object database is at least 8 times a worker's
# budget (default rings80, 557 MiB: 8.7 times; tetra12 is 112 MiB, 1.7
# times, too small); the workers read the scene
# from the coordinator's data directory as shared storage (--scene-dir),
# and two of them are killed with SIGKILL while round 2 runs. Checks the
# image against the embedded render and prints what the coordinator served
# of the scene, the tasks requeued and the job's restarts (0: it never
# started again from its eye rays).
#
#   SRAY=target/release/sray benchmarks/cluster-16.sh
#   SCENE=spd:balls:7 SIZE=128 SRAY=... benchmarks/cluster-16.sh
set -euo pipefail
S=$(realpath "${SRAY:-target/release/sray}")
SCENE=${SCENE:-spd:rings:80}
SIZE=${SIZE:-128}
W=$(mktemp -d)
trap 'kill $(jobs -p) 2>/dev/null || true; rm -rf "$W"' EXIT
cd "$W"
export SRAY_JOBS_DIR=$W/tickets
head -c 32 /dev/urandom | base64 >token
"$S" render "$SCENE" -o embedded.png --mode bf --width "$SIZE" --height "$SIZE" --quiet
RUST_LOG=info,sray_coordinator=debug "$S" coordinator --listen 127.0.0.1:0 --data-dir data --token-file token \
  --heartbeat-ms 500 --worker-timeout 5 2>coord.log &
for _ in $(seq 100); do grep -q "listening on" coord.log && break; sleep 0.2; done
URL=$(grep "listening on" coord.log | awk '{print $NF}')
declare -A PIDS
for i in $(seq 0 15); do
  RUST_LOG=info "$S" worker --coordinator "$URL" --token-file token --threads 1 --memory 64MiB \
    --cache-dir cache-$i --scene-dir data --name w$i 2>worker-$i.log &
  PIDS[w$i]=$!
done
sleep 3
t0=$(date +%s.%N)
"$S" render "$SCENE" -o cluster.png --coordinator "$URL" --token-file token --quiet \
  --width "$SIZE" --height "$SIZE" --stats stats.json 2>client.log &
CLIENT=$!
# Two workers killed, each once it is given a task of round 2.
killed=()
until [ ${#killed[@]} -ge 2 ]; do
  for i in $(seq 0 15); do
    [[ " ${killed[*]-} " == *" w$i "* ]] && continue
    if grep -q "task assigned worker=w$i .*round=2 " coord.log 2>/dev/null; then
      kill -9 "${PIDS[w$i]}"
      killed+=("w$i")
      echo "killed w$i"
      [ ${#killed[@]} -ge 2 ] && break
    fi
  done
  kill -0 $CLIENT 2>/dev/null || break
  sleep 0.1
done
wait $CLIENT
t1=$(date +%s.%N)
# Peak resident memory of the workers still running (VmHWM).
for i in $(seq 0 15); do
  [[ " ${killed[*]-} " == *" w$i "* ]] && continue
  awk '/VmHWM/ {print $2}' "/proc/${PIDS[w$i]}/status" 2>/dev/null || true
done >worker-hwm.txt
cmp embedded.png cluster.png && echo "image: the same as the embedded render"
python3 - "$t0" "$t1" <<'PY'
import json, os, sys
s = json.load(open("stats.json"))
db = os.path.getsize(next(f for f in (os.path.join("data", n) for n in os.listdir("data")) if f.endswith(".sdb")))
print(f"database {db / 2**20:.0f} MiB = {db / (64 * 2**20):.1f} x a worker's 64 MiB")
print(f"scene bytes served by the coordinator: {s['scene_bytes_served']} ({s['scene_bytes_served'] / db:.2f} x the database)")
print(f"tasks requeued {s['tasks_requeued']}, job restarts {s['job_restarts']}, workers {s['workers']}")
print(f"wall {float(sys.argv[2]) - float(sys.argv[1]):.1f} s")
hwm = [int(x) for x in open("worker-hwm.txt").read().split()]
if hwm:
    print(f"peak memory: coordinator {s.get('peak_rss_bytes', 0) / 2**20:.0f} MiB, workers max {max(hwm) / 1024:.0f} MiB (of {len(hwm)} still running)")
PY
