#!/bin/sh
# Objects in spatial order (database version 6) against the input's order
# (version 4), side by side: bytes on disk, and breadth-first (under
# 64 MiB) and depth-first renders at 512x512, alternating, RUNS rounds;
# time, peak memory, bytes read and intersection tests per render. With
# OLD set to an older sray, it renders the input-order database too (it
# cannot read version 6). Images must be identical across orders, tracers
# and binaries. Usage:
#   [OLD=/path/to/old/sray] sh run.sh /path/to/sray DIR RUNS SCENE...
# where each SCENE is a mesh or NFF file; DIR receives the databases.
set -e
SRAY=$1; DIR=$2; RUNS=$3; shift 3
mkdir -p "$DIR"
one() { # label binary db mode name
  EXTRA=""; [ "$4" = bf ] && EXTRA="--memory 64MiB"
  /usr/bin/time -f "%e %M" -o "$DIR/t.txt" "$2" render "$3" -q -o "$DIR/$5_$1_$4.png" \
    --mode "$4" $EXTRA --stats "$DIR/$5_$1_$4.json"
  python3 -c "
import json; d=json.load(open('$DIR/$5_$1_$4.json')); t=open('$DIR/t.txt').read().split()
print('$5 $4 $1 round $i: %s s, %.1f MiB, %d bytes read, %d tests' % (t[0], int(t[1])/1024, d.get('db_bytes_read',0), d['intersection_tests']))"
}
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
      one input "$SRAY" "$DIR/${N}_input.sdb" $M "$N"
      one spatial "$SRAY" "$DIR/${N}_spatial.sdb" $M "$N"
      [ -z "$OLD" ] || one old "$OLD" "$DIR/${N}_input.sdb" $M "$N"
    done
  done
  for P in input_bf spatial_df spatial_bf; do
    cmp "$DIR/${N}_input_df.png" "$DIR/${N}_$P.png"
  done
  [ -z "$OLD" ] || { cmp "$DIR/${N}_input_df.png" "$DIR/${N}_old_df.png" && cmp "$DIR/${N}_input_df.png" "$DIR/${N}_old_bf.png"; }
  echo "$N: images identical"
done
