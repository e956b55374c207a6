#!/bin/bash
# 3 reps, configurations alternating; each render capped at 15 min
cd "${1:-.}"
CONFIGS="d1024:auto d64:auto d64flat:auto d1024:bf d64:bf"
for rep in 1 2 3; do
  for c in $CONFIGS; do
    db=${c%%:*}; mode=${c##*:}; tag=${db}_${mode}_r${rep}
    echo "$(date +%T) start $tag"
    timeout 900 /usr/bin/time -v ${SRAY:-sray} render $db.sdb --width 512 --height 512 --memory 1GiB --mode $mode \
        -o $tag.png --stats $tag.json -q > logs/$tag.out 2> logs/$tag.time
    echo "$(date +%T) end $tag rc=$?"
  done
done
