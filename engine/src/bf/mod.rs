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

mod files;
mod intersect;
mod radix;
mod records;
mod regmap;
mod shade;
mod voxels;

pub use files::{ExternalSorter, RecordFile, SpillDir};
pub use intersect::{IntersectStats, MAX_GRIDS, Slots, StoreNumber, StorePlan};
pub use records::{NO_HIT, RayKind, RayRec, ResultRec};
pub use shade::ShadeStats;
pub use voxels::{VoxelGrid, VoxelGrids};

use crate::error::Error;
use crate::grid::{GridSpec, choose_resolution, plan_groups};
use crate::math::Real;
use crate::progress::Progress;
use crate::render::{
    Camera, Frame, GridRes, Precision, RayCounts, RenderOptions, RenderStats, ShadeScene, epsilon,
};
use crate::sdb::Database;
use files::RecordWriter;
use intersect::{IntersectSetup, REGISTRATION_BYTES, intersect_rays, slot_bytes};
use serde::Serialize;
use shade::{NextRays, ShadeSetup, ray_key, shade_round};
use std::path::PathBuf;
use std::time::Instant;

/// Options of the breadth-first tracer.
#[derive(Clone, Debug)]
pub struct BfOptions {
    /// Memory budget in bytes for everything the render holds.
    pub memory: u64,
    pub store: StoreNumber,
    /// Where rays and results spill (default: the system's temp dir).
    pub spill_dir: Option<PathBuf>,
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
    pub io_buffers: u64,
    /// What the phases share.
    pub shared: u64,
    /// Bytes of one ray slot with its planned registrations.
    pub slot_bytes: u64,
    /// Hits per shading set.
    pub shading_set: u64,
    /// Records the next-round sorter holds in memory.
    pub next_ray_sort_records: u64,
}

/// Shares of [`Budget::shared`].
pub const RESIDENT_RAYS: f64 = 0.30;
pub const RESIDENT_RESULTS: f64 = 0.10;
const SLOTS_SHARE: f64 = 0.45;
const DENSE_SHARE: f64 = 0.10;
const SET_SHARE: f64 = 0.25;
const NEXT_SHARE: f64 = 0.30;

/// Record file buffers at any moment (a round's rays read, results and
/// next-round rays written, a merge's readers), and a margin for small
/// allocations; the database's block buffers come on top.
const IO_BYTES: u64 =
    5 * files::IO_BUFFER as u64 + (files::MERGE_FANIN * files::MERGE_BUFFER) as u64 + (64 << 10);
/// Fewest rays worth a pass.
const MIN_SLOTS: u64 = 64;
/// Registrations planned per ray in memory.
const REGS_PER_SLOT: u64 = 4;
/// Databases smaller than this are cheap to scan...
const CHEAP_SCAN_BYTES: u64 = 256 << 20;
/// ... so that rounds keep at most this many rays in memory at once, which
/// measured faster than holding every ray (the scan's accesses to rays stay
/// in cache).
const CACHE_SLOTS: u64 = 1 << 17;
/// Most voxels in the breadth-first grids.
const MAX_CELLS: u64 = 1 << 27;

impl Budget {
    /// Splits `total` bytes for a render of `corners` pixel corners with
    /// `cells` voxels, or explains the smallest budget that would do.
    pub fn plan<R: Real>(
        total: u64,
        corners: u64,
        cells: u64,
        scan_buffers: u64,
    ) -> Result<Budget, Error> {
        let frame = corners * 24;
        let io = IO_BYTES + scan_buffers;
        let fixed = frame + cells + io;
        let slot_bytes = slot_bytes::<R>() as u64 + REGS_PER_SLOT * REGISTRATION_BYTES as u64;
        // Without resident rays or results, the slots may take all but the
        // result sorter's share.
        let min_shared = ((MIN_SLOTS * slot_bytes) as f64 / (1.0 - RESIDENT_RESULTS)).ceil() as u64;
        let minimum = fixed + min_shared;
        if total < minimum {
            return Err(Error::Invalid(format!(
                "a memory budget of {} is too small for this render; it needs at least {} \
                 (frame buffer {}, voxel flags {}, I/O buffers {}, {MIN_SLOTS} rays {})",
                fmt_bytes(total),
                fmt_bytes(minimum),
                fmt_bytes(frame),
                fmt_bytes(cells),
                fmt_bytes(io),
                fmt_bytes(min_shared),
            )));
        }
        let shared = total - fixed;
        let part = |f: f64, rec: usize| ((shared as f64 * f) as u64 / rec as u64).max(16);
        Ok(Budget {
            total,
            frame,
            voxel_flags: cells,
            io_buffers: io,
            shared,
            slot_bytes,
            shading_set: part(SET_SHARE, std::mem::size_of::<records::HitRec>()),
            next_ray_sort_records: part(NEXT_SHARE, std::mem::size_of::<RayRec>()),
        })
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
        n * std::mem::size_of::<ResultRec>() as u64
            <= (self.shared as f64 * RESIDENT_RESULTS) as u64
    }

