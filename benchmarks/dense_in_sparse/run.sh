#!/bin/sh
# Issue 15's dense model in a sparse world against the model alone, both
# tracers, whole processes, alternating, five runs each; peak memory from
# /usr/bin/time. Usage, from this directory:
#   sh run.sh /path/to/sray ../../../shared/meshes/dragon_vrip.ply.gz [OLD_SRAY]
# With OLD_SRAY, its depth-first renders run beside the new ones (and the
# images must be identical). Breadth-first runs once each, under 64 MiB.
set -e
SRAY=$1; MESH=$2; OLD=$3
[ -f mesh.nff ] || "$SRAY" convert "$MESH" -o mesh.nff -q
[ -f alone.sdb ] || { python3 scene.py mesh.nff alone.nff 0 && "$SRAY" convert alone.nff -o alone.sdb -q; }
[ -f sparse.sdb ] || { python3 scene.py mesh.nff sparse.nff 20000 && "$SRAY" convert sparse.nff -o sparse.sdb -q; }
run() { # label binary scene mode [args]
  L=$1; B=$2; S=$3; M=$4; shift 4
  /usr/bin/time -f "$L $S $M %e s %M KB" "$B" render "$S.sdb" -o "${L}_${S}_$M.png" \
    --mode "$M" -q --stats "${L}_${S}_$M.json" "$@" 2>&1 | tail -1
}
for i in 1 2 3 4 5; do
  for S in alone sparse; do
    run new "$SRAY" $S df
    [ -z "$OLD" ] || run old "$OLD" $S df
  done
done
[ -z "$OLD" ] || { cmp new_alone_df.png old_alone_df.png && cmp new_sparse_df.png old_sparse_df.png && echo "old and new images identical"; }
for S in alone sparse; do run new "$SRAY" $S bf --memory 64MiB; done
cmp new_alone_df.png new_alone_bf.png && cmp new_sparse_df.png new_sparse_bf.png && echo "df and bf images identical"
