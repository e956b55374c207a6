//! The breadth-first tracer (Nakamaru and Ohno): rays, not objects, in
//! memory; the object database read front to back, once per pass.
//!
//! A render is a sequence of rounds. Round 1 holds the eye rays; each later
//! round holds the shadow rays of the previous round's hits together with
//! the reflection and refraction rays they spawned ("shadow, reflection and
//! refraction rays of one depth are intersected together"). Each round:
//!
//! 1. [`intersect`]: the rays are intersected in passes over the objects,
//!    as many at a time as memory allows, the rest waiting on disk; each
//!    ray's result (nearest object and distance, or first blocker) is
//!    written as it finishes and sorted back into ray order;
//! 2. [`shade`]: rays and results are read together; misses and unblocked
//!    shadow rays add their colour; hits are joined with the objects in
//!    memory-sized sets sorted by object id, shaded, and spawn the next
//!    round's rays, which are sorted into a fixed order.
//!
//! Everything the render holds is bounded by `--memory`; see [`Budget`].

mod candidates;
mod intersect;
mod records;
mod regmap;
mod shade;
mod skip;
mod store;
mod tracer;
mod voxels;

pub use crate::render::Contribution;
pub use intersect::{IntersectStats, MAX_GRIDS, RaySource, Slots};
pub use records::{Outcome, RayKind, RayRec, ResultRec, SPAWN_SLOTS};
pub use shade::ShadeStats;
pub use store::{StoreNumber, StorePlan};
pub use tracer::{HeldRays, ResultReader, SortedRays, Tracer, eye_ray};
pub use voxels::{VoxelGrid, VoxelGrids};

use crate::error::Error;
use crate::grid::{GridSpec, MAX_CELLS, choose_resolution, plan_groups};
use crate::progress::{Prefixed, Progress};
use crate::render::{
    Camera, EyeRays, Frame, GridRes, Precision, RayCounts, RenderOptions, RenderStats,
};
use crate::sdb::Database;
use crate::simd::Elem;
use crate::spill::{self, SpillDir};
use crate::units::fmt_bytes;
use intersect::{REGISTRATION_BYTES, VOXEL_BYTES, WORST_REGISTRATION_BYTES, slot_bytes};
use serde::Serialize;
use std::path::PathBuf;

/// Options of the breadth-first tracer.
#[derive(Clone, Debug)]
pub struct BfOptions {
    /// Memory budget in bytes for everything the render holds.
    pub memory: u64,
    pub store: StoreNumber,
    /// Where rays and results spill (default: the system's temp dir).
    pub spill_dir: Option<PathBuf>,
    pub shading: Shading,
    /// Whether the models instances place are held for the render or
    /// read by each pass that needs them.
    pub models: ModelHolding,
}

/// Where the breadth-first tracer keeps the models instances place.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum ModelHolding {
    /// Held when they take at most a quarter of the budget, else read
    /// per pass.
    #[default]
    Auto,
    /// Read once and held for the render.
    Held,
    /// Read by each pass whose rays meet their instances, one model at a
    /// time, after the world's objects: the memory of the largest model,
    /// not of all of them.
    PerPass,
}

/// Where shading gets a hit's normals and material.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Shading {
    /// Worked out when the hit is found, during the intersection scan, and
    /// carried with the result: shading reads rays and results in ray order
    /// and needs no pass over the objects, and the rays it spawns come out
    /// already in order.
    #[default]
    Carry,
    /// The paper's Pseudocode 4: hits are sorted by object and joined with
    /// one front-to-back scan of the objects per shading set (what the
    /// cluster does, where results travel without surfaces, and what `sray
    /// bench table1` measures).
    Join,
}

impl std::str::FromStr for ModelHolding {
    type Err = String;
    fn from_str(s: &str) -> Result<ModelHolding, String> {
        match s {
            "auto" => Ok(ModelHolding::Auto),
            "held" => Ok(ModelHolding::Held),
            "per-pass" => Ok(ModelHolding::PerPass),
            _ => Err(format!(
                "unknown model holding '{s}' (expected auto, held or per-pass)"
            )),
        }
    }
}