    /// Records the result sorter holds when results spill.
    pub fn result_sort_records(&self) -> u64 {
        ((self.shared as f64 * RESIDENT_RESULTS) as u64 / std::mem::size_of::<ResultRec>() as u64)
            .max(16)
    }

    /// Ray slots while intersecting, given what else stays in memory.
    pub fn slots(&self, resident_rays: bool, resident_results: bool) -> u64 {
        let mut f = SLOTS_SHARE;
        if !resident_rays {
            f += RESIDENT_RAYS;
        }
        if !resident_results {
            f += 0.0; // the result sorter keeps its share
        }
        (((self.shared as f64) * f) as u64 / self.slot_bytes).max(MIN_SLOTS)
    }
}

/// `1.5 MiB` and the like.
pub fn fmt_bytes(b: u64) -> String {
    const U: [&str; 5] = ["B", "KiB", "MiB", "GiB", "TiB"];
    let mut v = b as f64;
    let mut i = 0;
    while v >= 1024.0 && i < U.len() - 1 {
        v /= 1024.0;
        i += 1;
    }
    if i == 0 {
        format!("{b} B")
    } else {
        format!("{v:.1} {}", U[i])
    }
}

/// Parses `64MiB`, `2GiB`, `512M`, `1G`, `1048576`.
pub fn parse_bytes(s: &str) -> Result<u64, String> {
    let t = s.trim();
    let split = t
        .find(|c: char| !(c.is_ascii_digit() || c == '.'))
        .unwrap_or(t.len());
    let (num, unit) = t.split_at(split);
    let v: f64 = num
        .parse()
        .map_err(|_| format!("'{s}' is not a size (e.g. 64MiB, 2GiB)"))?;
    let mul: u64 = match unit.trim().to_ascii_lowercase().as_str() {
        "" | "b" => 1,
        "k" | "kb" | "kib" => 1 << 10,
        "m" | "mb" | "mib" => 1 << 20,
        "g" | "gb" | "gib" => 1 << 30,
        "t" | "tb" | "tib" => 1 << 40,
        u => {
            return Err(format!(
                "unknown size unit '{u}' in '{s}' (use KiB, MiB, GiB)"
            ));
        }
    };
    let b = v * mul as f64;
    if !(1.0..1.8e19).contains(&b) {
        return Err(format!("size '{s}' is out of range"));
    }
    Ok(b as u64)
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
    pub db_scans: u64,
    pub db_bytes_read: u64,
    pub spill_bytes_written: u64,
    pub ray_voxel_registrations: u64,
    pub tests_skipped_last_voxel: u64,
    pub tests_skipped_mailbox: u64,
    pub memory_budget_bytes: u64,
    pub budget: Option<Budget>,
    pub store_number: String,
}

/// A round's rays.
enum RoundRays {
    /// The eye rays, generated from the camera: corner `i` is ray `i`.
    Eye(u64),
    Memory(Vec<RayRec>),
    File(RecordFile<RayRec>),
}

impl RoundRays {
    fn len(&self) -> u64 {
        match self {
            RoundRays::Eye(n) => *n,
            RoundRays::Memory(v) => v.len() as u64,
            RoundRays::File(f) => f.len(),
        }
    }

