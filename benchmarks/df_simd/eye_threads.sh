#!/bin/sh
# The dragon's eye rays on one and two threads, side by side: Embree 3.13's
# viewer (Debian's embree-tools), a new and an old sray binary (single and
# double precision), alternating, RUNS rounds. Prints one line a run:
#   who threads precision seconds M-rays/s
# (Embree's rate is its BENCHMARK_RENDER_MRAYPS_AVG; sray's eye_rays /
# trace_seconds, without lights, and with the dragon's two default lights
# as "lit"). Usage, from this directory (dragon_nl.sdb and dragon.sdb as
# run.sh makes them, dragon.obj as ../embree/ply2obj.py makes it):
#   sh eye_threads.sh NEW_SRAY OLD_SRAY
set -e
NEW=$1; OLD=$2; RUNS=${RUNS:-5}
CAM="$(python3 ../embree/cam.py)"
stat() { python3 -c "import json;s=json.load(open('s.json'));t=s['trace_seconds'];print(t, s['eye_rays']/t/1e6)"; }
for r in $(seq "$RUNS"); do
  for T in 1 2; do
    # shellcheck disable=SC2086
    echo "embree $T single - $(viewer -i dragon.obj --size 512 512 --threads $T $CAM \
      --benchmark 3 10 2>&1 | sed -n 's/.*BENCHMARK_RENDER_MRAYPS_AVG \([0-9.]*\).*/\1/p')"
    for cfg in "new $NEW single" "new $NEW double" "old $OLD single" "old $OLD double"; do
      set -- $cfg
      "$2" render dragon_nl.sdb -o out.png --mode df --depth 1 --threads $T \
        --precision "$3" -q --stats s.json
      echo "$1 $T $3 $(stat)"
      "$2" render dragon.sdb -o out.png --mode df --depth 1 --threads $T \
        --precision "$3" -q --stats s.json
      echo "$1-lit $T $3 $(stat)"
    done
  done
done
