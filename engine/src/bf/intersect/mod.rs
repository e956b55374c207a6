//! Intersecting one round's rays breadth-first: the paper's Pseudocode 3
//! with ray filling (Section 2.3, Fig. 5c).
//!
//! Rays live in a fixed number of slots. Each pass:
//!
//! 1. **fill**: empty slots take the next waiting rays;
//! 2. **register**: each ray walks its grids (3D-DDA) and stores itself in
//!    up to `store number` voxels where it enters some object's voxel
//!    boundary (a flagged face), or in the voxel it starts in (Fig. 4);
//! 3. **scan**: the objects are read front to back; each is tested against
//!    the rays stored in its voxels, unless the ray tested it already
//!    (mailbox) or the ray's last voxel of the previous pass lies in the
//!    object's voxel box, which means it was tested then (Fig. 5b);
//! 4. **complete**: a ray is finished in a grid when its best hit lies
//!    before the far side of the last voxel it was stored in, or its walk
//!    has left the grid; finished rays write their result and free their
//!    slot. A shadow ray finishes at its first blocker.
//!
//! The store number follows each ray: it starts at the grid's base (its
//! resolution / 10, the paper's choice) and doubles with every pass the
//! ray survives, up to the resolution. Rays that survive many passes are
//! few (their number falls exponentially, Fig. 3), so the memory freed by
//! finished rays pays for the larger numbers: the paper's two adaptive
//! methods, applied per ray. Because a ray's registrations depend only on
//! the ray, every count is the same whatever the number of threads,
//! workers, slots or memory. (The budget's store number,
//! [`StoreNumber::Budget`](crate::bf::StoreNumber::Budget), trades that for
//! fewer passes: a round's last pass extends the walks it cut short.)
//!
//! Slots are split into shards, one per thread; every thread scans the same
//! decoded block for its own rays, so no ray is touched by two threads
//! while it is traced (a finished ray's result is a copy, which another
//! thread may write to its place).
//!
//! This module holds the pass loop ([`intersect_rays`]) and the shards;
//! each stage has a module of its own: [`slot`] (what a ray slot holds),
//! [`admit`] (fill), [`register`], [`scan`] and [`complete`].

use super::candidates::{Candidate, Found, NO_REGION, Region, candidates};
use super::records::{Outcome, RayRec, ResultRec};
use super::regmap::RegMap;
use super::skip::Touched;
use super::store::StorePlan;
use super::voxels::{BLOCK_SHIFT, OCCUPIED, VoxelGrid, VoxelGrids, entry_face};
use crate::error::Error;
use crate::grid::nested::{Entry, high_first, ray_meets};
use crate::grid::{Dda, GridSpec};
use crate::hit::{Hit, PrimId};
use crate::intersect::{Attrs, RayQ};
use crate::kernels::{Found as LaneHits, LANES, RayLanes};
use crate::models::{Models, Placement};
use crate::progress::Progress;
use crate::render::{Cutouts, KindCounts};
use crate::sdb::{Block, Database, ObjectRef};
use crate::shapes::{Prepared, Shape};
use crate::simd::{Elem, Isa};
use rayon::prelude::*;
use serde::Serialize;

mod admit;
mod complete;
mod register;
mod scan;
mod slot;
use admit::{ByIdFill, Dealer, load, misses_every_grid, stage};
use complete::{ResultPlaces, complete};
pub use register::sample_registrations;
use register::{extend, register};
use scan::{ScanPass, pair_bytes, scan_block, test_pairs};
use slot::{Cold, DONE, FRESH, Hot, JOIN, NONE16, WALKING, empty_cold, empty_hot, od64, ray64};
pub use slot::{
    MAX_GRIDS, REGISTRATION_BYTES, VOXEL_BYTES, WORST_REGISTRATION_BYTES, slot_bytes,
    streamed_extra_bytes,
};

/// Counters of one pass.
#[derive(Clone, Copy, Debug, Default)]
struct PassCounts {
    tests: KindCounts,
    skipped_mailbox: u64,
    skipped_last_voxel: u64,
    /// Walks of an aggregate's hierarchy.
    aggregate_walks: u64,
}

/// A ray given a slot from a stream since the last pass: its slot, where
/// [`stage`] put what its shard's thread needs to [`load`] it.
type Pending = u32;