impl std::str::FromStr for Shading {
    type Err = String;
    fn from_str(s: &str) -> Result<Shading, String> {
        match s {
            "carry" => Ok(Shading::Carry),
            "join" => Ok(Shading::Join),
            _ => Err(format!("unknown shading '{s}' (expected carry or join)")),
        }
    }
}

/// How the memory budget is spent. Whatever is left after the fixed parts
/// (frame buffer, voxel flags, I/O buffers) is shared by the phases, which
/// take turns: a round's rays and results may stay in memory (up to
/// [`RESIDENT_RAYS`] and [`RESIDENT_RESULTS`] of it), and the rest goes to
/// the ray slots while intersecting, and to the hit set and the next round's
/// sorter while shading. What does not fit spills to disk.
#[derive(Clone, Debug, Serialize)]
pub struct Budget {
    pub total: u64,
    pub frame: u64,
    pub voxel_flags: u64,
    /// The models instances place, held for the render.
    pub models: u64,
    pub io_buffers: u64,
    /// What the phases share.
    pub shared: u64,
    /// Bytes of one ray slot with its planned registrations: the most a
    /// fresh ray may make in its first pass, which sizes the smallest
    /// budget that will do. (How many slots a round gets depends on the
    /// registrations rays make in fact: see [`Budget::slots`].)
    pub slot_bytes: u64,
    /// Bytes of one ray slot without its registrations.
    pub slot_base_bytes: u64,
    /// Registrations planned per slot, at most.
    pub regs_per_slot: u64,
    /// Bytes of a shading set: the hits, their radix-sort copy and the
    /// rays they spawn (see [`Budget::shading_set_hits`]).
    pub shading_set: u64,
    /// Records the next-round sorter holds in memory (with a radix-sort
    /// copy of them when it spills a run).
    pub next_ray_sort_records: u64,
}

/// Shares of [`Budget::shared`].
pub const RESIDENT_RAYS: f64 = 0.30;
pub const RESIDENT_RESULTS: f64 = 0.10;
const SLOTS_SHARE: f64 = 0.45;
const DENSE_SHARE: f64 = 0.10;
const SET_SHARE: f64 = 0.25;
const NEXT_SHARE: f64 = 0.30;
/// Left over by both phases: the buffers of the phase not running may keep
/// this much (see [`Budget::idle_allowance`]).
const IDLE_SHARE: f64 = 0.05;

/// Record file buffers at any moment (a round's rays read, results and
/// next-round rays written, a merge's readers), and a margin for small
/// allocations; the database's block buffers come on top.
const IO_BYTES: u64 =
    5 * spill::IO_BUFFER as u64 + (spill::MERGE_FANIN * spill::MERGE_BUFFER) as u64 + (64 << 10);
/// Kept free of every planned buffer, for what no plan counts: the
/// allocator's slack and fragments, small allocations, the rounding of
/// buffer sizes. A sixteenth of the budget, at most 4 MiB.
fn slack(total: u64) -> u64 {
    (total / 16).min(4 << 20)
}
/// Fewest rays worth a pass.
const MIN_SLOTS: u64 = 64;
/// Databases smaller than this are cheap to scan...
const CHEAP_SCAN_BYTES: u64 = 256 << 20;
/// ... so that rounds keep at most this many rays in memory at once, which
/// measured faster than holding every ray (the scan's accesses to rays stay
/// in cache). 2^15 slots (about 20 MB) against 2^17: user + system time
/// 0.8x on balls4, gears4, tetra6 and teapot12 at 512x512 on one thread;
/// 2^13 was no better and makes more passes.
const CACHE_SLOTS: u64 = 1 << 15;

