#!/bin/sh
# The SIMD depth-first tracer against an older sray binary, side by side:
# the Stanford dragon's eye rays (no lights) and with its default lights
# (shadow rays), one thread, single and double precision; and the seven
# SPD scenes at 512x512, depth 5. Alternating runs; take medians.
# Usage, from this directory:
#   sh run.sh NEW_SRAY OLD_SRAY ../../../shared/meshes/dragon_vrip.ply.gz
set -e
NEW=$1; OLD=$2; DRAGON=$3; RUNS=${RUNS:-5}
stat() { python3 -c "import json,sys;s=json.load(open('$1'));print($2)"; }
[ -f dragon.sdb ] || "$NEW" convert "$DRAGON" -o dragon.sdb
if [ ! -f dragon_nl.sdb ]; then
  "$NEW" convert dragon.sdb -o dragon.nff
  grep -v '^l ' dragon.nff > dragon_nl.nff
  "$NEW" convert dragon_nl.nff -o dragon_nl.sdb
fi
for s in balls gears mount rings tetra tree teapot; do
  [ -f "$s.sdb" ] || "$NEW" convert "spd:$s" -o "$s.sdb"
done
for r in $(seq "$RUNS"); do
  for cfg in "$NEW single" "$NEW double" "$OLD double"; do
    set -- $cfg
    for scene in dragon_nl dragon; do
      "$1" render $scene.sdb -o out.png --mode df --depth 1 --threads 1 \
        --precision "$2" -q --stats s.json
      echo "$scene $1 $2 $(stat s.json "s['trace_seconds'], s['eye_rays'], s['shadow_rays']")"
    done
  done
done
for s in balls gears mount rings tetra tree teapot; do
  for r in 1 2 3; do
    for b in "$NEW" "$OLD"; do
      "$b" render "$s.sdb" -o out.png --mode df --threads 1 --width 512 \
        --height 512 --depth 5 -q --stats s.json
      echo "spd $s $b $(stat s.json "s['trace_seconds'], s['intersection_tests']")"
    done
  done
done