    fn iter<'a>(
        &'a self,
        eye: &'a dyn Fn(u64) -> RayRec,
    ) -> Result<Box<dyn Iterator<Item = Result<RayRec, Error>> + 'a>, Error> {
        Ok(match self {
            RoundRays::Eye(n) => Box::new((0..*n).map(|i| Ok(eye(i)))),
            RoundRays::Memory(v) => Box::new(v.iter().map(|r| Ok(*r))),
            RoundRays::File(f) => {
                let mut rd = f.reader()?;
                Box::new(std::iter::from_fn(move || rd.next().transpose()))
            }
        })
    }
}

fn result_key(r: &ResultRec) -> u64 {
    r.ray
}

/// A slot of the in-memory results not yet written.
const UNSET: ResultRec = ResultRec {
    ray: u64::MAX,
    object: NO_HIT,
    _pad: 0,
    t: 0.0,
};

/// A round's results, brought into ray order: placed by id in memory, or
/// sorted externally.
enum Results {
    Dense(Vec<ResultRec>),
    Sort(ExternalSorter<ResultRec, u64, fn(&ResultRec) -> u64>),
}

impl Results {
    fn put(&mut self, r: ResultRec) -> Result<(), Error> {
        match self {
            Results::Dense(v) => {
                v[r.ray as usize] = r;
                Ok(())
            }
            Results::Sort(s) => s.push(r),
        }
    }

    fn into_reader(self) -> Result<ResultReader, Error> {
        Ok(match self {
            Results::Dense(v) => ResultReader::Dense(v.into_iter()),
            Results::Sort(s) => ResultReader::Sorted(s.finish()?),
        })
    }
}

enum ResultReader {
    Dense(std::vec::IntoIter<ResultRec>),
    Sorted(files::Sorted<ResultRec, u64, fn(&ResultRec) -> u64>),
}

impl ResultReader {
    fn next(&mut self) -> Result<Option<ResultRec>, Error> {
        match self {
            ResultReader::Dense(it) => Ok(it.next()),
            ResultReader::Sorted(s) => s.next(),
        }
    }
}

/// A breadth-first render: the frame and the statistics.
pub struct BfOutput {
    pub frame: Frame,
    pub stats: RenderStats,
}

