#!/bin/bash
# Bounded-memory glTF conversion, two binaries side by side (BENCHMARKS.md,
# "glTF files larger than memory").
# Usage: run.sh NEW_SRAY OLD_SRAY DIR   (DIR holds many48.glb and one.glb from make_many.py)
set -u
new=$1 old=$2
cd "$3"
t() { /usr/bin/time -f "%e s %M KiB" "$@" 2>&1 >/dev/null | tail -1; }
for round in 1 2 3; do
  for m in 64MiB 2GiB; do
    echo "round $round new many48 $m: $(t "$new" convert many48.glb -o new_$m.sdb --memory $m)"
    echo "round $round old many48 $m: $(t "$old" convert many48.glb -o old_$m.sdb --memory $m)"
  done
  for m in 8MiB 1GiB; do
    echo "round $round new one $m: $(t "$new" convert one.glb -o one_new_$m.sdb --memory $m)"
    echo "round $round old one $m: $(t "$old" convert one.glb -o one_old_$m.sdb --memory $m)"
  done
done
md5sum ./*.sdb
