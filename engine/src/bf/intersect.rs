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
//! decoded block for its own rays, so no ray is touched by two threads.

use super::records::{NO_HIT, RayRec, ResultRec};
use super::regmap::RegMap;
use super::voxels::{OCCUPIED, REGISTERED, VoxelGrids, entry_face};
use crate::error::Error;
use crate::grid::{Dda, DdaSave, GridSpec};
use crate::intersect::{Prepared, RayQ, intersect_prepared, prepare};
use crate::math::{Real, Vec3};
use crate::progress::Progress;
use crate::render::KindCounts;
use crate::sdb::{Block, Database};
use rayon::prelude::*;
use serde::Serialize;

/// Grids a ray can walk (the main grid and the huge objects' grid).
pub const MAX_GRIDS: usize = 2;
const NONE16: u16 = u16::MAX;

/// How many voxels a ray stores itself in per pass.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum StoreNumber {
    Fixed(u32),
    Adaptive,
}

/// Store numbers per grid.
#[derive(Clone, Copy, Debug)]
pub struct StorePlan {
    fixed: Option<u32>,
    base: [u32; MAX_GRIDS],
    max: [u32; MAX_GRIDS],
}

impl StorePlan {
    pub fn new(policy: StoreNumber, grids: &VoxelGrids) -> StorePlan {
        let mut base = [1; MAX_GRIDS];
        let mut max = [1; MAX_GRIDS];
        for (g, grid) in grids.grids.iter().enumerate() {
            let res = *grid.spec.res.iter().max().unwrap_or(&1);
            base[g] = ((res as f64 / 10.0).round() as u32).max(1);
            max[g] = res.max(base[g]);
        }
        StorePlan {
            fixed: match policy {
                StoreNumber::Fixed(n) => Some(n.max(1)),
                StoreNumber::Adaptive => None,
            },
            base,
            max,
        }
    }

    /// Store number in grid `g` for a ray's pass number `k` there.
    #[inline]
    pub fn store(&self, g: usize, k: u8) -> u32 {
        match self.fixed {
            Some(n) => n,
            None => self.max[g].min(self.base[g].saturating_mul(1 << k.min(20))),
        }
    }

    /// The most registrations one ray can ask for in a pass.
    pub fn worst(&self, grids: usize) -> u32 {
        (0..grids).map(|g| self.store(g, 30)).sum()
    }
}

const FRESH: u8 = 0;
const WALKING: u8 = 1;
const DONE: u8 = 2;

/// A ray's walk through one grid.
#[derive(Clone, Copy, Debug)]
struct Walk {
    save: DdaSave,
    state: u8,
    /// Passes in which this walk registered.
    k: u8,
    /// The last voxel stored in, and the one of the pass before (for the
    /// last-voxel rule); `NONE16` in [0] when there is none.
    last: [u16; 3],
    prev: [u16; 3],
}

const NEW_WALK: Walk = Walk {
    save: DdaSave {
        t_next: [0.0; 3],
        t_end: 0.0,
        cell: [0; 3],
    },
    state: FRESH,
    k: 0,
    last: [NONE16; 3],
    prev: [NONE16; 3],
};

/// A ray in memory.
struct Slot<R> {
    active: bool,
    shadow: bool,
    blocked: bool,
    /// The last object tested (the paper's mailbox).
    mailbox: u32,
    best_id: u32,
    best_t: f64,
    /// Tests must find a hit below this: just above the best distance, so
    /// that an exact tie is seen and goes to the smaller id.
    upper: R,
    q: RayQ<R>,
    walks: [Walk; MAX_GRIDS],
    id: u64,
    o: Vec3,
    d: Vec3,
    inv: Vec3,
    t_min: f64,
    t_max: f64,
}

impl<R: Real> Slot<R> {
    fn empty() -> Slot<R> {
        Slot {
            active: false,
            shadow: false,
            blocked: false,
            mailbox: NO_HIT,
            best_id: NO_HIT,
            best_t: f64::INFINITY,
            upper: R::INFINITY,
            q: RayQ::new(
                crate::math::V3::zero(),
                crate::math::V3::new(R::ONE, R::ZERO, R::ZERO),
            ),
            walks: [NEW_WALK; MAX_GRIDS],
            id: 0,
            o: Vec3::zero(),
            d: Vec3::new(1.0, 0.0, 0.0),
            inv: Vec3::new(1.0, f64::INFINITY, f64::INFINITY),
            t_min: 0.0,
            t_max: f64::INFINITY,
        }
    }