impl Budget {
    /// Splits `total` bytes for a render of `corners` pixel corners with
    /// `cells` voxels and `models` bytes of models, or explains the
    /// smallest budget that would do.
    /// `store` says how many registrations a ray slot plans for, and how
    /// far the last ray a shard admits may overrun its share; `threads`
    /// is the number of shards.
    pub fn plan<R: Elem>(
        total: u64,
        frame: u64,
        cells: u64,
        models: u64,
        scan_buffers: u64,
        store: &StorePlan,
        threads: usize,
    ) -> Result<Budget, Error> {
        let io = IO_BYTES + scan_buffers;
        let overrun = threads.max(1) as u64 * store.overrun() * WORST_REGISTRATION_BYTES as u64;
        let fixed = frame + cells + models + io + overrun + slack(total);
        let slot_bytes =
            slot_bytes::<R>() as u64 + store.planned() * WORST_REGISTRATION_BYTES as u64;
        // Without resident rays or results, the slots may take all but the
        // result sorter's share.
        let min_shared = ((MIN_SLOTS * slot_bytes) as f64 / (1.0 - RESIDENT_RESULTS)).ceil() as u64;
        let minimum = fixed + min_shared;
        if total < minimum {
            return Err(Error::Invalid(format!(
                "a memory budget of {} is too small for this render; it needs at least {} \
                 (frame buffer {}, voxel flags {}, {}I/O buffers {}, {MIN_SLOTS} rays {}, \
                 allocator slack {})",
                fmt_bytes(total),
                fmt_bytes(minimum),
                fmt_bytes(frame),
                fmt_bytes(cells),
                if models > 0 {
                    format!("models {}, ", fmt_bytes(models))
                } else {
                    String::new()
                },
                fmt_bytes(io),
                fmt_bytes(min_shared),
                fmt_bytes(slack(total)),
            )));
        }
        let shared = total - fixed;
        let part = |f: f64, rec: usize| ((shared as f64 * f) as u64 / rec as u64).max(16);
        Ok(Budget {
            total,
            frame,
            voxel_flags: cells,
            models,
            io_buffers: io,
            shared,
            slot_bytes,
            slot_base_bytes: intersect::slot_bytes::<R>() as u64,
            regs_per_slot: store.planned(),
            shading_set: (shared as f64 * SET_SHARE) as u64,
            next_ray_sort_records: part(NEXT_SHARE, 2 * std::mem::size_of::<RayRec>()),
        })
    }

    /// What one phase's buffers may keep while the other phase runs: the
    /// shares of either phase add up to 95 % of [`Budget::shared`].
    pub fn idle_allowance(&self) -> u64 {
        (self.shared as f64 * IDLE_SHARE) as u64
    }

    /// Hits per shading set in a scene of `lights` lights: each hit costs
    /// its record, the record's copy while the set is sorted by object, and
    /// the rays it may spawn (a shadow ray per light, a reflection and a
    /// refraction).
    pub fn shading_set_hits(&self, lights: usize) -> usize {
        let per_hit = 2 * std::mem::size_of::<records::HitRec>()
            + (lights + 2) * std::mem::size_of::<RayRec>();
        ((self.shading_set / per_hit as u64) as usize).max(16)
    }

    /// Largest grid that gets a dense voxel index (four bytes per voxel per
    /// thread), out of the slots' share.
    pub fn dense_cells(&self, threads: usize) -> usize {
        ((self.shared as f64 * DENSE_SHARE) as u64 / (4 * threads.max(1) as u64)) as usize
    }

    /// Whether `n` rays may stay in memory between phases.
    pub fn rays_resident(&self, n: u64) -> bool {
        n * std::mem::size_of::<RayRec>() as u64 <= (self.shared as f64 * RESIDENT_RAYS) as u64
    }

    /// Whether `n` results may be held in memory, placed by ray id.
    pub fn results_resident(&self, n: u64) -> bool {
        n * std::mem::size_of::<records::Outcome>() as u64
            <= (self.shared as f64 * RESIDENT_RESULTS) as u64
    }

    /// Records the result sorter holds when results spill.
    pub fn result_sort_records(&self) -> u64 {
        ((self.shared as f64 * RESIDENT_RESULTS) as u64
            / (std::mem::size_of::<records::Outcome>() + spill::RADIX_BYTES_PER_RECORD) as u64)
            .max(16)
    }

