#!/bin/sh
# Aggregates (issue 15): the dense-in-sparse scenes of
# ../dense_in_sparse (its scene.py writes alone.nff and sparse.nff into
# SCENE_DIR), rendered by this binary with its default aggregates
# (breadth-first), with --aggregates off and (depth-first) on, and by an
# older binary, with one grid (--grids 1, the paper's setup,
# where the dragon crowds a few voxels of a grid sized for the floor) and
# with the default grids (a dense region gets a grid of its own).
# Whole processes, alternating, ROUNDS rounds; peak memory from
# /usr/bin/time; one line per render with the stats that matter.
# Usage:
#   sh run.sh NEW_SRAY OLD_SRAY SCENE_DIR ROUNDS [CONFIG...]
# CONFIG names what to run: df1 bf1 df bf (default: all four).
set -e
NEW=$1; OLD=$2; DIR=$3; ROUNDS=$4; shift 4
CONFIGS=${*:-df1 bf1 df bf}
cd "$DIR"
for S in alone sparse; do
  [ -f "new_$S.sdb" ] || "$NEW" convert "$S.nff" -o "new_$S.sdb" -q
  [ -f "old_$S.sdb" ] || "$OLD" convert "$S.nff" -o "old_$S.sdb" -q
done
run() { # label binary scene config [args]
  L=$1; B=$2; S=$3; C=$4; shift 4
  case $C in
    df1) A="--mode df --grids 1" ;;
    bf1) A="--mode bf --memory 64MiB --grids 1" ;;
    df) A="--mode df" ;;
    bf) A="--mode bf --memory 64MiB" ;;
  esac
  T=$( { /usr/bin/time -f "%e %M" "$B" render "${L%-*}_$S.sdb" -o "${L}_${S}_$C.png" $A -q \
        --stats "${L}_${S}_$C.json" "$@" 2>&1 >/dev/null; } | tail -1)
  python3 - "$L" "$S" "$C" "$T" "${L}_${S}_$C.json" <<'PY'
import json, sys
l, s, c, t, f = sys.argv[1:]
d = json.load(open(f))
secs, kb = t.split()
g = d.get("grids", [])
print(f"{l:14} {s:6} {c:4} {float(secs):7.2f} s {int(kb)/1024:6.0f} MiB"
      f"  tests {d['intersection_tests']:>11}  aggregates {sum(x.get('aggregates', 0) for x in g):>6}"
      f"  walks {d.get('aggregate_walks', 0) or 0:>9}  nested voxels {sum(x.get('nested_voxels', 0) for x in g):>5}"
      f"  read {d.get('db_bytes_read', 0)/1e6:8.1f} MB")
PY
}
i=0
while [ $i -lt "$ROUNDS" ]; do
  i=$((i + 1))
  for C in $CONFIGS; do
    for S in alone sparse; do
      run new "$NEW" $S $C
      run new-off "$NEW" $S $C --aggregates off
      case $C in df*) run new-on "$NEW" $S $C --aggregates on ;; esac
      run old "$OLD" $S $C
    done
  done
done
for C in $CONFIGS; do
  for S in alone sparse; do
    cmp "new_${S}_$C.png" "old_${S}_$C.png"
    cmp "new_${S}_$C.png" "new-off_${S}_$C.png"
    case $C in df*) cmp "new_${S}_$C.png" "new-on_${S}_$C.png" ;; esac
  done
done
echo "images identical"
