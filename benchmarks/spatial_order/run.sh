#!/bin/sh
# Objects in spatial order (database version 6) against the input's order
# (version 4), one binary, side by side: bytes on disk, and breadth-first
# (under 64 MiB) and depth-first renders at 512x512, alternating, RUNS
# rounds; time, peak memory and bytes read per render. Images must be
# identical between the orders and the tracers. Usage:
#   sh run.sh /path/to/sray DIR [RUNS] SCENE...
# where each SCENE is a mesh or NFF file; DIR receives the databases.
set -e
SRAY=$1; DIR=$2; RUNS=${3:-3}; shift 3
mkdir -p "$DIR"
for SCENE in "$@"; do
  N=$(basename "$SCENE"); N=${N%%.*}
  for O in input spatial; do
    [ -f "$DIR/${N}_$O.sdb" ] || "$SRAY" convert -q "$SCENE" -o "$DIR/${N}_$O.sdb" --order $O 2>/dev/null
    "$SRAY" info --json "$DIR/${N}_$O.sdb" | python3 -c "
import json,sys; d=json.load(sys.stdin)
print('$N $O: %d bytes, %.1f bytes per object, %d blocks, %d runs' % (d['file_bytes'], d['file_bytes']/d['objects'], d['blocks'], d.get('runs',0)))"
  done
  for i in $(seq "$RUNS"); do
    for M in bf df; do
      for O in input spatial; do
        EXTRA=""; [ $M = bf ] && EXTRA="--memory 64MiB"
        /usr/bin/time -f "%e %M" -o "$DIR/t.txt" "$SRAY" render "$DIR/${N}_$O.sdb" -q \
          -o "$DIR/${N}_${O}_$M.png" --mode $M $EXTRA --stats "$DIR/${N}_${O}_$M.json"
        python3 -c "
import json; d=json.load(open('$DIR/${N}_${O}_$M.json')); t=open('$DIR/t.txt').read().split()
print('$N $M $O round $i: %s s, %.1f MiB, %d bytes read, %d tests' % (t[0], int(t[1])/1024, d.get('db_bytes_read',0), d['intersection_tests']))"
      done
    done
  done
  cmp "$DIR/${N}_input_df.png" "$DIR/${N}_spatial_df.png"
  cmp "$DIR/${N}_input_df.png" "$DIR/${N}_spatial_bf.png"
  cmp "$DIR/${N}_input_df.png" "$DIR/${N}_input_bf.png"
  echo "$N: images identical"
done