    /// Ray slots while intersecting, and the bytes their registrations
    /// may take in a pass, given what else stays in memory, the
    /// registrations a registering ray makes in a pass on average
    /// (`regs_per_ray`, at most [`Budget::regs_per_slot`]) and the voxels
    /// they are in per registration (`voxels_per_reg`, at most 1).
    ///
    /// A registration takes [`REGISTRATION_BYTES`], and each voxel
    /// [`VOXEL_BYTES`] more. Planned as if each registration had a voxel
    /// of its own, rings80's second round got 131 thousand slots of 1,404
    /// bytes for 982 thousand rays, where its rays share a voxel between
    /// 8 and 15 of them. The shards count what they use as they register,
    /// so rays that share fewer voxels than planned only wait for the next
    /// pass, as when they register more than planned.
    ///
    /// Planning every slot for the most a ray may register left most of
    /// the memory unused: mount11's rays make 1.3 registrations a pass
    /// where 33 were planned, so its rounds took 4-6 passes for want of
    /// slots. When rays register more than planned, those the pass has no
    /// room for wait for the next one, which changes no count.
    ///
    /// `streamed` says whether rays come in order from a stream (or their
    /// results do not have places of their own), which takes a queue;
    /// `dense_index` whether some grid is small enough for a dense voxel
    /// index (see [`Budget::dense_cells`]), whose share the slots take
    /// when none is.
    pub fn slots(
        &self,
        resident_rays: bool,
        resident_results: bool,
        regs_per_ray: f64,
        voxels_per_reg: f64,
        streamed: bool,
        dense_index: bool,
    ) -> (u64, u64) {
        let mut f = SLOTS_SHARE;
        if !resident_rays {
            f += RESIDENT_RAYS;
        }
        if !dense_index {
            f += DENSE_SHARE;
        }
        if !resident_results {
            f += 0.0; // the result sorter keeps its share
        }
        let regs = regs_per_ray.clamp(1.0, self.regs_per_slot.max(1) as f64);
        let base = if streamed {
            self.slot_base_bytes
        } else {
            self.slot_base_bytes - intersect::streamed_extra_bytes() as u64
        };
        let per_reg =
            REGISTRATION_BYTES as f64 + VOXEL_BYTES as f64 * voxels_per_reg.clamp(0.0, 1.0);
        let per = base as f64 + regs * per_reg;
        let slots = (((self.shared as f64) * f / per) as u64).max(MIN_SLOTS);
        (slots, (slots as f64 * regs * per_reg).ceil() as u64)
    }
}

/// Statistics of a breadth-first render (added to `--stats`).
#[derive(Clone, Debug, Default, Serialize)]
pub struct BfStats {
    /// Passes per round.
    pub passes: Vec<u64>,
    /// Per round, the rays not yet finished at the start of each pass.
    pub remaining_rays_per_pass: Vec<Vec<u64>>,
    /// Per round, the mean store number of each pass.
    pub store_numbers: Vec<Vec<f64>>,
    pub rays_per_round: Vec<u64>,
    /// Per round, the ray slots: the most rays a pass holds (fewer rays
    /// per pass mean more passes, each a scan of the objects).
    pub slots_per_round: Vec<u64>,
    pub db_scans: u64,
    pub db_bytes_read: u64,
    /// Blocks the intersection passes left unread (see `skip`).
    pub db_blocks_skipped: u64,
    /// How the models were kept ("held" or "per-pass"; none without
    /// models), and how many times the passes read one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub models: Option<ModelHolding>,
    pub model_reads: u64,
    pub spill_bytes_written: u64,
    pub ray_voxel_registrations: u64,
    pub tests_skipped_last_voxel: u64,
    pub tests_skipped_mailbox: u64,
    /// Rays that walked an aggregate's hierarchy.
    pub aggregate_walks: u64,
    pub memory_budget_bytes: u64,
    pub budget: Option<Budget>,
    pub store_number: String,
    /// Texture tiles the shading and the cut-outs read.
    #[serde(skip)]
    pub textures: Option<crate::texture::TileReads>,
}

/// A round's rays.
enum RoundRays {
    /// The eye rays, generated from the camera: corner `i` is ray `i`.
    Eye(u64),
    Held(HeldRays),
}

impl RoundRays {
    fn len(&self) -> u64 {
        match self {
            RoundRays::Eye(n) => *n,
            RoundRays::Held(HeldRays::Memory(v)) => v.len() as u64,
            RoundRays::Held(HeldRays::File(f)) => f.len(),
        }
    }

