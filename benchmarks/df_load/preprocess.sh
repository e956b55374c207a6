#!/bin/sh
# The depth-first tracer's preprocessing (loading the objects and building
# the grids) of real meshes, a new and an old sray binary side by side:
# alternating runs, one and two threads, an 8x8 image so that tracing
# takes nothing. Prints one line a run:
#   mesh binary threads preprocess_seconds total_seconds peak_rss_kib
# Usage, from this directory (the meshes are converted once, by NEW):
#   sh preprocess.sh NEW_SRAY OLD_SRAY ../../../shared/meshes
set -e
NEW=$1; OLD=$2; MESHES=$3; RUNS=${RUNS:-5}
[ -f dragon.sdb ] || "$NEW" convert "$MESHES/dragon_vrip.ply.gz" -o dragon.sdb -q
[ -f armadillo.sdb ] || "$NEW" convert "$MESHES/armadillo.off" -o armadillo.sdb -q
[ -f bunny.sdb ] || "$NEW" convert "$MESHES/stanford-bunny.obj" -o bunny.sdb -q
for r in $(seq "$RUNS"); do
  for mesh in dragon armadillo bunny; do
    for T in 1 2; do
      for bin in "$NEW" "$OLD"; do
        /usr/bin/time -f "%M" -o rss.txt "$bin" render "$mesh.sdb" -o out.png \
          --mode df --depth 1 --threads "$T" --width 8 --height 8 -q --stats s.json
        echo "$mesh $bin $T $(python3 -c "import json;s=json.load(open('s.json'));print(s['preprocess_seconds'], s['total_seconds'])") $(cat rss.txt)"
      done
    done
  done
done
