#!/bin/bash
# Table 1 in memory, side by side: OLD's depth-first, NEW's depth-first,
# NEW's breadth-first, OLD's breadth-first, at one and two threads, three
# alternating runs, one line per run (scene, threads, binary, mode, run,
# total s, scans). table1_summary.py takes the medians.
# usage: table1.sh NEW_SRAY OLD_SRAY DIR
# DIR holds balls.sdb gears.sdb mount.sdb rings.sdb tetra.sdb tree.sdb
# teapot.sdb: the default sizes, `sray gen NAME -o DIR/NAME.sdb`.
NEW=$1; OLD=$2; cd "${3:-.}"
for i in 1 2 3; do
 for s in balls gears mount rings tetra tree teapot; do
  for t in 1 2; do
   for c in "OLD df" "NEW df" "NEW bf" "OLD bf"; do
    set -- $c; bin=${!1}
    $bin render $s.sdb -o /tmp/t1.png --mode $2 --threads $t --stats /tmp/t1.json >/dev/null 2>&1
    echo "$s $t $1 $2 $i $(python3 -c "import json;d=json.load(open('/tmp/t1.json'));print(round(d['total_seconds'],4), d.get('db_scans','-'))")"
   done
  done
 done
done