    /// Calls `f` with the rays as a [`RaySource`]: by id where they can be
    /// had so (eye rays, rays in memory), which lets every thread of the
    /// tracer take its own; else read in order.
    fn with_source<T>(
        &self,
        eye: &EyeRays,
        f: impl FnOnce(RaySource<'_>) -> Result<T, Error>,
    ) -> Result<T, Error> {
        match self {
            RoundRays::Eye(n) => f(RaySource::Indexed {
                len: *n,
                ray: &|i| eye_ray(eye, i),
            }),
            RoundRays::Held(HeldRays::Memory(v)) => f(RaySource::Indexed {
                len: v.len() as u64,
                ray: &|i| v[i as usize],
            }),
            RoundRays::Held(HeldRays::File(_)) => {
                let mut it = self.iter(eye)?;
                f(RaySource::Stream(&mut *it))
            }
        }
    }

    fn iter<'a>(
        &'a self,
        eye: &'a EyeRays,
    ) -> Result<Box<dyn Iterator<Item = Result<RayRec, Error>> + 'a>, Error> {
        Ok(match self {
            RoundRays::Eye(n) => Box::new((0..*n).map(|i| Ok(eye_ray(eye, i)))),
            RoundRays::Held(HeldRays::Memory(v)) => Box::new(v.iter().map(|r| Ok(*r))),
            RoundRays::Held(HeldRays::File(f)) => {
                let mut rd = f.reader()?;
                Box::new(std::iter::from_fn(move || rd.next().transpose()))
            }
        })
    }
}

/// A breadth-first render: the frame and the statistics.
pub struct BfOutput {
    pub frame: Frame,
    pub stats: RenderStats,
}

/// Where a breadth-first render keeps its frame: in memory when the frame
/// takes at most a quarter of the budget, else on disk as contributions,
/// sorted by slot and summed when the image is written, so that the
/// memory bound holds for any image size.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FramePlan {
    Memory,
    /// Contributions spill, at most this many in memory at a time.
    Spilled {
        records: usize,
    },
}

/// Bytes a spilled frame's sorter takes per contribution it holds: the
/// record, the radix sort's keys and indices, and the permuted copy.
const SPILLED_FRAME_RECORD_BYTES: u64 = 96;

impl FramePlan {
    pub fn new(slots: u64, memory: u64) -> FramePlan {
        if Frame::memory_bytes(slots) <= memory / 4 {
            FramePlan::Memory
        } else {
            let share = (memory / 16).min(64 << 20);
            FramePlan::Spilled {
                records: (share / SPILLED_FRAME_RECORD_BYTES).max(1024) as usize,
            }
        }
    }

    /// Bytes the frame holds in memory.
    pub fn bytes(&self, slots: u64) -> u64 {
        match *self {
            FramePlan::Memory => Frame::memory_bytes(slots),
            FramePlan::Spilled { records } => records as u64 * SPILLED_FRAME_RECORD_BYTES,
        }
    }

    /// An empty frame of this kind.
    pub fn frame(&self, opts: &RenderOptions, spill: &SpillDir) -> Frame {
        match *self {
            FramePlan::Memory => Frame::with_sampling(opts.width, opts.height, opts.sampling()),
            FramePlan::Spilled { records } => {
                Frame::spilled(opts.width, opts.height, opts.sampling(), spill, records)
            }
        }
    }
}

/// Grid specifications for the breadth-first tracer: as the depth-first
/// tracer's, but no finer than the memory budget allows.
pub fn plan_grids(
    db: &Database,
    opts: &RenderOptions,
    memory: u64,
) -> (Vec<GridSpec>, crate::grid::Partition) {
    let plan = plan_groups(db.sizes(), db.density(), opts.multiple_grids);
    let slots = opts.frame_slots();
    let frame = FramePlan::new(slots, memory).bytes(slots);
    let cap = (memory.saturating_sub(frame) / 8).clamp(1, MAX_CELLS);
    let mut specs = Vec::new();
    for (g, (bounds, &count)) in plan.bounds.iter().zip(&plan.counts).enumerate() {
        let res = match (g, opts.grid_res) {
            (0, GridRes::Fixed(r)) => r,
            _ => choose_resolution(
                bounds,
                count,
                opts.grid_density,
                cap / plan.counts.len() as u64,
            ),
        };
        specs.push(GridSpec::new(bounds, res));
    }
    (specs, plan.partition)
}