    fn load(&mut self, id: u64, r: &RayRec, eps: f64) {
        let o = Vec3::from_f64(r.o);
        let d = Vec3::from_f64(r.d);
        let inv = Vec3::new(1.0 / d.x, 1.0 / d.y, 1.0 / d.z);
        *self = Slot {
            active: true,
            shadow: r.is_shadow(),
            blocked: false,
            mailbox: NO_HIT,
            best_id: NO_HIT,
            best_t: f64::INFINITY,
            upper: if r.is_shadow() {
                R::from_f64(r.t_max)
            } else {
                R::INFINITY
            },
            q: RayQ::with_inverse(o.cast(), d.cast(), inv.cast()),
            walks: [NEW_WALK; MAX_GRIDS],
            id,
            o,
            d,
            inv,
            t_min: if r.kind == super::records::RayKind::Eye as u8 {
                0.0
            } else {
                eps
            },
            t_max: r.t_max,
        };
    }
}

/// Bytes one ray slot takes.
pub fn slot_bytes<R: Real>() -> usize {
    std::mem::size_of::<Slot<R>>()
}

/// Memory per registration: its key while sorting, its slot id, and its
/// share of the voxel table.
pub const REGISTRATION_BYTES: usize = 8 + 4 + 24;

/// Counters of one pass.
#[derive(Clone, Copy, Debug, Default)]
struct PassCounts {
    tests: KindCounts,
    skipped_mailbox: u64,
    skipped_last_voxel: u64,
}

impl std::ops::AddAssign for PassCounts {
    fn add_assign(&mut self, o: Self) {
        self.tests += o.tests;
        self.skipped_mailbox += o.skipped_mailbox;
        self.skipped_last_voxel += o.skipped_last_voxel;
    }
}

/// One thread's rays and their registrations.
struct Shard<R> {
    slots: Vec<Slot<R>>,
    keys: [Vec<u64>; MAX_GRIDS],
    regs: [RegMap; MAX_GRIDS],
    counts: PassCounts,
    done: Vec<ResultRec>,
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
    pub intersection_tests: KindCounts,
    pub tests_skipped_mailbox: u64,
    pub tests_skipped_last_voxel: u64,
    pub db_scans: u64,
    pub db_bytes_read: u64,
}

/// What the intersection stage is given.
pub struct IntersectSetup<'a> {
    pub db: &'a Database,
    pub grids: &'a mut VoxelGrids,
    pub store: StorePlan,
    /// Ray slots in memory.
    pub slots: usize,
    /// Registrations per pass, at most.
    pub registrations: usize,
    pub threads: usize,
    pub eps: f64,
}

