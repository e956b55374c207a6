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
//! workers, slots or memory.
//!
//! Slots are split into shards, one per thread; every thread scans the same
//! decoded block for its own rays, so no ray is touched by two threads
//! while it is traced (a finished ray's result is a copy, which another
//! thread may write to its place).

use super::candidates::{Candidate, Found, NO_REGION, Region, candidates};
use super::records::{Outcome, RayRec, ResultRec};
use super::regmap::RegMap;
use super::skip::Touched;
use super::store::StorePlan;
use super::voxels::{OCCUPIED, REGISTERED, VoxelGrid, VoxelGrids, entry_face};
use crate::error::Error;
use crate::grid::nested::{Entry, high_first, ray_meets};
use crate::grid::{Dda, GridSpec};
use crate::hit::{Hit, PrimId};
use crate::intersect::{Attrs, RayQ};
use crate::math::{Real, Vec3, Vec3Ext};
use crate::models::{Models, Placement};
use crate::progress::Progress;
use crate::render::{Cutouts, KindCounts};
use crate::sdb::{Block, Database, ObjectRef};
use crate::shapes::{Prepared, Shape};
use rayon::prelude::*;
use serde::Serialize;

mod register;
mod scan;
use register::register;
pub use register::sample_registrations;
use scan::{AggregateWalk, pair_bytes, scan_block, test_pairs};

/// Grids a ray can walk (the main grid, and dense regions or the huge
/// objects' grid: see [`crate::grid::MAX_GROUPS`]).
pub const MAX_GRIDS: usize = crate::grid::MAX_GROUPS;
const NONE16: u16 = u16::MAX;

const FRESH: u8 = 0;
const WALKING: u8 = 1;
const DONE: u8 = 2;
/// A carried material that asks for the shading join instead (the
/// surface has attributes, which slots do not keep).
const JOIN: u32 = u32::MAX;

/// A ray's walk through one grid, in 8 bytes. Its 3D-DDA state is not
/// kept: a walk that will go on stopped in the voxel it last stored the ray
/// in (it stops when the ray's store number is used up), and the walk from
/// the ray's start to that voxel gives the state bit for bit again
/// ([`Dda::start_at`]). Kept, the state took 40 bytes a grid.
#[derive(Clone, Copy, Debug)]
struct Walk {
    /// The last voxel stored in (`NONE16` in [0] when none yet); while
    /// `WALKING`, the voxel the walk stopped in.
    last: [u16; 3],
    state: u8,
    /// Passes in which this walk registered.
    k: u8,
}

const NEW_WALK: Walk = Walk {
    last: [NONE16; 3],
    state: FRESH,
    k: 0,
};

/// What the scan reads for every registration it visits: small, and kept
/// apart from the rest of the ray so that visits stay in cache.
#[derive(Clone, Copy, Debug)]
struct Hot<R> {
    /// The last primitive tested (the paper's mailbox).
    mailbox: PrimId,
    best: Hit,
    /// Tests must find a hit below this: just above the best distance, so
    /// that an exact tie is seen and goes to the smaller id.
    upper: R,
    t_min: R,
    /// Per grid, the last voxel stored in during the previous pass
    /// (`NONE16` in [0] when none): the last-voxel rule's voxel.
    prev: [[u16; 3]; MAX_GRIDS],
    active: bool,
    shadow: bool,
    blocked: bool,
}

/// The rest of a ray in memory: what registration and completion need.
/// The ray itself is the slot's [`RayQ`], in the tests' precision; in
/// `f64` that is the ray as given, and nothing else is kept of it (`o`,
/// `d` and `t_min` take no room); in `f32` they keep the `f64` values the
/// walks need (see [`ray64`]).
#[derive(Clone, Copy, Debug)]
struct Cold<R: Real> {
    id: u64,
    t_max: f64,
    o: [R::Kept; 3],
    d: [R::Kept; 3],
    t_min: R::Kept,
    /// The surface at the best hit so far, when surfaces are carried.
    ng: Vec3,
    ns: Vec3,
    material: u32,
    /// The input id of the best hit's object, which decides ties.
    rank: u32,
    walks: [Walk; MAX_GRIDS],
}

fn empty_hot<R: Real>() -> Hot<R> {
    Hot {
        mailbox: PrimId::NONE,
        best: Hit::NONE,
        upper: R::INFINITY,
        t_min: R::ZERO,
        prev: [[NONE16; 3]; MAX_GRIDS],
        active: false,
        shadow: false,
        blocked: false,
    }
}

