#!/bin/bash
# Table 3 side by side: two sray binaries alternating, three runs each, one
# line per run (binary, scene, run, total s, preprocess s, scans, bytes
# read, intersection tests, slot bytes, slot base bytes, passes per round,
# peak MiB).
# usage: table3.sh NEW_SRAY OLD_SRAY DIR
# DIR holds mount11.sdb, rings80.sdb and tetra12.sdb, made with
#   sray gen mount --size 11 -o DIR/mount11.sdb --compress zstd
#   sray gen rings --size 80 -o DIR/rings80.sdb --compress zstd
#   sray gen tetra --size 12 -o DIR/tetra12.sdb --compress zstd
NEW=$1; OLD=$2; cd "${3:-.}"
for i in 1 2 3; do
 for s in mount11 rings80 tetra12; do
  for b in NEW OLD; do
   bin=${!b}
   /usr/bin/time -v -o /tmp/tv.txt $bin render $s.sdb -o /tmp/t3_$b.png --mode bf --memory 256MiB --stats /tmp/t3_$b.json >/dev/null 2>&1
   peak=$(grep "Maximum resident" /tmp/tv.txt | awk '{print $6}')
   python3 - "$b" "$s" "$i" "$peak" <<'PY'
import json,sys
b,s,i,peak=sys.argv[1:]
d=json.load(open(f'/tmp/t3_{b}.json'))
print(b,s,i,round(d['total_seconds'],2),round(d['preprocess_seconds'],2),d['db_scans'],d['db_bytes_read'],d['intersection_tests'],d['budget']['slot_bytes'],d['budget'].get('slot_base_bytes','-'),d['passes'],int(peak)//1024, flush=True)
PY
  done
 done
done