/// Renders `db` breadth-first.
pub fn render(
    db: &Database,
    opts: &RenderOptions,
    bf: &BfOptions,
    progress: &dyn Progress,
) -> Result<BfOutput, Error> {
    match opts.precision {
        Precision::Double => render_in::<f64>(db, opts, bf, progress),
        Precision::Single => render_in::<f32>(db, opts, bf, progress),
    }
}

fn render_in<R: Elem>(
    db: &Database,
    opts: &RenderOptions,
    bf: &BfOptions,
    progress: &dyn Progress,
) -> Result<BfOutput, Error> {
    opts.validate()?;
    let eye = EyeRays {
        camera: Camera::new(&db.scene().view, opts.width, opts.height)?,
        sampling: opts.sampling(),
    };
    // Marking the voxels counts objects.
    progress.set_unit("objects");
    let mut tr = Tracer::<R>::new(db, opts, bf, opts.frame_slots(), progress)?;
    let mut frame = FramePlan::new(opts.frame_slots(), bf.memory).frame(opts, &tr.spill);
    let mut counts = RayCounts {
        eye_rays: eye.count(),
        ..Default::default()
    };
    // Round 1: the eye rays, generated in order; each later round holds
    // the rays the previous one spawned, in key order.
    let mut rays = RoundRays::Eye(eye.count());
    let mut round = 1;
    loop {
        let n = rays.len();
        if n == 0 {
            break;
        }
        tr.stats.rays_per_round.push(n);
        // Each round counts its own rays against its own total (a new
        // count: the done count starts again at zero), and names itself in
        // the passes' messages. The whole render's rays are not known in
        // advance: each round holds the rays the previous one spawned.
        progress.set_unit("rays");
        progress.set_total(n);
        progress.set_message(&format!("round {round}: intersecting {n} rays"));
        let in_round = Prefixed::new(progress, format!("round {round}: "));
        let resident = matches!(rays, RoundRays::Held(HeldRays::Memory(_)));
        let (mut results, _) =
            rays.with_source(&eye, |src| tr.intersect(0, src, n, resident, &in_round))?;

        progress.set_message(&format!("round {round}: shading"));
        let (next, count, _) = rays.with_source(&eye, |src| {
            tr.shade(
                0,
                src,
                &mut results,
                &mut |corner, c| frame.add(corner, c),
                &mut counts,
            )
        })?;
        tr.recycle(results);
        if let RoundRays::Held(HeldRays::Memory(v)) =
            std::mem::replace(&mut rays, RoundRays::Eye(0))
        {
            tr.recycle_rays(v);
        }
        rays = RoundRays::Held(tr.hold_rays(next, count)?);
        round += 1;
    }
    let st = tr.finish_stats();
    let grid_stats = tr.grid_stats();
    let stats = RenderStats {
        mode: "bf".into(),
        objects: db.object_count(),
        width: opts.width,
        height: opts.height,
        depth: opts.max_depth,
        threads: tr.threads,
        precision: format!("{:?}", opts.precision).to_lowercase(),
        simd: Some(tr.isa().name().into()),
        epsilon: tr.eps,
        rays: counts,
        intersection_tests: tr.tests.total(),
        intersection_tests_by_kind: tr.tests,
        grid_res: grid_stats[0].resolution,
        grids: grid_stats,
        preprocess_seconds: tr.preprocess_seconds,
        trace_seconds: tr.intersect_seconds + tr.shade_seconds,
        intersect_seconds: Some(tr.intersect_seconds),
        shade_seconds: Some(tr.shade_seconds),
        peak_rss_bytes: crate::sys::peak_rss_bytes(),
        textures: st.textures,
        details: Some(serde_json::to_value(&st).map_err(|e| Error::Invalid(e.to_string()))?),
        ..Default::default()
    };
    Ok(BfOutput { frame, stats })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn too_small_a_budget_names_the_minimum() {
        let specs = [GridSpec::new(
            &crate::scene::Aabb {
                min: [0.0; 3],
                max: [1.0; 3],
            },
            [10, 10, 10],
        )];
        let store = StorePlan::new(StoreNumber::Adaptive, &specs);
        let e = Budget::plan::<f64>(1 << 20, 513 * 513 * 24, 1000, 0, 1 << 17, &store, 2)
            .unwrap_err()
            .to_string();
        assert!(e.contains("needs at least"), "{e}");
        assert!(Budget::plan::<f64>(64 << 20, 513 * 513 * 24, 1000, 0, 1 << 17, &store, 2).is_ok());
        // A small image fits in a few hundred kilobytes.
        assert!(
            Budget::plan::<f64>(600 << 10, 33 * 33 * 24, 20_000, 0, 1 << 17, &store, 2).is_ok()
        );
    }

    /// Slots are planned for the registrations rays make: rays that make
    /// few get more slots in the same memory (at most as many
    /// registrations as the slots may make in all), never more than the
    /// store number allows for, and a stream's queue costs slots.
    #[test]
    fn slots_follow_the_registrations_rays_make() {
        let specs = [GridSpec::new(
            &crate::scene::Aabb {
                min: [0.0; 3],
                max: [1.0; 3],
            },
            [300, 300, 300],
        )];
        let store = StorePlan::new(StoreNumber::Adaptive, &specs);
        let b = Budget::plan::<f64>(256 << 20, 513 * 513 * 24, 27_000_000, 0, 1 << 17, &store, 2)
            .unwrap();
        assert_eq!(b.regs_per_slot, 30);
        let worst = WORST_REGISTRATION_BYTES as u64;
        let (few, few_regs) = b.slots(false, true, 1.5, 1.0, false, true);
        let (many, many_regs) = b.slots(false, true, 25.0, 1.0, false, true);
        let (most, most_regs) = b.slots(false, true, f64::INFINITY, 1.0, false, true);
        assert!(few > 2 * many, "{few} slots against {many}");
        assert!(many > most, "{many} slots against {most}");
        assert_eq!(most_regs, most * 30 * worst);
        assert_eq!(few_regs, (few as f64 * 1.5 * worst as f64).ceil() as u64);
        assert!(many_regs >= many * 25 * worst);
        // Rays that share their voxels get more slots, with more
        // registrations in the same bytes.
        let (shared, shared_bytes) = b.slots(false, true, 25.0, 0.1, false, true);
        assert!(2 * shared > 3 * many, "{shared} slots against {many}");
        let per_reg = REGISTRATION_BYTES as f64 + 0.1 * VOXEL_BYTES as f64;
        assert_eq!(shared_bytes, (shared as f64 * 25.0 * per_reg).ceil() as u64);
        // Planned for the most a ray may make, as before plans followed
        // what rays make.
        let before = (b.shared as f64 * (SLOTS_SHARE + RESIDENT_RAYS)) as u64 / b.slot_bytes;
        assert!(most >= before, "{most} slots against {before}");
        // A streamed ray waits in the queue by its slot, which takes no
        // more than the id a ray admitted by id waits by.
        let (streamed, _) = b.slots(false, true, 1.5, 1.0, true, true);
        assert!(streamed <= few);
        // A grid too large for a dense voxel index leaves its share.
        let (sparse, _) = b.slots(false, true, 1.5, 1.0, false, false);
        assert!(sparse > few);
        // Everything fits in what the slots may take.
        let share = b.shared as f64 * (SLOTS_SHARE + RESIDENT_RAYS);
        for (n, bytes, streamed) in [
            (few, few_regs, false),
            (many, many_regs, false),
            (shared, shared_bytes, false),
        ] {
            let base = b.slot_base_bytes
                - if streamed {
                    0
                } else {
                    intersect::streamed_extra_bytes() as u64
                };
            let bytes = n * base + bytes;
            assert!(bytes as f64 <= share * 1.001, "{bytes} bytes of {share}");
        }
    }
}