fn empty_cold<R: Real>() -> Cold<R> {
    Cold {
        walks: [NEW_WALK; MAX_GRIDS],
        id: 0,
        t_max: f64::INFINITY,
        o: [R::keep(0.0); 3],
        d: [R::keep(1.0), R::keep(0.0), R::keep(0.0)],
        t_min: R::keep(0.0),
        ng: Vec3::ZERO,
        ns: Vec3::ZERO,
        material: 0,
        rank: 0,
    }
}

/// A slot's ray in `f64`, as its walks take it: exactly the values
/// [`load`] worked out from the ray given.
#[derive(Clone, Copy, Debug)]
struct Ray64 {
    o: Vec3,
    d: Vec3,
    inv: Vec3,
    t_min: f64,
    t_max: f64,
}

/// The origin and direction of a slot's ray in `f64`.
#[inline(always)]
fn od64<R: Real>(q: &RayQ<R>, c: &Cold<R>) -> (Vec3, Vec3) {
    (
        Vec3::new(
            q.o.x.unround(|| c.o[0]),
            q.o.y.unround(|| c.o[1]),
            q.o.z.unround(|| c.o[2]),
        ),
        Vec3::new(
            q.d.x.unround(|| c.d[0]),
            q.d.y.unround(|| c.d[1]),
            q.d.z.unround(|| c.d[2]),
        ),
    )
}

/// A slot's ray in `f64` (see [`Ray64`]). In `f64`, copies of the slot's
/// [`RayQ`] and [`Hot`] values, which [`load`] made from the same
/// values; in `f32`, the kept values, with `1 / d` worked out as `load`
/// did (the same operations give the same bits).
#[inline(always)]
fn ray64<R: Real>(q: &RayQ<R>, h: &Hot<R>, c: &Cold<R>) -> Ray64 {
    let (o, d) = od64(q, c);
    Ray64 {
        o,
        d,
        inv: Vec3::new(
            q.inv.x.unround(|| R::keep(1.0 / d.x)),
            q.inv.y.unround(|| R::keep(1.0 / d.y)),
            q.inv.z.unround(|| R::keep(1.0 / d.z)),
        ),
        t_min: h.t_min.unround(|| c.t_min),
        t_max: c.t_max,
    }
}

/// Bytes one ray slot takes (with its place in the queue of rays loaded
/// in parallel, see [`Shard::pending`], and in the pass's finished rays
/// and their order, see [`put_results`]).
pub fn slot_bytes<R: Real>() -> usize {
    std::mem::size_of::<Hot<R>>()
        + std::mem::size_of::<Cold<R>>()
        + std::mem::size_of::<RayQ<R>>()
        // Its place in the queue, or the id it was admitted by.
        + std::mem::size_of::<Pending>().max(std::mem::size_of::<u64>())
        // Its place among the pass's finished rays, and in their order.
        + 2 * std::mem::size_of::<u32>()
}

/// Bytes of a slot's place in the queue of streamed rays (see
/// [`Shard::pending`]) beyond what a ray admitted by id takes instead (its
/// id): what a slot saves when its rays can be had by id and its results
/// have their places.
pub fn streamed_extra_bytes() -> usize {
    std::mem::size_of::<Pending>().saturating_sub(std::mem::size_of::<u64>())
}

/// Memory per registration: its key, its slot id, and its share of the
/// voxel table.
pub const REGISTRATION_BYTES: usize = 8 + 4 + 24;

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
struct Shard<R: Real> {
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
    /// Indices of the finished hits in `done`, by part of the result
    /// buffer, and where each part's begin (see [`put_results`]).
    order: Vec<u32>,
    bounds: Vec<usize>,
    /// Slots holding a ray.
    live: usize,
    /// Store numbers of the walks registered this pass, and their number.
    store_sum: u64,
    store_walks: u64,
    /// Rays registered this pass.
    registered: u64,
    /// When models are read per pass: the instances met this pass, and
    /// the rays (slots) registered near each, tested once the model is
    /// read after the world's objects.
    placed: Vec<(u32, u32, Placement)>,
    pairs: Vec<Pair>,
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
    /// Registrations per pass, at most.
    pub registrations: usize,
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
    /// a block ahead of the shards.
    pub read_ahead: bool,
}

