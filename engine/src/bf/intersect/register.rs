//! Registration (step 2 of a pass): each ray walks its grids and stores
//! itself in up to its store number of voxels; and the sample of a
//! round's rays that plans its slots by the registrations they make.

use super::slot::{Ray64, Walk};
use super::*;

/// Rays [`sample_registrations`] walks at most.
const SAMPLE_RAYS: u64 = 1024;

/// The registrations rays `ray(0..len)` make in their first pass, on
/// average, from up to [`SAMPLE_RAYS`] of them spread evenly over the
/// round (rays that meet no grid take no slot and are not counted), and
/// the voxels they are in per registration (an upper bound for the
/// round's: its rays are denser than the sample and share more voxels);
/// `None` when no sampled ray meets a grid. What a round's slots are planned for
/// (see [`crate::bf::Budget::slots`]): the rays of one scene differ by tens
/// of times (mount11's eye rays make 1.3 a pass, rings80's 25), and a
/// round's shadow rays are unlike its eye rays. Walking a thousand rays
/// costs a few hundredths of a pass.
pub fn sample_registrations<R: Elem>(
    len: u64,
    ray: &(dyn Fn(u64) -> RayRec + Sync),
    grids: &VoxelGrids,
    store: &StorePlan,
    eps: f64,
) -> Option<(f64, f64)> {
    let mut slots = Slots::<R>::new(1);
    slots.ensure(1, false);
    let sh = &mut slots.shards[0];
    let mut regs: [RegMap; MAX_GRIDS] = Default::default();
    let mut region = [NO_REGION; MAX_GRIDS];
    for m in regs.iter_mut() {
        m.clear(64, 0);
    }
    let step = (len / SAMPLE_RAYS).max(1);
    let mut rays = 0u64;
    let mut i = step / 2;
    while i < len {
        let r = ray(i);
        i += step;
        if misses_every_grid(&r, grids, eps) {
            continue;
        }
        stage(sh, 0, 0, &r, eps);
        load(sh, 0);
        register(
            &mut sh.hot[0],
            &sh.q[0],
            &mut sh.cold[0],
            0,
            grids,
            store,
            &mut regs,
            &mut region,
        );
        rays += 1;
    }
    let total = regs.iter().map(RegMap::len).sum::<usize>();
    let voxels = regs.iter().map(|m| m.voxels().len()).sum::<usize>();
    (rays > 0).then(|| {
        (
            total as f64 / rays as f64,
            voxels as f64 / total.max(1) as f64,
        )
    })
}

/// A ray given a slot, to be loaded into it by the shard's own thread.
/// Walks a ray through each grid, storing it in up to its store number of
/// voxels: where it enters some object's voxel boundary, or the first
/// voxel of its walk if that is occupied. Returns the sum of the store
/// numbers of the walks it continued, and their number (for statistics).
#[allow(clippy::too_many_arguments)]
pub(super) fn register<R: Elem>(
    h: &mut Hot<R>,
    q: &RayQ<R>,
    c: &mut Cold<R>,
    slot: u32,
    grids: &VoxelGrids,
    store: &StorePlan,
    regs: &mut [RegMap; MAX_GRIDS],
    region: &mut [Region; MAX_GRIDS],
) -> (u64, u64) {
    let (mut store_sum, mut walks) = (0u64, 0u64);
    let r = ray64(q, h, c);
    for (g, grid) in grids.grids.iter().enumerate() {
        let w = &mut c.walks[g];
        if w.state == DONE {
            continue;
        }
        store_sum += store.store(g, w.k) as u64;
        walks += 1;
        h.prev[g] = w.last;
        let spec: &GridSpec = &grid.spec;
        if spec.cells() == 1 {
            // A one-voxel grid (a few large objects): the ray is stored in
            // it once, if it meets the grid's box at all.
            if grid.flags[0] & OCCUPIED != 0
                && spec.clip(r.o, r.d, r.inv, r.t_min, r.t_max).is_some()
            {
                regs[g].insert(0, slot);
                region[g].add([0, 0, 0]);
                w.last = [0, 0, 0];
                w.k = w.k.saturating_add(1);
            }
            w.state = DONE;
            continue;
        }
        let (mut dda, entry) = if w.state == FRESH {
            match Dda::start(spec, r.o, r.d, r.inv, r.t_min, r.t_max) {
                Some(d) => (d, None),
                None => {
                    w.state = DONE;
                    continue;
                }
            }
        } else {
            match resume(spec, &r, w) {
                Some(x) => x,
                None => continue,
            }
        };
        let limit = store.store(g, w.k);
        let mut to = Storing {
            regs: &mut regs[g],
            region: &mut region[g],
            slot,
        };
        let n = walk_storing(&mut dda, entry, grid, h.best.t, limit, &mut to, w);
        if w.state != DONE {
            // Stopped in the voxel just stored in, `w.last`: where the
            // next pass starts its walk again.
            debug_assert_eq!(w.last.map(u32::from), dda.voxel());
            w.state = WALKING;
        }
        if n > 0 {
            w.k = w.k.saturating_add(1);
        }
    }
    (store_sum, walks)
}

