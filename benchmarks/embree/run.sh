#!/bin/sh
# Embree 3.13's viewer (Debian's embree-tools) against sray's depth-first
# tracer on the Stanford dragon's eye rays, 512x512, one and two threads,
# alternating, three runs each. Usage, from this directory:
#   sh run.sh /path/to/sray ../../../shared/meshes/dragon_vrip.ply.gz
# Embree prints BENCHMARK_RENDER_MRAYPS_AVG (primary rays only); for sray
# take eye_rays / trace_seconds from the stats files it writes here.
set -e
SRAY=$1; DRAGON=$2
[ -f dragon.obj ] || python3 ply2obj.py "$DRAGON" dragon.obj
CAM="$(python3 cam.py)"
for i in 1 2 3; do
  for T in 1 2; do
    echo "== embree threads=$T run=$i"
    # shellcheck disable=SC2086
    viewer -i dragon.obj --size 512 512 --threads $T $CAM --benchmark 5 60 2>&1 \
      | grep -E 'BENCHMARK_RENDER_MRAYPS_AVG '
    echo "== sray threads=$T run=$i"
    "$SRAY" render "$DRAGON" -o "d$T.png" --mode df --width 512 --height 512 \
      --threads $T --depth 1 -q --stats "sray_t${T}_r$i.json"
    grep -E '"(eye_rays|trace_seconds)"' "sray_t${T}_r$i.json" | tr -d '\n '; echo
  done
done