/// One thread's rays and their registrations. Aligned to its own cache
/// lines (two, as the hardware prefetches lines in pairs): the shards lie
/// side by side in one vector, and each thread writes its own shard's
/// counters at every intersection test, so a line shared by two shards
/// would travel between the cores at every test (false sharing). Unpadded,
/// whether the two shards shared a line depended on where the allocator
/// put the vector: any change in the process's earlier allocations (an
/// extra command-line option, a worker process instead of `sray render`)
/// made the intersection 15-20 % slower at two threads.
#[repr(align(128))]
struct Shard<R: Elem> {
    hot: Vec<Hot<R>>,
    q: Vec<RayQ<R>>,
    cold: Vec<Cold<R>>,
    /// Rays given a slot since the last pass, when they come from a
    /// stream: filling is then serial, as rays come in order from one
    /// source, and only stages each ray in its slot; preparing a ray for
    /// its walk and tests is not, so each shard does it for its own. (Rays
    /// that can be had by id are loaded by their shard straight from the
    /// source.)
    pending: Vec<Pending>,
    regs: [RegMap; MAX_GRIDS],
    region: [Region; MAX_GRIDS],
    counts: PassCounts,
    /// The slots whose rays finished this pass: their results are read
    /// from the slots (see [`Shard::outcome`]), which keep them until the
    /// next pass fills them again.
    done: Vec<u32>,
    /// Slots holding a ray.
    live: usize,
    /// Store numbers of the walks registered this pass, and their number.
    store_sum: u64,
    store_walks: u64,
    /// Rays registered this pass.
    registered: u64,
    /// Registrations this pass, before any walk is extended.
    used: u64,
    /// Some active ray did not register this pass (its share was used).
    left_out: bool,
    /// Walks stopped by their store number this pass (counted with the
    /// budget's store number only).
    cut: u64,
    /// When models are read per pass: the instances met this pass, and
    /// the rays (slots) registered near each, tested once the model is
    /// read after the world's objects.
    placed: Vec<(u32, u32, Placement)>,
    pairs: Vec<Pair>,
    /// One object's rays gathered for its kernel.
    gather: Box<scan::Gather<R>>,
}

/// A ray and an instance to test it against (an index into
/// `Shard::placed`).
#[derive(Clone, Copy, Debug)]
struct Pair {
    slot: u32,
    placed: u32,
}

/// Statistics of one round's intersection.
#[derive(Clone, Debug, Default, Serialize)]
pub struct IntersectStats {
    pub rays: u64,
    pub passes: u64,
    /// Rays not yet finished at the start of each pass (in memory or
    /// waiting), as the paper's Fig. 3.
    pub remaining_rays_per_pass: Vec<u64>,
    /// Mean store number of the rays registered in each pass.
    pub store_numbers: Vec<f64>,
    pub registrations: u64,
    /// Voxels rays were registered in, summed over the passes (once a
    /// pass, however many shards registered rays there).
    pub registered_voxels: u64,
    /// Rays that registered, summed over the passes (a ray counts once
    /// per pass it registers in).
    pub registered_rays: u64,
    pub intersection_tests: KindCounts,
    pub tests_skipped_mailbox: u64,
    pub tests_skipped_last_voxel: u64,
    /// Rays that walked an aggregate's hierarchy (see
    /// [`crate::grid::aggregate`]).
    pub aggregate_walks: u64,
    pub db_scans: u64,
    pub db_bytes_read: u64,
    /// Blocks the passes left unread (no registered ray near them).
    pub db_blocks_skipped: u64,
    /// Models read by the passes (when they are not held).
    pub model_reads: u64,
}

/// What the intersection stage is given.
pub struct IntersectSetup<'a> {
    pub db: &'a Database,
    /// The models the database's instances place.
    pub models: &'a Models,
    /// Models are not held: each pass reads those its instances' rays
    /// need, after the world's objects (see [`crate::models`]).
    pub models_per_pass: bool,
    /// Bytes of (ray, instance) pairs and placements the shards may
    /// gather in a pass before the models they need are read and tested:
    /// past it a pass reads those models again (same hits, more tests).
    pub pairs_cap: usize,
    pub grids: &'a mut VoxelGrids,
    pub store: StorePlan,
    /// Ray slots in memory.
    pub slots: usize,
    /// Bytes the registrations of a pass may take, at most (counted by
    /// [`REGISTRATION_BYTES`] and [`VOXEL_BYTES`]).
    pub registration_bytes: usize,
    /// Grids of at most this many voxels get a dense voxel index per shard.
    pub dense_cells: usize,
    pub eps: f64,
    /// Trace crowded groups of objects as aggregates (see [`Found`]); off
    /// for the paper's passes.
    pub aggregates: bool,
    /// How far from its box an object's hit may be computed
    /// ([`crate::grid::box_slack`]).
    pub slack: f64,
    /// Work out the surface at each ray's best hit as it is found, so that
    /// shading needs no pass over the objects.
    pub carry: bool,
    /// Read (and decompress) each pass's blocks on a thread of their own,
    /// this many blocks a batch, a batch ahead of the shards (0: read on
    /// the shards' thread).
    pub read_ahead: usize,
    /// The kernels' instruction set.
    pub isa: Isa,
}

