#!/usr/bin/env bash
# What verification costs: balls4 and tetra9 at 512x512 on a coordinator
# with 2 local workers (1 thread, 1 GiB each), --verify-fraction 0 against
# the default (0.02), 3 times each; every render after one that uploads the
# scene and warms the workers' caches. Prints the medians of the job's
# total seconds, the worker seconds of the shards' tasks and the seconds
# spent tracing verification samples (`verification.seconds` in --stats),
# and checks the images are the same.
#
#   SRAY=target/release/sray benchmarks/verify-overhead.sh
set -euo pipefail
S=$(realpath "${SRAY:-target/release/sray}")
W=$(mktemp -d)
trap 'kill $(jobs -p) 2>/dev/null || true; rm -rf "$W"' EXIT
cd "$W"
export SRAY_JOBS_DIR=$W/tickets
head -c 32 /dev/urandom | base64 >token
for rep in 1 2 3; do
  for vf in 0 0.02; do
    rm -rf data cache-*
    "$S" coordinator --listen 127.0.0.1:0 --data-dir data --token-file token \
      --verify-fraction $vf 2>coord.log &
    CP=$!
    for _ in $(seq 100); do grep -q "listening on" coord.log && break; sleep 0.2; done
    URL=$(grep "listening on" coord.log | awk '{print $NF}')
    for w in a b; do
      "$S" worker --coordinator "$URL" --token-file token --threads 1 --memory 1GiB \
        --cache-dir cache-$w --name $w 2>worker-$w.log &
    done
    sleep 2
    for sc in balls:4 tetra:9; do
      n=${sc/:/}
      "$S" render spd:$sc -o warm.png --coordinator "$URL" --token-file token --quiet 2>/dev/null
      "$S" render spd:$sc -o "$n-$vf.png" --coordinator "$URL" --token-file token --quiet \
        --stats "st-$n-$vf-$rep.json" 2>/dev/null
    done
    kill $(jobs -p)
    wait 2>/dev/null || true
  done
done
cmp balls4-0.png balls4-0.02.png
cmp tetra9-0.png tetra9-0.02.png
python3 - <<'EOF'
import glob, json, statistics as st
rows = {}
for f in sorted(glob.glob("st-*.json")):
    _, scene, vf, _ = f[:-5].split("-")
    s = json.load(open(f))
    rows.setdefault((scene, vf), []).append(s)
print("scene   fraction  total s  worker s  verify s  sample rays / rays")
for (scene, vf), r in sorted(rows.items()):
    v = r[0]["verification"]
    med = lambda f: st.median(f(s) for s in r)
    print(f"{scene:7} {vf:8}  {med(lambda s: s['total_seconds']):7.2f}  "
          f"{med(lambda s: s['worker_seconds']):8.2f}  "
          f"{med(lambda s: s['verification'].get('seconds', 0)):8.2f}  "
          f"{v['sample_rays']} / {v['shard_rays']} ({100 * v['sample_rays'] / v['shard_rays']:.1f} %)")
print("images identical with and without verification")
EOF