/// The ray slots, kept from round to round so that their memory is
/// allocated once.
pub struct Slots<R: Real> {
    shards: Vec<Shard<R>>,
    /// The candidates of a batch of blocks, one per block.
    found: Vec<Found>,
    /// The coarse cells this pass has rays in (which blocks it skips).
    touched: Touched,
}

impl<R: Real> Slots<R> {
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
                    order: Vec::new(),
                    bounds: Vec::new(),
                    live: 0,
                    store_sum: 0,
                    store_walks: 0,
                    registered: 0,
                    placed: Vec::new(),
                    pairs: Vec::new(),
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
                    + sh.order.capacity() * size_of::<u32>()
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
            sh.order = Vec::new();
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

/// Whether the ray meets no grid's box within its extent: nothing can
/// be found along it.
fn misses_every_grid(r: &RayRec, grids: &VoxelGrids, eps: f64) -> bool {
    let o = Vec3::from_array(r.o);
    let d = Vec3::from_array(r.d);
    let inv = Vec3::new(1.0 / d.x, 1.0 / d.y, 1.0 / d.z);
    let t_min = if r.kind == super::records::RayKind::Eye as u8 {
        0.0
    } else {
        eps
    };
    grids
        .grids
        .iter()
        .all(|g| g.spec.clip(o, d, inv, t_min, r.t_max).is_none())
}

/// Puts what [`load`] needs of ray `r` into slot `i`: the serial part
/// of giving a ray a slot (see [`Shard::pending`]).
fn stage<R: Real>(sh: &mut Shard<R>, i: usize, id: u64, r: &RayRec, eps: f64) {
    let t_min = if r.kind == super::records::RayKind::Eye as u8 {
        0.0
    } else {
        eps
    };
    let (o, d) = (Vec3::from_array(r.o), Vec3::from_array(r.d));
    let shadow = r.is_shadow();
    sh.hot[i] = Hot {
        mailbox: PrimId::NONE,
        best: Hit::NONE,
        upper: if shadow {
            R::from_f64(r.t_max)
        } else {
            R::INFINITY
        },
        t_min: R::from_f64(t_min),
        prev: [[NONE16; 3]; MAX_GRIDS],
        active: true,
        shadow,
        blocked: false,
    };
    let q = &mut sh.q[i];
    q.o = o.cast();
    q.d = d.cast();
    sh.cold[i] = Cold {
        id,
        t_max: r.t_max,
        o: o.to_array().map(R::keep),
        d: d.to_array().map(R::keep),
        t_min: R::keep(t_min),
        ..empty_cold()
    };
}

/// Makes a ray [`stage`] put into slot `i` ready for its walks and tests.
fn load<R: Real>(sh: &mut Shard<R>, i: usize) {
    sh.live += 1;
    let (o, d) = od64(&sh.q[i], &sh.cold[i]);
    let inv = Vec3::new(1.0 / d.x, 1.0 / d.y, 1.0 / d.z);
    sh.q[i] = RayQ::with_inverse(o.cast(), d.cast(), inv.cast());
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

/// Admission of rays that can be had by id (see [`intersect_rays`]): the
/// same rays, in the same order, as filling the slots one by one from a
/// stream, but with the rays made, looked at and loaded by all threads.
struct ByIdFill<'a> {
    ray: &'a (dyn Fn(u64) -> RayRec + Sync),
    total: u64,
    /// The first id not yet admitted or passed over.
    next: u64,
    /// Whether each ray of the window looked at meets no grid (reused).
    sky: Vec<bool>,
    /// The ids admitted this pass, in order: shard `k` loads
    /// `ids[start[k]..start[k + 1]]` into its empty slots, in slot order.
    ids: Vec<u64>,
    start: Vec<usize>,
}

impl ByIdFill<'_> {
    /// Admits up to `free[k]` rays for shard `k`, in order: the next rays
    /// that meet some grid, as the serial fill would have given them to
    /// the empty slots of shard 0, then shard 1, ... Returns the number
    /// of rays passed over because they meet no grid (misses at once).
    fn admit(
        &mut self,
        free: &[usize],
        pool: &rayon::ThreadPool,
        grids: &VoxelGrids,
        eps: f64,
    ) -> u64 {
        let want: usize = free.iter().sum();
        self.ids.clear();
        let mut sky = 0;
        while self.ids.len() < want && self.next < self.total {
            // A window a little larger than what is missing: few rays are
            // looked at twice, and a sky-heavy window is followed by
            // another.
            let need = want - self.ids.len();
            let w = ((need + need / 4 + 64) as u64).min(self.total - self.next) as usize;
            self.sky.resize(w, false);
            let (ray, base) = (self.ray, self.next);
            pool.install(|| {
                self.sky[..w]
                    .par_iter_mut()
                    .enumerate()
                    .with_min_len(1024)
                    .for_each(|(i, s)| *s = misses_every_grid(&ray(base + i as u64), grids, eps))
            });
            let mut used = w;
            for (i, &s) in self.sky[..w].iter().enumerate() {
                if self.ids.len() == want {
                    used = i;
                    break;
                }
                if s {
                    sky += 1;
                } else {
                    self.ids.push(base + i as u64);
                }
            }
            self.next += used as u64;
        }
        self.start.clear();
        let mut at = 0;
        for &f in free {
            self.start.push(at);
            at = (at + f).min(self.ids.len());
        }
        self.start.push(at);
        sky
    }
}