/// Intersects every ray `rays` yields (with ids `0, 1, ...` in order),
/// passing each ray's result to `emit` in completion order.
pub fn intersect_rays<R: Real>(
    setup: &mut IntersectSetup<'_>,
    pool: &rayon::ThreadPool,
    rays: &mut dyn Iterator<Item = Result<RayRec, Error>>,
    total: u64,
    emit: &mut dyn FnMut(ResultRec) -> Result<(), Error>,
    progress: &dyn Progress,
) -> Result<IntersectStats, Error> {
    let threads = setup.threads.max(1);
    // No more slots than rays.
    let slots = (setup.slots as u64).min(total).max(1) as usize;
    let per = slots.div_ceil(threads).max(1);
    let mut shards: Vec<Shard<R>> = (0..threads)
        .map(|_| Shard {
            slots: (0..per).map(|_| Slot::empty()).collect(),
            keys: Default::default(),
            regs: Default::default(),
            counts: PassCounts::default(),
            done: Vec::new(),
        })
        .collect();
    let ngrids = setup.grids.grids.len();
    let mut st = IntersectStats {
        rays: total,
        ..Default::default()
    };
    let mut next_id: u64 = 0;
    let mut exhausted = false;
    let mut finished: u64 = 0;
    loop {
        // Fill empty slots, in slot order.
        if !exhausted {
            'fill: for sh in shards.iter_mut() {
                for s in sh.slots.iter_mut() {
                    if s.active {
                        continue;
                    }
                    match rays.next() {
                        Some(r) => {
                            s.load(next_id, &r?, setup.eps);
                            next_id += 1;
                        }
                        None => {
                            exhausted = true;
                            break 'fill;
                        }
                    }
                }
            }
        }
        let active: u64 = shards
            .iter()
            .map(|sh| sh.slots.iter().filter(|s| s.active).count() as u64)
            .sum();
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

        // Admit rays in slot order while their registrations fit.
        let cap = setup.registrations.max(setup.store.worst(ngrids) as usize) as u64;
        let mut budget = cap;
        let mut admitted: Vec<Vec<bool>> = Vec::with_capacity(shards.len());
        let (mut s_sum, mut s_n) = (0u64, 0u64);
        for sh in &shards {
            let mut a = Vec::with_capacity(sh.slots.len());
            for s in &sh.slots {
                let need: u64 = if s.active && !s.blocked {
                    (0..ngrids)
                        .filter(|&g| s.walks[g].state != DONE)
                        .map(|g| setup.store.store(g, s.walks[g].k) as u64)
                        .sum()
                } else {
                    0
                };
                let ok = need > 0 && need <= budget;
                if ok {
                    budget -= need;
                    s_sum += need;
                    s_n += 1;
                }
                a.push(ok);
            }
            admitted.push(a);
        }
        st.store_numbers.push(if s_n > 0 {
            s_sum as f64 / s_n as f64 / ngrids as f64
        } else {
            0.0
        });

        // Register, per shard.
        let grids = &*setup.grids;
        let store = setup.store;
        pool.install(|| {
            shards
                .par_iter_mut()
                .zip(admitted.par_iter())
                .for_each(|(sh, adm)| {
                    for k in sh.keys.iter_mut() {
                        k.clear();
                    }
                    for (i, s) in sh.slots.iter_mut().enumerate() {
                        if adm[i] {
                            register(s, i as u32, grids, &store, &mut sh.keys);
                        }
                    }
                    for g in 0..ngrids {
                        let keys = &mut sh.keys[g];
                        sh.regs[g].build(keys);
                    }
                })
        });
        let regs: u64 = shards
            .iter()
            .map(|sh| sh.regs.iter().map(|r| r.len() as u64).sum::<u64>())
            .sum();
        st.registrations += regs;
        for sh in &shards {
            for (g, r) in sh.regs.iter().enumerate().take(ngrids) {
                for v in r.voxels() {
                    setup.grids.grids[g].flags[v as usize] |= REGISTERED;
                }
            }
        }

        // Scan the objects.
        if regs > 0 {
            let mut scan = setup.db.scan()?;
            let grids = &*setup.grids;
            while let Some(block) = scan.next_block()? {
                pool.install(|| {
                    shards
                        .par_iter_mut()
                        .for_each(|sh| scan_block(sh, &block, grids));
                });
            }
            st.db_scans += 1;
            st.db_bytes_read += scan.stats().bytes_read;
        }
        for sh in &shards {
            for (g, r) in sh.regs.iter().enumerate().take(ngrids) {
                for v in r.voxels() {
                    setup.grids.grids[g].flags[v as usize] &= !REGISTERED;
                }
            }
        }

        // Complete.
        pool.install(|| shards.par_iter_mut().for_each(|sh| complete(sh, ngrids)));
        for sh in shards.iter_mut() {
            st.intersection_tests += sh.counts.tests;
            st.tests_skipped_mailbox += sh.counts.skipped_mailbox;
            st.tests_skipped_last_voxel += sh.counts.skipped_last_voxel;
            sh.counts = PassCounts::default();
            finished += sh.done.len() as u64;
            progress.inc(sh.done.len() as u64);
            for r in sh.done.drain(..) {
                emit(r)?;
            }
        }
    }
    Ok(st)
}

