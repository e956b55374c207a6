#!/bin/sh
# Issue 15's dense model in a sparse world against the model alone, both
# tracers, whole processes, alternating, five runs each; peak memory from
# /usr/bin/time. Usage, from this directory:
#   sh run.sh /path/to/sray ../../../shared/meshes/dragon_vrip.ply.gz [OLD_SRAY]
# With OLD_SRAY, its renders run beside the new ones, each binary on a
# database it converted itself (an older sray may not read a newer
# database), and the images must be identical. Breadth-first runs once
# per binary and scene, under 64 MiB.
set -e
SRAY=$1; MESH=$2; OLD=$3
[ -f mesh.nff ] || "$SRAY" convert "$MESH" -o mesh.nff -q
[ -f alone.nff ] || python3 scene.py mesh.nff alone.nff 0
[ -f sparse.nff ] || python3 scene.py mesh.nff sparse.nff 20000
db() { # label binary
  for S in alone sparse; do
    [ -f "$1_$S.sdb" ] || "$2" convert "$S.nff" -o "$1_$S.sdb" -q
  done
}
db new "$SRAY"
[ -z "$OLD" ] || db old "$OLD"
run() { # label binary scene mode [args]
  L=$1; B=$2; S=$3; M=$4; shift 4
  /usr/bin/time -f "$L $S $M %e s %M KB" "$B" render "${L}_$S.sdb" -o "${L}_${S}_$M.png" \
    --mode "$M" -q --stats "${L}_${S}_$M.json" "$@" 2>&1 | tail -1
}
for i in 1 2 3 4 5; do
  for S in alone sparse; do
    run new "$SRAY" $S df
    [ -z "$OLD" ] || run old "$OLD" $S df
  done
done
for S in alone sparse; do
  run new "$SRAY" $S bf --memory 64MiB
  [ -z "$OLD" ] || run old "$OLD" $S bf --memory 64MiB
done
for S in alone sparse; do
  cmp "new_${S}_df.png" "new_${S}_bf.png"
  [ -z "$OLD" ] || { cmp "new_${S}_df.png" "old_${S}_df.png" && cmp "new_${S}_bf.png" "old_${S}_bf.png"; }
done
echo "images identical"