/// The walks of a ray [`register`] stopped at their store number this
/// pass (`WALKING`) go on, each storing the ray in up to `extra` more
/// voxels ([`StoreNumber::Budget`](crate::bf::StoreNumber::Budget)): as if
/// the store number had been larger. The last-voxel rule's voxel of the
/// previous pass, and the walks' pass counts, stay as `register` left
/// them.
#[allow(clippy::too_many_arguments)]
pub(super) fn extend<R: Elem>(
    h: &Hot<R>,
    q: &RayQ<R>,
    c: &mut Cold<R>,
    slot: u32,
    grids: &VoxelGrids,
    extra: u32,
    regs: &mut [RegMap; MAX_GRIDS],
    region: &mut [Region; MAX_GRIDS],
) {
    let r = ray64(q, h, c);
    for (g, grid) in grids.grids.iter().enumerate() {
        let w = &mut c.walks[g];
        if w.state != WALKING {
            continue;
        }
        let Some((mut dda, entry)) = resume(&grid.spec, &r, w) else {
            continue;
        };
        let mut to = Storing {
            regs: &mut regs[g],
            region: &mut region[g],
            slot,
        };
        walk_storing(&mut dda, entry, grid, h.best.t, extra, &mut to, w);
        if w.state != DONE {
            debug_assert_eq!(w.last.map(u32::from), dda.voxel());
        }
    }
}

/// A walk that stopped in the voxel it last stored the ray in, `w.last`,
/// started again and moved into the next voxel (with the face it entered
/// by); `None`, and the walk done, when that voxel was the grid's last.
fn resume(spec: &GridSpec, r: &Ray64, w: &mut Walk) -> Option<(Dda, Option<usize>)> {
    let cell = w.last.map(u32::from);
    // (It started, so it starts again.)
    let mut d = Dda::start_at(spec, r.o, r.d, r.inv, r.t_min, r.t_max, cell)
        .expect("a walk that started starts again");
    match d.advance_axis() {
        Some(a) => Some((d, Some(a))),
        None => {
            w.state = DONE;
            None
        }
    }
}

/// Where a walk stores ray `slot`: one grid's registrations, and the
/// region of voxels its rays are in.
struct Storing<'a> {
    regs: &'a mut RegMap,
    region: &'a mut Region,
    slot: u32,
}

impl Storing<'_> {
    /// Stores the ray in voxel `v`, of index `index` in its grid.
    #[inline(always)]
    fn put(&mut self, index: usize, v: [u32; 3]) {
        self.regs.insert(index as u32, self.slot);
        self.region.add(v);
    }
}

/// [`store_along`], with the loop that skips empty blocks when the grid
/// has them.
#[inline(always)]
fn walk_storing(
    dda: &mut Dda,
    entry: Option<usize>,
    grid: &VoxelGrid,
    best: f64,
    limit: u32,
    to: &mut Storing,
    w: &mut Walk,
) -> u32 {
    if grid.busy.is_empty() {
        store_along::<false>(dda, entry, grid, best, limit, to, w)
    } else {
        store_along::<true>(dda, entry, grid, best, limit, to, w)
    }
}

/// The walk `dda` (entered through `entry`'s face, `None` at its first
/// voxel) stores the ray in up to `limit` voxels of `to`; returns how many.
/// With `SKIP`, it crosses blocks with nothing in them in one move (see
/// [`crate::bf::voxels::BusyBlocks`]); without, the loop is the plain
/// voxel-by-voxel walk (two loops, not one with a test, which cost small
/// grids' walks 4 % more instructions).
#[inline(always)]
fn store_along<const SKIP: bool>(
    dda: &mut Dda,
    mut entry: Option<usize>,
    grid: &VoxelGrid,
    best: f64,
    limit: u32,
    to: &mut Storing,
    w: &mut Walk,
) -> u32 {
    let mut n = 0;
    // Whether the walk has just entered a block not looked at yet.
    let mut new_block = SKIP;
    loop {
        if best < dda.t_enter {
            w.state = DONE; // the best hit lies before this voxel
            break;
        }
        if SKIP && new_block && !grid.busy.any(dda.cell) {
            // Nothing in this voxel's block: no voxel to store in until
            // the walk leaves it.
            match dda.leave_block(BLOCK_SHIFT) {
                Some(a) => {
                    entry = Some(a);
                    continue;
                }
                None => {
                    w.state = DONE;
                    break;
                }
            }
        }
        let f = grid.flags[dda.index];
        let stored = f & OCCUPIED != 0
            && match entry {
                None => true,
                Some(a) => f & entry_face(a, dda.steps_up(a)) != 0,
            };
        if stored {
            let v = dda.voxel();
            to.put(dda.index, v);
            w.last = [v[0] as u16, v[1] as u16, v[2] as u16];
            n += 1;
            if n == limit {
                break;
            }
        }
        match dda.advance_axis() {
            Some(a) => {
                entry = Some(a);
                if SKIP {
                    new_block = dda.entered_block(a, BLOCK_SHIFT);
                }
            }
            None => {
                w.state = DONE;
                break;
            }
        }
    }
    n
}