/// Walks a ray through each grid, storing it in up to its store number of
/// voxels: where it enters some object's voxel boundary, or the first
/// voxel of its walk if that is occupied.
fn register<R: Real>(
    s: &mut Slot<R>,
    slot: u32,
    grids: &VoxelGrids,
    store: &StorePlan,
    keys: &mut [Vec<u64>; MAX_GRIDS],
) {
    for (g, grid) in grids.grids.iter().enumerate() {
        let w = &mut s.walks[g];
        if w.state == DONE {
            continue;
        }
        let spec: &GridSpec = &grid.spec;
        let (mut dda, mut entry) = if w.state == FRESH {
            match Dda::start(spec, s.o, s.d, s.inv, s.t_min, s.t_max) {
                Some(d) => (d, None),
                None => {
                    w.state = DONE;
                    continue;
                }
            }
        } else {
            let mut d = Dda::resume(spec, s.d, s.inv, &w.save);
            match d.advance_axis() {
                Some(a) => (d, Some(a)),
                None => {
                    w.state = DONE;
                    continue;
                }
            }
        };
        let limit = store.store(g, w.k);
        let mut n = 0;
        w.prev = w.last;
        loop {
            if s.best_t < dda.t_enter {
                w.state = DONE; // the best hit lies before this voxel
                break;
            }
            let f = grid.flags[dda.index];
            let stored = f & OCCUPIED != 0
                && match entry {
                    None => true,
                    Some(a) => f & entry_face(a, dda.steps_up(a)) != 0,
                };
            if stored {
                keys[g].push(((dda.index as u64) << 32) | slot as u64);
                let c = dda.voxel();
                w.last = [c[0] as u16, c[1] as u16, c[2] as u16];
                n += 1;
                if n == limit {
                    break;
                }
            }
            match dda.advance_axis() {
                Some(a) => entry = Some(a),
                None => {
                    w.state = DONE;
                    break;
                }
            }
        }
        if w.state != DONE {
            w.state = WALKING;
            w.save = dda.save();
        }
        if n > 0 {
            w.k = w.k.saturating_add(1);
        }
    }
}

/// Tests one block's objects against the shard's registered rays.
fn scan_block<R: Real>(sh: &mut Shard<R>, block: &Block<'_>, grids: &VoxelGrids) {
    for o in block.objects() {
        let g = grids.partition.group(&o.bbox);
        if sh.regs[g].is_empty() {
            continue;
        }
        let grid = &grids.grids[g];
        let Some((lo, hi)) = grid.spec.cell_range(&o.bbox) else {
            continue;
        };
        let mut prep: Option<Prepared> = None;
        for z in lo[2]..=hi[2] {
            for y in lo[1]..=hi[1] {
                let row = grid.spec.index([0, y, z]);
                for x in lo[0]..=hi[0] {
                    let v = row + x as usize;
                    if grid.flags[v] & REGISTERED == 0 {
                        continue;
                    }
                    for &slot in sh.regs[g].get(v as u32) {
                        let s = &mut sh.slots[slot as usize];
                        if s.blocked {
                            continue;
                        }
                        if s.mailbox == o.id {
                            sh.counts.skipped_mailbox += 1;
                            continue;
                        }
                        s.mailbox = o.id;
                        let p = s.walks[g].prev;
                        if p[0] != NONE16
                            && (lo[0]..=hi[0]).contains(&(p[0] as u32))
                            && (lo[1]..=hi[1]).contains(&(p[1] as u32))
                            && (lo[2]..=hi[2]).contains(&(p[2] as u32))
                        {
                            // Tested in the previous pass, when the ray was
                            // stored in its last voxel, which this object's
                            // voxel box contains (Fig. 5b).
                            sh.counts.skipped_last_voxel += 1;
                            continue;
                        }
                        let pr = prep.get_or_insert_with(|| prepare(&o.shape));
                        sh.counts.tests.add(o.shape.kind());
                        let rmin = R::from_f64(s.t_min);
                        if let Some(t) =
                            intersect_prepared(&o.shape, pr, &o.bbox, &s.q, rmin, s.upper)
                        {
                            let t = t.to_f64();
                            if s.shadow {
                                s.blocked = true;
                                s.best_t = t;
                                s.best_id = o.id;
                            } else if t < s.best_t || (t == s.best_t && o.id < s.best_id) {
                                s.best_t = t;
                                s.best_id = o.id;
                                s.upper = R::from_f64(t).next_up();
                            }
                        }
                    }
                }
            }
        }
    }
}

/// Finishes the rays whose result is complete, freeing their slots.
fn complete<R: Real>(sh: &mut Shard<R>, ngrids: usize) {
    for s in sh.slots.iter_mut() {
        if !s.active {
            continue;
        }
        let done = s.blocked
            || (0..ngrids).all(|g| {
                let w = &mut s.walks[g];
                if w.state == WALKING && s.best_t < w.save.t_exit() {
                    w.state = DONE;
                }
                w.state == DONE
            });
        if done {
            sh.done.push(ResultRec {
                ray: s.id,
                object: s.best_id,
                _pad: 0,
                t: s.best_t,
            });
            s.active = false;
        }
    }
}
