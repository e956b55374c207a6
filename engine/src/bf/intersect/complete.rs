//! Completion: a ray whose result can no longer change (its best hit lies
//! before the far side of the last voxel it was stored in, or it has left
//! its grids) gives up its slot, and its result goes out: to the caller in
//! completion order, or into its place among the round's results.

use super::Shard;
use super::slot::{DONE, JOIN, WALKING, ray64};
use crate::bf::records::{Outcome, ResultRec};
use crate::bf::voxels::VoxelGrids;
use crate::grid::Dda;
use crate::simd::Elem;
use rayon::prelude::*;

/// Writes the finished rays' results into their places in `v` (ids count
/// from 0; `first` is added), every thread a contiguous part of `v`: each
/// shard first orders the indices of its finished hits by part (a
/// counting sort, 4 bytes a hit), so that no part looks at another's (a
/// sort of the results by id cost more than the writes). Misses are in
/// `v` already.
pub(super) fn put_results<R: Elem>(
    shards: &mut [Shard<R>],
    v: &mut [Outcome],
    first: u64,
    carry: bool,
    pool: &rayon::ThreadPool,
) {
    let parts = pool.current_num_threads().max(1);
    if parts == 1 {
        for sh in shards.iter() {
            for &slot in &sh.done {
                put(v, 0, sh, slot, carry, first);
            }
        }
        return;
    }
    let part = v.len().div_ceil(parts).max(1);
    pool.install(|| {
        shards.par_iter_mut().for_each(|sh| {
            let (done, order, bounds) = (&sh.done, &mut sh.order, &mut sh.bounds);
            let (hot, cold) = (&sh.hot, &sh.cold);
            // The id of the ray in `slot`, if it hit.
            let hit = |slot: u32| {
                let i = slot as usize;
                (!hot[i].best.prim.is_none()).then_some(cold[i].id)
            };
            bounds.clear();
            bounds.resize(parts + 1, 0);
            for id in done.iter().filter_map(|&slot| hit(slot)) {
                bounds[id as usize / part + 1] += 1;
            }
            for k in 0..parts {
                bounds[k + 1] += bounds[k];
            }
            order.clear();
            order.resize(bounds[parts], 0);
            // bounds[k] serves as part k's cursor, ending at part k's end
            // (the old bounds[k + 1]); shifted back by one afterwards.
            for (j, &slot) in done.iter().enumerate() {
                if let Some(id) = hit(slot) {
                    let k = id as usize / part;
                    order[bounds[k]] = j as u32;
                    bounds[k] += 1;
                }
            }
            for k in (0..parts).rev() {
                bounds[k + 1] = bounds[k];
            }
            bounds[0] = 0;
        });
        let shards = &*shards;
        v.par_chunks_mut(part).enumerate().for_each(|(k, dst)| {
            for sh in shards {
                for &j in &sh.order[sh.bounds[k]..sh.bounds[k + 1]] {
                    put(
                        dst,
                        (k * part) as u64,
                        sh,
                        sh.done[j as usize],
                        carry,
                        first,
                    );
                }
            }
        });
    });
}

/// Writes the result of the ray that finished in `slot` of `sh` at its
/// place in `dst`, which starts at id `lo`, if it is a hit.
#[inline]
pub(super) fn put<R: Elem>(
    dst: &mut [Outcome],
    lo: u64,
    sh: &Shard<R>,
    slot: u32,
    carry: bool,
    first: u64,
) {
    if !sh.hot[slot as usize].best.prim.is_none() {
        let o = sh.outcome(slot, carry);
        let at = (o.res.ray - lo) as usize;
        dst[at] = o;
        dst[at].res.ray += first;
    }
}

/// Finishes the rays whose result is complete, freeing their slots.
pub(super) fn complete<R: Elem>(sh: &mut Shard<R>, grids: &VoxelGrids) {
    let ngrids = grids.grids.len();
    for (i, ((h, c), q)) in sh
        .hot
        .iter_mut()
        .zip(sh.cold.iter_mut())
        .zip(sh.q.iter())
        .enumerate()
    {
        if !h.active {
            continue;
        }
        let best_t = h.best.t;
        // Without a hit (`best_t` infinite), no walk is done by its hit:
        // the walks need not be worked out again.
        let r = (best_t < f64::INFINITY).then(|| ray64(q, h, c));
        let done = h.blocked
            || (0..ngrids).all(|g| {
                let w = &mut c.walks[g];
                if w.state == WALKING
                    && let Some(r) = &r
                {
                    // The far side of the voxel the walk stopped in.
                    let cell = w.last.map(u32::from);
                    let spec = &grids.grids[g].spec;
                    let t_exit = Dda::start_at(spec, r.o, r.d, r.inv, r.t_min, r.t_max, cell)
                        .map_or(f64::NEG_INFINITY, |d| d.t_exit());
                    if best_t < t_exit {
                        w.state = DONE;
                    }
                }
                w.state == DONE
            });
        if done {
            sh.done.push(i as u32);
            h.active = false;
        }
    }
}

impl<R: Elem> Shard<R> {
    /// The result of the ray that finished in `slot` (which keeps it until
    /// the slot is filled again), with its surface when `carry`.
    #[inline]
    pub(super) fn outcome(&self, slot: u32, carry: bool) -> Outcome {
        let (h, c) = (&self.hot[slot as usize], &self.cold[slot as usize]);
        let res = ResultRec {
            ray: c.id,
            prim: h.best.prim,
            t: h.best.t,
        };
        if carry && !h.shadow && h.best.is_some() && c.material != JOIN {
            Outcome {
                res,
                ng: c.ng.to_array(),
                ns: c.ns.to_array(),
                material: c.material,
                has_surface: 1,
            }
        } else {
            Outcome::bare(res)
        }
    }
}