/// The ray slots, kept from round to round so that their memory is
/// allocated once.
pub struct Slots<R: Elem> {
    shards: Vec<Shard<R>>,
    /// The candidates of a batch of blocks, one per block.
    found: Vec<Found>,
    /// The coarse cells this pass has rays in (which blocks it skips).
    touched: Touched,
}

impl<R: Elem> Slots<R> {
    pub fn new(threads: usize) -> Slots<R> {
        Slots {
            shards: (0..threads.max(1))
                .map(|_| Shard {
                    hot: Vec::new(),
                    q: Vec::new(),
                    cold: Vec::new(),
                    pending: Vec::new(),
                    regs: Default::default(),
                    region: [NO_REGION; MAX_GRIDS],
                    counts: PassCounts::default(),
                    done: Vec::new(),
                    live: 0,
                    store_sum: 0,
                    store_walks: 0,
                    registered: 0,
                    used: 0,
                    left_out: false,
                    cut: 0,
                    placed: Vec::new(),
                    pairs: Vec::new(),
                    gather: scan::Gather::new(),
                })
                .collect(),
            touched: Touched::default(),
            found: Vec::new(),
        }
    }

    /// Bytes the slots hold.
    pub fn bytes(&self) -> usize {
        use std::mem::size_of;
        self.shards
            .iter()
            .map(|sh| {
                sh.hot.capacity() * size_of::<Hot<R>>()
                    + sh.pending.capacity() * size_of::<Pending>()
                    + sh.q.capacity() * size_of::<RayQ<R>>()
                    + sh.cold.capacity() * size_of::<Cold<R>>()
                    + sh.done.capacity() * size_of::<u32>()
                    + sh.regs.iter().map(RegMap::bytes).sum::<usize>()
                    + sh.placed.capacity() * size_of::<(u32, u32, Placement)>()
                    + sh.pairs.capacity() * size_of::<Pair>()
            })
            .sum::<usize>()
    }

    /// Gives the slots' memory back at the end of a round's intersection,
    /// so that shading can use the same share of the budget.
    pub fn release(&mut self) {
        self.found = Vec::new();
        for sh in self.shards.iter_mut() {
            sh.hot = Vec::new();
            sh.q = Vec::new();
            sh.cold = Vec::new();
            sh.done = Vec::new();
            sh.pending = Vec::new();
            sh.regs = Default::default();
            sh.placed = Vec::new();
            sh.pairs = Vec::new();
        }
    }

    /// Makes room for `n` rays in all, split evenly over the shards.
    fn ensure(&mut self, n: usize, streamed: bool) {
        let per = n.div_ceil(self.shards.len()).max(1);
        let q0 = RayQ::new(
            crate::math::V3::zero(),
            crate::math::V3::new(R::ONE, R::ZERO, R::ZERO),
        );
        for sh in self.shards.iter_mut() {
            sh.live = 0;
            sh.hot.clear();
            sh.hot.resize(per, empty_hot());
            sh.q.resize(per, q0);
            sh.cold.resize(per, empty_cold());
            sh.q.truncate(per);
            sh.cold.truncate(per);
            // At most every slot waits to be loaded: no growth mid-fill.
            sh.pending.clear();
            if streamed {
                sh.pending.reserve_exact(per);
            } else {
                sh.pending = Vec::new();
            }
        }
    }
}

/// Where a run's rays come from.
pub enum RaySource<'a> {
    /// In id order, one after the other (a file being read).
    Stream(&'a mut dyn Iterator<Item = Result<RayRec, Error>>),
    /// Ray `i` of the run's `len`, made or looked up on demand by any
    /// thread (eye rays, rays in memory).
    Indexed {
        len: u64,
        ray: &'a (dyn Fn(u64) -> RayRec + Sync),
    },
}