/// Grid specifications for the breadth-first tracer: as the depth-first
/// tracer's, but no finer than the memory budget allows.
pub fn plan_grids(
    db: &Database,
    opts: &RenderOptions,
    memory: u64,
) -> (Vec<GridSpec>, crate::grid::Partition) {
    let plan = plan_groups(db.sizes(), opts.multiple_grids);
    let frame = opts.corners() * 24;
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

fn render_in<R: Real>(
    db: &Database,
    opts: &RenderOptions,
    bf: &BfOptions,
    progress: &dyn Progress,
) -> Result<BfOutput, Error> {
    opts.validate()?;
    let header = db.scene();
    let camera = Camera::new(&header.view, opts.width, opts.height)?;
    let (specs, partition) = plan_grids(db, opts, bf.memory);
    if specs.len() > MAX_GRIDS {
        return Err(Error::Invalid("too many grids".into()));
    }
    let cells: u64 = specs.iter().map(|s| s.cells() as u64).sum();
    let budget = Budget::plan::<R>(
        bf.memory,
        opts.corners(),
        cells,
        db.scan_buffer_bytes() as u64,
    )?;
    let threads = if opts.threads == 0 {
        crate::sys::cpus()
    } else {
        opts.threads
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| Error::Invalid(format!("cannot start threads: {e}")))?;
    let spill = SpillDir::new(bf.spill_dir.as_deref())?;
    let eps = epsilon(&db.bbox(), opts.precision);
    let shade_scene = ShadeScene::new(header, opts.max_depth, eps);

    // Preprocess: one scan marks the voxels.
    let t0 = Instant::now();
    progress.set_message("preprocess: marking voxels");
    let (mut grids, pre) = VoxelGrids::build(db, specs, partition, progress)?;
    let preprocess_seconds = t0.elapsed().as_secs_f64();

    let mut frame = Frame::new(opts.width, opts.height);
    let mut counts = RayCounts::default();
    let mut st = BfStats {
        memory_budget_bytes: bf.memory,
        db_scans: 1,
        db_bytes_read: pre.bytes_read,
        store_number: match bf.store {
            StoreNumber::Fixed(n) => n.to_string(),
            StoreNumber::Adaptive => "adaptive".into(),
        },
        ..Default::default()
    };
    let mut tests = crate::render::KindCounts::default();
    let store = StorePlan::new(bf.store, &grids);
    let (mut t_intersect, mut t_shade) = (0.0, 0.0);
    let mut slots = Slots::<R>::new(threads);

    // Round 1: the eye rays, generated in corner order.
    let eye = camera.eye.to_array();
    let eye_ray = |i: u64| {
        let (col, row) = camera.corner_of(i as u32);
        RayRec {
            o: eye,
            d: camera.direction(col, row).to_array(),
            t_max: f64::INFINITY,
            key: i,
            payload: [1.0, 0.0, 0.0],
            corner: i as u32,
            depth: 1,
            kind: RayKind::Eye as u8,
            _pad: [0; 6],
        }
    };
    let corners = opts.corners();
    counts.eye_rays = corners;
    let mut rays = RoundRays::Eye(corners);
    let mut round = 1;
    // Buffers reused from round to round: allocating them afresh costs
    // page faults every round.
    let mut dense_buf: Vec<ResultRec> = Vec::new();
    let mut spare_rays: Vec<RayRec> = Vec::new();
    let mut set_buf = Vec::new();
    let mut shade_outputs = Vec::new();
    let mut radix = radix::Scratch::default();
    loop {
        let n = rays.len();
        if n == 0 {
            break;
        }
        st.rays_per_round.push(n);
        progress.set_total(n);
        progress.set_message(&format!("round {round}: intersecting {n} rays"));

        // Intersect; results go in ray order, in memory if they fit.
        let ti = Instant::now();
        let resident = budget.results_resident(n);
        let mut results = if resident {
            let mut v = std::mem::take(&mut dense_buf);
            v.clear();
            v.resize(n as usize, UNSET);
            Results::Dense(v)
        } else {
            Results::Sort(ExternalSorter::new(
                &spill,
                "results",
                budget.result_sort_records() as usize,
                result_key,
            ))
        };
        let ist = {
            let mut slots_n = budget.slots(matches!(rays, RoundRays::Memory(_)), resident);
            if db.raw_bytes() < CHEAP_SCAN_BYTES {
                // A pass over a small database costs little; a smaller ray
                // set keeps the scan's ray accesses in cache.
                slots_n = slots_n.min(CACHE_SLOTS);
            }
            let mut setup = IntersectSetup {
                db,
                grids: &mut grids,
                store,
                slots: slots_n as usize,
                registrations: (slots_n * REGS_PER_SLOT) as usize,
                dense_cells: budget.dense_cells(threads),
                eps,
            };
            let mut emit = |r: ResultRec| results.put(r);
            let mut it = rays.iter(&eye_ray)?;
            intersect_rays::<R>(
                &mut setup, &pool, &mut slots, &mut it, n, &mut emit, progress,
            )?
        };
        t_intersect += ti.elapsed().as_secs_f64();
        st.passes.push(ist.passes);
        st.remaining_rays_per_pass.push(ist.remaining_rays_per_pass);
        st.store_numbers.push(ist.store_numbers);
        st.db_scans += ist.db_scans;
        st.db_bytes_read += ist.db_bytes_read;
        st.ray_voxel_registrations += ist.registrations;
        st.tests_skipped_last_voxel += ist.tests_skipped_last_voxel;
        st.tests_skipped_mailbox += ist.tests_skipped_mailbox;
        tests += ist.intersection_tests;

        // Shade.
        let ts = Instant::now();
        progress.set_message(&format!("round {round}: shading"));
        let mut results = results.into_reader()?;
        let mut next: NextRays = ExternalSorter::with_buffer(
            &spill,
            "rays",
            budget.next_ray_sort_records as usize,
            ray_key as fn(&RayRec) -> u64,
            std::mem::take(&mut spare_rays),
        );
        let mut setup = ShadeSetup {
            db,
            set: &mut set_buf,
            outputs: &mut shade_outputs,
            radix: &mut radix,
            materials: &header.materials,
            shade: &shade_scene,
            set_cap: budget.shading_set as usize,
        };
        let mut next_result = || results.next();
        let sst = {
            let mut it = rays.iter(&eye_ray)?;
            shade_round(
                &mut setup,
                &pool,
                &mut it,
                &mut next_result,
                &mut frame,
                &mut next,
                &mut counts,
            )?
        };
        if let ResultReader::Dense(it) = results {
            dense_buf = it.into_iter().collect::<Vec<_>>();
            dense_buf.clear();
        }
        st.db_scans += sst.db_scans;
        st.db_bytes_read += sst.db_bytes_read;
        // The next round's rays, in key order: kept in memory if they fit,
        // else written to a file.
        if let RoundRays::Memory(v) = std::mem::replace(&mut rays, RoundRays::Eye(0)) {
            spare_rays = v;
        }
        let count = next.len();
        let sorted = next.finish()?;
        rays = match sorted.into_vec() {
            Ok(v) if budget.rays_resident(count) => RoundRays::Memory(v),
            Ok(v) => {
                let mut w = RecordWriter::<RayRec>::create(&spill, "round")?;
                w.extend(&v)?;
                spare_rays = v;
                RoundRays::File(w.finish()?)
            }
            Err(mut sorted) => {
                let mut w = RecordWriter::<RayRec>::create(&spill, "round")?;
                while let Some(r) = sorted.next()? {
                    w.push(&r)?;
                }
                RoundRays::File(w.finish()?)
            }
        };
        t_shade += ts.elapsed().as_secs_f64();
        round += 1;
    }
    st.spill_bytes_written = spill.bytes_written();
    st.budget = Some(budget);
    let grid_stats = grids.stats();
    let stats = RenderStats {
        mode: "bf".into(),
        objects: db.object_count(),
        width: opts.width,
        height: opts.height,
        depth: opts.max_depth,
        threads,
        precision: format!("{:?}", opts.precision).to_lowercase(),
        epsilon: eps,
        rays: counts,
        intersection_tests: tests.total(),
        intersection_tests_by_kind: tests,
        grid_res: grid_stats[0].resolution,
        grids: grid_stats,
        preprocess_seconds,
        trace_seconds: t_intersect + t_shade,
        intersect_seconds: Some(t_intersect),
        shade_seconds: Some(t_shade),
        peak_rss_bytes: crate::sys::peak_rss_bytes(),
        breadth_first: Some(serde_json::to_value(&st).map_err(|e| Error::Invalid(e.to_string()))?),
        ..Default::default()
    };
    Ok(BfOutput { frame, stats })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse() {
        assert_eq!(parse_bytes("64MiB"), Ok(64 << 20));
        assert_eq!(parse_bytes("2GiB"), Ok(2 << 30));
        assert_eq!(parse_bytes("512k"), Ok(512 << 10));
        assert_eq!(parse_bytes("1.5G"), Ok(3 << 29));
        assert_eq!(parse_bytes("1000"), Ok(1000));
        assert!(parse_bytes("lots").is_err());
        assert!(parse_bytes("5 parsecs").is_err());
        assert!(parse_bytes("0").is_err());
    }

    #[test]
    fn too_small_a_budget_names_the_minimum() {
        let e = Budget::plan::<f64>(1 << 20, 513 * 513, 1000, 1 << 17)
            .unwrap_err()
            .to_string();
        assert!(e.contains("needs at least"), "{e}");
        assert!(Budget::plan::<f64>(64 << 20, 513 * 513, 1000, 1 << 17).is_ok());
        // A small image fits in a few hundred kilobytes.
        assert!(Budget::plan::<f64>(600 << 10, 33 * 33, 20_000, 1 << 17).is_ok());
    }
}
