#!/bin/sh
# The seven SPD scenes, depth-first, 512x512, depth 5, one and two threads,
# three binaries alternating, RUNS rounds: "scene threads binary seconds
# tests" (trace_seconds). Usage, from a directory holding the scenes'
# .sdb files (sray gen NAME -o NAME.sdb): sh spd_threads.sh SRAY...
set -e
RUNS=${RUNS:-3}
for r in $(seq "$RUNS"); do
  for s in balls gears mount rings tetra tree teapot; do
    for T in 1 2; do
      for b in "$@"; do
        "$b" render "$s.sdb" -o out.png --mode df --threads $T --width 512 \
          --height 512 --depth 5 -q --stats s.json
        echo "$s $T $(basename "$b") $(python3 -c "import json;s=json.load(open('s.json'));print(s['trace_seconds'], s['intersection_tests'])")"
      done
    done
  done
done
