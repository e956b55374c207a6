//! Completion: a ray whose result can no longer change (its best hit lies
//! before the far side of the last voxel it was stored in, or it has left
//! its grids) gives up its slot, and its result goes out: to the caller in
//! completion order, or into its place among the round's results (written
//! by the shard's own thread as it finishes the ray).

use super::Shard;
use super::slot::{Cold, DONE, Hot, JOIN, WALKING, ray64};
use crate::bf::records::{Outcome, ResultRec};
use crate::bf::voxels::VoxelGrids;
use crate::grid::Dda;
use crate::simd::Elem;
use std::marker::PhantomData;

/// A round's dense results (ids count from 0), written by every shard's
/// thread at once as its rays finish: each at its own rays' places.
/// Misses are in place already.
pub(super) struct ResultPlaces<'a> {
    at: *mut Outcome,
    len: usize,
    /// Added to the ids written.
    first: u64,
    _v: PhantomData<&'a mut [Outcome]>,
    /// The places written (checked in debug builds, the tests': a place
    /// written twice breaks `put`'s contract).
    #[cfg(debug_assertions)]
    written: Vec<std::sync::atomic::AtomicBool>,
}

// SAFETY: a `ResultPlaces` only writes through `at`, through
// `ResultPlaces::put`, whose contract is that no two threads write the
// same place while it lives; sharing it between threads is then sharing
// `&mut [Outcome]` split into disjoint parts, which is sound.
unsafe impl Sync for ResultPlaces<'_> {}

impl<'a> ResultPlaces<'a> {
    pub(super) fn new(v: &'a mut [Outcome], first: u64) -> ResultPlaces<'a> {
        ResultPlaces {
            at: v.as_mut_ptr(),
            len: v.len(),
            first,
            _v: PhantomData,
            #[cfg(debug_assertions)]
            written: (0..v.len()).map(|_| Default::default()).collect(),
        }
    }

    /// Writes `o` at the place of its ray.
    ///
    /// # Safety
    ///
    /// No other thread may write that place while `self` lives. A ray id
    /// is in one slot of one shard at a time, and a slot finishes its ray
    /// once (it is then refilled only in the next pass's fill): the
    /// shards' threads finishing the rays of one pass write distinct
    /// places.
    unsafe fn put(&self, mut o: Outcome) {
        let i = o.res.ray as usize;
        assert!(
            i < self.len,
            "ray {i} has no place among {} results",
            self.len
        );
        #[cfg(debug_assertions)]
        assert!(
            !self.written[i].swap(true, std::sync::atomic::Ordering::Relaxed),
            "ray {i}'s result written twice in one pass"
        );
        o.res.ray += self.first;
        // SAFETY: `i` is in bounds (checked above), `at` points to `len`
        // initialised `Outcome`s borrowed mutably for `'a` (so nothing
        // else reads or writes them meanwhile), and by the caller's
        // contract no other thread writes place `i` concurrently.
        unsafe { self.at.add(i).write(o) };
    }
}

/// Finishes the rays whose result is complete, freeing their slots; with
/// `places`, writes the hits' results there (while the slots are in
/// cache, on the shard's own thread).
pub(super) fn complete<R: Elem>(
    sh: &mut Shard<R>,
    grids: &VoxelGrids,
    places: Option<&ResultPlaces<'_>>,
    carry: bool,
) {
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
            if let Some(places) = places
                && !h.best.prim.is_none()
            {
                // SAFETY: this slot's ray finishes here, once (see
                // `ResultPlaces::put`).
                unsafe { places.put(outcome(h, c, carry)) };
            }
        }
    }
}

impl<R: Elem> Shard<R> {
    /// The result of the ray that finished in `slot` (which keeps it until
    /// the slot is filled again), with its surface when `carry`.
    #[inline]
    pub(super) fn outcome(&self, slot: u32, carry: bool) -> Outcome {
        outcome(&self.hot[slot as usize], &self.cold[slot as usize], carry)
    }
}

/// The result of the ray whose slot holds `h` and `c`, with its surface
/// when `carry`.
#[inline]
fn outcome<R: Elem>(h: &Hot<R>, c: &Cold<R>, carry: bool) -> Outcome {
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