/// Rays read in id order.
type RayStream<'a> = &'a mut dyn Iterator<Item = Result<RayRec, Error>>;
/// Where finished rays' results go, one by one.
type Emit<'a> = &'a mut dyn FnMut(Outcome) -> Result<(), Error>;

/// Where a run's results go.
pub enum ResultSink<'a> {
    /// Each finished ray's result, in completion order, misses included.
    Each(&'a mut dyn FnMut(Outcome) -> Result<(), Error>),
    /// Hits written at their ray's place, with `first` added to the ray
    /// id; the buffer (one entry per ray) holds misses already.
    Dense { v: &'a mut [Outcome], first: u64 },
}

/// Each shard's empty slots, where the next pass's rays go.
fn empty_slots<R: Elem>(shards: &[Shard<R>]) -> Vec<usize> {
    shards
        .iter()
        .map(|sh| {
            debug_assert_eq!(
                sh.hot.len() - sh.live,
                sh.hot.iter().filter(|h| !h.active).count()
            );
            sh.hot.len() - sh.live
        })
        .collect()
}

/// Intersects the `total` rays of `source` (ids `0, 1, ...`), giving each
/// ray's result to `sink`: to its callback in completion order, or into
/// its place in a dense buffer.
#[allow(clippy::too_many_arguments)]
pub fn intersect_rays<R: Elem>(
    setup: &mut IntersectSetup<'_>,
    pool: &rayon::ThreadPool,
    slots: &mut Slots<R>,
    source: RaySource<'_>,
    total: u64,
    sink: ResultSink<'_>,
    progress: &dyn Progress,
) -> Result<IntersectStats, Error> {
    if let RaySource::Indexed { len, .. } = &source
        && *len != total
    {
        return Err(Error::Invalid(format!("{len} rays given for {total}")));
    }
    if let ResultSink::Dense { v, .. } = &sink
        && v.len() as u64 != total
    {
        return Err(Error::Invalid(format!(
            "a result buffer of {} for {total} rays",
            v.len()
        )));
    }
    // No more slots than rays. Rays had by id with results put in place
    // (`ByIdFill`) need no queue.
    let streamed = !matches!(
        (&source, &sink),
        (RaySource::Indexed { .. }, ResultSink::Dense { .. })
    );
    slots.ensure((setup.slots as u64).min(total).max(1) as usize, streamed);
    let shards = &mut slots.shards;
    let ngrids = setup.grids.grids.len();
    // Rays that can be had by id, with results that have a place each:
    // which rays a pass admits is worked out with every thread looking
    // (`ByIdFill`), each shard loads its own, and each shard's thread
    // writes its finished rays' results to their places (`complete`,
    // `ResultPlaces`). Else this thread
    // fills the slots in order from the stream and passes results on.
    let mut by_id: Option<ByIdFill<'_>> = None;
    let mut dense: Option<(&mut [Outcome], u64)> = None;
    let mut stream_of_indexed;
    let mut dense_emit;
    let (rays, emit): (RayStream<'_>, Emit<'_>) = match (source, sink) {
        (RaySource::Indexed { ray, .. }, ResultSink::Dense { v, first }) => {
            by_id = Some(ByIdFill {
                ray,
                total,
                next: 0,
                sky: Vec::new(),
                ids: Vec::new(),
                dealt: Vec::new(),
            });
            dense = Some((v, first));
            (&mut std::iter::empty(), &mut |_| Ok(()))
        }
        (source, sink) => {
            let rays: RayStream<'_> = match source {
                RaySource::Stream(it) => it,
                RaySource::Indexed { len, ray: f } => {
                    stream_of_indexed = (0..len).map(move |i| Ok(f(i)));
                    &mut stream_of_indexed
                }
            };
            let emit: Emit<'_> = match sink {
                ResultSink::Each(e) => e,
                ResultSink::Dense { v, first } => {
                    dense_emit = move |mut r: Outcome| {
                        if !r.res.prim.is_none() {
                            let i = r.res.ray as usize;
                            r.res.ray += first;
                            v[i] = r;
                        }
                        Ok(())
                    };
                    &mut dense_emit
                }
            };
            (rays, emit)
        }
    };
    let mut st = IntersectStats {
        rays: total,
        ..Default::default()
    };
    let mut next_id: u64 = 0;
    let mut exhausted = false;
    let mut finished: u64 = 0;
    let mut active: u64 = 0;
    // Rays that left at once and are not yet counted in the progress.
    let mut sky: u64 = 0;
    if by_id.is_some() {
        // Admitted by `ByIdFill`, loaded by the shards themselves.
        exhausted = true;
    }
    loop {
        // From a stream: fill empty slots, dealt to the shards in turn
        // (each shard's in slot order). A ray that meets no grid's box
        // (the sky around a model) is a miss at once and takes no slot.
        // (Rays by id: the same, through `ByIdFill`.)
        if !exhausted {
            let mut dealer = Dealer::new(empty_slots(shards));
            let mut next_free = vec![0usize; shards.len()];
            while let Some(k) = dealer.next_shard() {
                // The stream's next ray that meets some grid.
                let next = loop {
                    let Some(r) = rays.next() else { break None };
                    let r = r?;
                    let id = next_id;
                    next_id += 1;
                    if !misses_every_grid(&r, setup.grids, setup.eps) {
                        break Some((id, r));
                    }
                    finished += 1;
                    // Counted in batches: a progress update costs more
                    // than such a ray.
                    sky += 1;
                    if sky == 1 << 16 {
                        progress.inc(std::mem::take(&mut sky));
                    }
                    emit(Outcome::bare(ResultRec {
                        ray: id,
                        prim: PrimId::NONE,
                        t: f64::INFINITY,
                    }))?;
                };
                let Some((id, r)) = next else {
                    exhausted = true;
                    break;
                };
                let (sh, at) = (&mut shards[k], &mut next_free[k]);
                // (The dealer gives a shard no more rays than it has
                // empty slots.)
                while sh.hot[*at].active {
                    *at += 1;
                }
                // Loaded by the shard's thread before it registers
                // (below); taken from now on.
                stage(sh, *at, id, &r, setup.eps);
                sh.pending.push(*at as u32);
                active += 1;
            }
        }
        if let Some(fill) = by_id.as_mut() {
            let passed = fill.admit(&empty_slots(shards), pool, setup.grids, setup.eps);
            finished += passed;
            sky += passed;
            active += fill.ids.len() as u64;
        }
        progress.inc(std::mem::take(&mut sky));
        if active == 0 {
            break;
        }
        st.remaining_rays_per_pass.push(total - finished);
        st.passes += 1;
        progress.set_message(&format!(
            "pass {}, {} rays left",
            st.passes,
            total - finished
        ));

        // Register, per shard: each shard takes its rays in slot order
        // while its share of the registrations lasts. A ray reserves
        // nothing beforehand; it registers what its walk finds (up to its
        // store number per grid), so the last ray admitted may overrun the
        // share by at most one ray's store numbers, which the budget
        // allows for. A ray left out waits for the next pass unchanged:
        // what it registers, and so every count, does not depend on when.
        let grids = &*setup.grids;
        let store = setup.store;
        let dense_cells = setup.dense_cells;
        let share = (setup.registration_bytes / shards.len()).max(1) as u64;
        let eps = setup.eps;
        let admitted = by_id.as_ref().map(|f| (f.ray, &f.dealt[..]));
        pool.install(|| {
            shards.par_iter_mut().enumerate().for_each(|(k, sh)| {
                let pending = std::mem::take(&mut sh.pending);
                for &i in &pending {
                    load(sh, i as usize);
                }
                sh.pending = pending;
                sh.pending.clear();
                if let Some((ray, dealt)) = admitted {
                    let mut mine = dealt[k].iter();
                    for i in 0..sh.hot.len() {
                        if sh.hot[i].active {
                            continue;
                        }
                        let Some(&id) = mine.next() else { break };
                        stage(sh, i, id, &ray(id), eps);
                        load(sh, i);
                    }
                }
                let expect = (share as usize / WORST_REGISTRATION_BYTES).clamp(1024, 1 << 20);
                for g in 0..ngrids {
                    let cells = grids.grids[g].spec.cells();
                    sh.regs[g].clear(expect, if cells <= dense_cells { cells } else { 0 });
                    sh.region[g] = NO_REGION;
                }
                sh.store_sum = 0;
                sh.store_walks = 0;
                sh.registered = 0;
                sh.left_out = false;
                sh.cut = 0;
                let (mut used, mut regs_made) = (0u64, 0u64);
                for i in 0..sh.hot.len() {
                    let h = &sh.hot[i];
                    if !h.active || h.blocked {
                        continue;
                    }
                    if used >= share {
                        sh.left_out = true;
                        continue;
                    }
                    let (sum, walks) = register(
                        &mut sh.hot[i],
                        &sh.q[i],
                        &mut sh.cold[i],
                        i as u32,
                        grids,
                        &store,
                        &mut sh.regs,
                        &mut sh.region,
                    );
                    sh.store_sum += sum;
                    sh.store_walks += walks;
                    sh.registered += 1;
                    used = sh.regs.iter().map(RegMap::used_bytes).sum::<usize>() as u64;
                    regs_made = sh.regs.iter().map(RegMap::len).sum::<usize>() as u64;
                    if store.extends() {
                        sh.cut += sh.cold[i].walks[..ngrids]
                            .iter()
                            .filter(|w| w.state == WALKING)
                            .count() as u64;
                    }
                }
                sh.used = regs_made;
            })
        });
        // With the budget's store number: in a round's last pass (no ray
        // waits for a slot), what the pass's rays left of the
        // registrations goes to the walks their store numbers cut short,
        // shared evenly, so that they need no pass (and scan) of their
        // own. Not before: a pass follows anyway, and a longer walk
        // registered before the scan costs tests wherever the ray finds
        // its hit early. Only when every ray registered (none waited for
        // room: its walk would go on from where the last pass left it,
        // before the last-voxel rule's voxel moved on). Which rays wait
        // when room runs short depends on the threads' shares, so then
        // the work counts do too.
        let waiting = total - finished - active;
        let extra = if store.extends() && waiting == 0 && !shards.iter().any(|sh| sh.left_out) {
            // Counted as if each registration had a voxel of its own: the
            // most they may take, and a count that does not depend on how
            // the shards share the voxels (nor, so, on the threads).
            let used: u64 = shards.iter().map(|sh| sh.used).sum();
            let cut: u64 = shards.iter().map(|sh| sh.cut).sum();
            let left = (setup.registration_bytes / WORST_REGISTRATION_BYTES) as u64;
            (left.saturating_sub(used) / cut.max(1)).min(u32::MAX as u64) as u32
        } else {
            0
        };
        pool.install(|| {
            shards.par_iter_mut().for_each(|sh| {
                if extra > 0 && sh.cut > 0 {
                    for i in 0..sh.hot.len() {
                        let h = &sh.hot[i];
                        if h.active && !h.blocked {
                            extend(
                                h,
                                &sh.q[i],
                                &mut sh.cold[i],
                                i as u32,
                                grids,
                                extra,
                                &mut sh.regs,
                                &mut sh.region,
                            );
                        }
                    }
                }
                for r in sh.regs.iter_mut() {
                    r.finish();
                }
            })
        });
        let (s_sum, s_n) = shards
            .iter()
            .fold((0, 0), |(a, b), sh| (a + sh.store_sum, b + sh.store_walks));
        // The mean store number over the walks registered in this pass.
        st.store_numbers.push(if s_n > 0 {
            s_sum as f64 / s_n as f64
        } else {
            0.0
        });
        let regs: u64 = shards
            .iter()
            .map(|sh| sh.regs.iter().map(|r| r.len() as u64).sum::<u64>())
            .sum();
        st.registrations += regs;
        st.registered_rays += shards.iter().map(|sh| sh.registered).sum::<u64>();
        let mut region = [NO_REGION; MAX_GRIDS];
        let touched = &mut slots.touched;
        touched.clear(setup.grids);
        for sh in shards.iter() {
            for g in 0..ngrids {
                region[g].union(&sh.region[g]);
                let grid = &mut setup.grids.grids[g];
                for &v in sh.regs[g].voxels() {
                    st.registered_voxels += u64::from(!grid.is_registered(v as usize));
                    grid.set_registered(v as usize, true);
                    touched.mark(g, &grid.spec, v);
                }
            }
        }
        touched.finish();

        // Scan the objects, passing over the blocks no registered ray is
        // near.
        if regs > 0 {
            let grids = &*setup.grids;
            let models = setup.models;
            let per_pass = setup.models_per_pass;
            let (db, pairs_cap) = (setup.db, setup.pairs_cap);
            let carry = setup.carry;
            let touched = &*touched;
            let region = &region;
            // A reader thread may read and decompress blocks ahead of the
            // shards; the shards' threads pick each block's candidates
            // (the reader doing it too held every shard up: on tetra12 it
            // was the busiest thread), then test them.
            let aggregates = setup.aggregates;
            let walk = ScanPass {
                pass: st.passes,
                slack: setup.slack,
                isa: setup.isa,
            };
            let found = &mut slots.found;
            let stats = crate::sdb::scan_blocks::<()>(
                setup.db.scan()?,
                setup.read_ahead,
                &|index| grids.block_boxes(index).is_some_and(|b| !touched.meets(b)),
                &|_, _| {},
                &mut |batch| {
                    if found.len() < batch.len() {
                        found.resize_with(batch.len(), Found::default);
                    }
                    let found = &mut found[..batch.len()];
                    each_on(pool, found, |i, f| {
                        candidates(&batch[i].0, grids, region, aggregates, f)
                    });
                    let scan =
                        |shards: &mut [Shard<R>], blocks: &[(Block<'_>, &())], found: &[Found]| {
                            each_on(pool, shards, |_, sh| {
                                for ((block, ()), found) in blocks.iter().zip(found) {
                                    if !found.is_empty() {
                                        scan_block(
                                            sh, block, found, grids, models, per_pass, carry, &walk,
                                        );
                                    }
                                }
                            });
                        };
                    if found.iter().all(Found::is_empty) {
                        return Ok(());
                    }
                    if !per_pass {
                        // The whole batch in one call: each shard's thread
                        // goes through its blocks without waiting.
                        scan(shards, batch, found);
                        return Ok(());
                    }
                    // Models read per pass: their pairs are tested when
                    // they outgrow their share, checked after every block
                    // (so that when does not depend on the batches).
                    for (one, f) in batch.chunks(1).zip(found.chunks(1)) {
                        scan(shards, one, f);
                        if pair_bytes(shards) > pairs_cap {
                            test_pairs(shards, db, models, pool, carry, &mut st)?;
                        }
                    }
                    Ok(())
                },
            )?;
            st.db_scans += 1;
            st.db_bytes_read += stats.bytes_read;
            st.db_blocks_skipped += stats.blocks_skipped;
            if per_pass {
                test_pairs(shards, setup.db, models, pool, carry, &mut st)?;
            }
        }
        for sh in shards.iter() {
            for g in 0..ngrids {
                for &v in sh.regs[g].voxels() {
                    setup.grids.grids[g].set_registered(v as usize, false);
                }
            }
        }

        // Complete.
        let (carry, grids) = (setup.carry, &*setup.grids);
        {
            let places = dense
                .as_mut()
                .map(|(v, first)| ResultPlaces::new(v, *first));
            let places = places.as_ref();
            pool.install(|| {
                shards
                    .par_iter_mut()
                    .for_each(|sh| complete(sh, grids, places, carry))
            });
        }
        for sh in shards.iter_mut() {
            st.intersection_tests += sh.counts.tests;
            st.tests_skipped_mailbox += sh.counts.skipped_mailbox;
            st.tests_skipped_last_voxel += sh.counts.skipped_last_voxel;
            st.aggregate_walks += sh.counts.aggregate_walks;
            sh.counts = PassCounts::default();
            let done = sh.done.len();
            sh.live -= done;
            finished += done as u64;
            active -= done as u64;
            progress.inc(done as u64);
            if dense.is_none() {
                for &slot in &sh.done {
                    emit(sh.outcome(slot, carry))?;
                }
            }
            sh.done.clear();
        }
    }
    Ok(st)
}

/// Runs `f` on each of `items` (with its index) on the threads of `pool`,
/// or on the caller's thread when the pool has one. A scan hands every
/// block to the pool (every batch of blocks with a reader thread); a
/// pool of one thread takes each from the caller, which waits, and the
/// two threads woke each other for every block: a one-thread render of
/// mount11 under 256 MiB spent 37 % of its samples in the kernel's
/// scheduler and took three times as long as at two threads.
fn each_on<T: Send>(pool: &rayon::ThreadPool, items: &mut [T], f: impl Fn(usize, &mut T) + Sync) {
    if pool.current_num_threads() == 1 {
        items.iter_mut().enumerate().for_each(|(i, t)| f(i, t));
    } else {
        pool.install(|| items.par_iter_mut().enumerate().for_each(|(i, t)| f(i, t)));
    }
}