/// Writes the finished rays' results into their places in `v` (ids count
/// from 0; `first` is added), every thread a contiguous part of `v`: each
/// shard first orders the indices of its finished hits by part (a
/// counting sort, 4 bytes a hit), so that no part looks at another's (a
/// sort of the results by id cost more than the writes). Misses are in
/// `v` already.
fn put_results<R: Real>(
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
fn put<R: Real>(dst: &mut [Outcome], lo: u64, sh: &Shard<R>, slot: u32, carry: bool, first: u64) {
    if !sh.hot[slot as usize].best.prim.is_none() {
        let o = sh.outcome(slot, carry);
        let at = (o.res.ray - lo) as usize;
        dst[at] = o;
        dst[at].res.ray += first;
    }
}

/// Intersects the `total` rays of `source` (ids `0, 1, ...`), giving each
/// ray's result to `sink`: to its callback in completion order, or into
/// its place in a dense buffer.
#[allow(clippy::too_many_arguments)]
pub fn intersect_rays<R: Real>(
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
    // (`ByIdFill`), each shard loads its own, and results are written to
    // their places by every thread (`put_results`). Else this thread
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
                start: Vec::new(),
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
        // From a stream: fill empty slots, in slot order. A ray that meets
        // no grid's box (the sky around a model) is a miss at once and
        // takes no slot. (Rays by id: the same, through `ByIdFill`.)
        if !exhausted {
            'fill: for sh in shards.iter_mut() {
                for i in 0..sh.hot.len() {
                    if sh.hot[i].active {
                        continue;
                    }
                    loop {
                        match rays.next() {
                            Some(r) => {
                                let r = r?;
                                let id = next_id;
                                next_id += 1;
                                if misses_every_grid(&r, setup.grids, setup.eps) {
                                    finished += 1;
                                    // Counted in batches: a progress update
                                    // costs more than such a ray.
                                    sky += 1;
                                    if sky == 1 << 16 {
                                        progress.inc(std::mem::take(&mut sky));
                                    }
                                    emit(Outcome::bare(ResultRec {
                                        ray: id,
                                        prim: PrimId::NONE,
                                        t: f64::INFINITY,
                                    }))?;
                                    continue;
                                }
                                // Loaded by the shard's thread before it
                                // registers (below); taken from now on.
                                stage(sh, i, id, &r, setup.eps);
                                sh.pending.push(i as u32);
                                active += 1;
                                break;
                            }
                            None => {
                                exhausted = true;
                                break 'fill;
                            }
                        }
                    }
                }
            }
        }
        if let Some(fill) = by_id.as_mut() {
            let free: Vec<usize> = shards.iter().map(|sh| sh.hot.len() - sh.live).collect();
            let passed = fill.admit(&free, pool, setup.grids, setup.eps);
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
        let share = (setup.registrations / shards.len()).max(1) as u64;
        let eps = setup.eps;
        let admitted = by_id.as_ref().map(|f| (f.ray, &f.ids[..], &f.start[..]));
        pool.install(|| {
            shards.par_iter_mut().enumerate().for_each(|(k, sh)| {
                let pending = std::mem::take(&mut sh.pending);
                for &i in &pending {
                    load(sh, i as usize);
                }
                sh.pending = pending;
                sh.pending.clear();
                if let Some((ray, ids, start)) = admitted {
                    let mut mine = ids[start[k]..start[k + 1]].iter();
                    for i in 0..sh.hot.len() {
                        if sh.hot[i].active {
                            continue;
                        }
                        let Some(&id) = mine.next() else { break };
                        stage(sh, i, id, &ray(id), eps);
                        load(sh, i);
                    }
                }
                let expect = (share as usize).clamp(1024, 1 << 20);
                for g in 0..ngrids {
                    let cells = grids.grids[g].spec.cells();
                    sh.regs[g].clear(expect, if cells <= dense_cells { cells } else { 0 });
                    sh.region[g] = NO_REGION;
                }
                sh.store_sum = 0;
                sh.store_walks = 0;
                sh.registered = 0;
                let mut used = 0u64;
                for i in 0..sh.hot.len() {
                    let h = &sh.hot[i];
                    if !h.active || h.blocked || used >= share {
                        continue;
                    }
                    let before: usize = sh.regs.iter().map(RegMap::len).sum();
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
                    used += (sh.regs.iter().map(RegMap::len).sum::<usize>() - before) as u64;
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
                    grid.flags[v as usize] |= REGISTERED;
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
            let walk = AggregateWalk {
                pass: st.passes,
                slack: setup.slack,
            };
            let found = &mut slots.found;
            let stats =
                crate::sdb::scan_blocks::<()>(
                    setup.db.scan()?,
                    setup.read_ahead,
                    &|index| grids.block_boxes(index).is_some_and(|b| !touched.meets(b)),
                    &|_, _| {},
                    &mut |batch| {
                        if found.len() < batch.len() {
                            found.resize_with(batch.len(), Found::default);
                        }
                        let found = &mut found[..batch.len()];
                        pool.install(|| {
                            found.par_iter_mut().zip(batch.par_iter()).for_each(
                                |(f, (block, ()))| candidates(block, grids, region, aggregates, f),
                            )
                        });
                        let scan = |shards: &mut [Shard<R>],
                                    blocks: &[(Block<'_>, &())],
                                    found: &[Found]| {
                            pool.install(|| {
                                shards.par_iter_mut().for_each(|sh| {
                                    for ((block, ()), found) in blocks.iter().zip(found) {
                                        if !found.is_empty() {
                                            scan_block(
                                                sh, block, found, grids, models, per_pass, carry,
                                                &walk,
                                            );
                                        }
                                    }
                                });
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
                    setup.grids.grids[g].flags[v as usize] &= !REGISTERED;
                }
            }
        }

        // Complete.
        let (carry, grids) = (setup.carry, &*setup.grids);
        pool.install(|| shards.par_iter_mut().for_each(|sh| complete(sh, grids)));
        if let Some((v, first)) = dense.as_mut() {
            put_results(shards, v, *first, carry, pool);
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

/// Finishes the rays whose result is complete, freeing their slots.
fn complete<R: Real>(sh: &mut Shard<R>, grids: &VoxelGrids) {
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

impl<R: Real> Shard<R> {
    /// The result of the ray that finished in `slot` (which keeps it until
    /// the slot is filled again), with its surface when `carry`.
    #[inline]
    fn outcome(&self, slot: u32, carry: bool) -> Outcome {
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The parts of a slot, printed (`--nocapture`) to see what a slot
    /// spends its bytes on; and the slot of the `f64` tracer kept small.
    #[test]
    fn slot_parts() {
        use std::mem::size_of;
        for (name, hot, q, cold, total) in [
            (
                "f64",
                size_of::<Hot<f64>>(),
                size_of::<RayQ<f64>>(),
                size_of::<Cold<f64>>(),
                slot_bytes::<f64>(),
            ),
            (
                "f32",
                size_of::<Hot<f32>>(),
                size_of::<RayQ<f32>>(),
                size_of::<Cold<f32>>(),
                slot_bytes::<f32>(),
            ),
        ] {
            println!(
                "{name}: Hot {hot}, RayQ {q}, Cold {cold} (Walk {} x {MAX_GRIDS}), Pending {}: slot {total}",
                size_of::<Walk>(),
                size_of::<Pending>(),
            );
        }
        assert!(slot_bytes::<f64>() <= 300, "{}", slot_bytes::<f64>());
    }
}
