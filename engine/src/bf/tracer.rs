//! The breadth-first stages as one object: a [`Tracer`] owns a database's
//! grids, the memory budget and the buffers reused from round to round,
//! and runs the two stages of a round on any contiguous run of its rays:
//! [`Tracer::intersect`] (results back in ray order) and [`Tracer::shade`]
//! (colour contributions and the next round's rays, sorted by key).
//!
//! The embedded renderer ([`super::render`]) gives a tracer whole rounds; a
//! cluster worker gives it one shard of a round at a time. Both produce the
//! same results, because a ray's intersection depends only on the ray, and
//! a ray's spawn keys only on its id in the round.

use super::intersect::{
    IntersectSetup, IntersectStats, RaySource, ResultSink, Slots, intersect_rays,
};
use super::records::{Outcome, RayKind, RayRec, ResultRec};
use super::shade::{
    ChunkOut, NextRays, ShadeSetup, ShadeStats, ray_key, shade_indexed, shade_round,
};
use super::store::StorePlan;
use super::voxels::VoxelGrids;
use super::{BfOptions, BfStats, Budget, CACHE_SLOTS, CHEAP_SCAN_BYTES, MAX_GRIDS, ModelHolding};
use crate::error::Error;
use crate::hit::PrimId;
use crate::models::Models;
use crate::progress::Progress;
use crate::render::{EyeRays, KindCounts, RayCounts, RenderOptions, ShadeScene, epsilon};
use crate::scene::Material;
use crate::sdb::Database;
use crate::simd::{Elem, Isa};
use crate::spill::{ExternalSorter, RecordFile, RecordReader, RecordWriter, Sorted, SpillDir};
use std::time::Instant;

/// Slots plan for this much more than the last round's rays registered.
const REGS_MARGIN: f64 = 1.25;
/// And for this many times the voxels per registration the last round's
/// rays were in (a round's rays share fewer voxels than the last round's
/// when they are its reflections: rings80's eye rays, one voxel for 18
/// to 32 registrations; their reflections, one for 8 to 15).
const VOXELS_MARGIN: f64 = 2.0;

/// Eye ray `i` (see [`EyeRays`]): its colour goes to frame slot
/// `corner`, its key is its id.
pub fn eye_ray(eye: &EyeRays, i: u64) -> RayRec {
    let (d, slot) = eye.ray(i);
    RayRec {
        o: eye.camera.eye.to_array(),
        d: d.to_array(),
        t_max: f64::INFINITY,
        key: i,
        payload: [1.0, 0.0, 0.0],
        corner: slot,
        depth: 1,
        kind: RayKind::Eye as u8,
        _pad: [0; 6],
    }
}

fn result_key(r: &Outcome) -> u64 {
    r.res.ray
}

/// The result of ray `ray` when it hit nothing (or, a shadow ray, was not
/// blocked): what the tracer reports for it, without storing it.
fn miss(ray: u64) -> Outcome {
    Outcome::bare(ResultRec {
        ray,
        prim: PrimId::NONE,
        t: f64::INFINITY,
    })
}

type ResultSorter = ExternalSorter<Outcome, u64, fn(&Outcome) -> u64>;

/// Results of a run of rays, brought into ray order: placed by id in memory
/// when they fit, else sorted externally. Only hits (and blocked shadow
/// rays) are stored: a missing result is a miss.
enum Results {
    Dense { first: u64, v: Vec<Outcome> },
    Sort(ResultSorter),
}

/// Rays in key order, as [`Tracer::shade`] returns the ones it spawned.
pub type SortedRays = Sorted<RayRec, u64, fn(&RayRec) -> u64>;

/// Stored hits read back in ray order.
pub type SortedOutcomes = Sorted<Outcome, u64, fn(&Outcome) -> u64>;

/// Results in ray order, one per ray: as [`Tracer::intersect`] returns
/// them (with the surfaces it carried, if any), or read from a file of
/// results already in order.
pub enum ResultReader {
    /// Every result, and the index of the next one; the buffer goes back
    /// to the tracer for the next call ([`Tracer::recycle`]), so that it
    /// is not faulted in afresh every round or task.
    Dense {
        v: Vec<Outcome>,
        next: usize,
    },
    /// The stored hits in ray order, misses filled in between.
    Sparse {
        hits: Box<SortedOutcomes>,
        pending: Option<Outcome>,
        next: u64,
        end: u64,
    },
    File(RecordReader<ResultRec>),
}

impl ResultReader {
    /// The next result, with its carried surface if there is one.
    pub fn next_outcome(&mut self) -> Result<Option<Outcome>, Error> {
        match self {
            ResultReader::Dense { v, next } => {
                let o = v.get(*next).copied();
                *next += o.is_some() as usize;
                Ok(o)
            }
            ResultReader::Sparse {
                hits,
                pending,
                next,
                end,
            } => {
                if *next == *end {
                    return Ok(None);
                }
                if pending.is_none() {
                    *pending = hits.next()?;
                }
                let id = *next;
                *next += 1;
                match *pending {
                    Some(h) if h.res.ray == id => Ok(pending.take()),
                    Some(h) if h.res.ray < id => Err(Error::Invalid(format!(
                        "intersection results out of order: ray {} after ray {id}",
                        h.res.ray
                    ))),
                    _ => Ok(Some(miss(id))),
                }
            }
            ResultReader::File(r) => Ok(r.next()?.map(Outcome::bare)),
        }
    }

    /// The next result, as it travels between processes.
    pub fn next_result(&mut self) -> Result<Option<ResultRec>, Error> {
        Ok(self.next_outcome()?.map(|o| o.res))
    }
}

/// Read-ahead buffers may take at most this part of the memory budget
/// (two batches of blocks: a few MiB for databases of about a thousand
/// objects a block, so batches of 32 blocks run from budgets of about
/// 96 MiB, and smaller batches below).
const READ_AHEAD_SHARE: u64 = 16;

/// The breadth-first stages over one database.
pub struct Tracer<'db, R: Elem> {
    db: &'db Database,
    grids: VoxelGrids,
    store: StorePlan,
    pub budget: Budget,
    pool: rayon::ThreadPool,
    pub threads: usize,
    pub spill: SpillDir,
    pub eps: f64,
    /// How far from its box an object's hit may be computed.
    slack: f64,
    /// Trace crowded groups of objects as aggregates.
    aggregates: bool,
    shading: super::Shading,
    shade_scene: ShadeScene,
    /// The models the database's instances place, held for the render.
    pub models: Models,
    /// The world's materials followed by the models'.
    materials: Vec<Material>,
    slots: Slots<R>,
    /// Registrations a ray makes in a pass, on average, as the last round
    /// found (with a margin): what the next round's slots plan for. The
    /// first round plans for the most a fresh ray may make: planning for
    /// fewer than its rays make leaves slots idle (rings80's eye rays make
    /// 25 a pass, mount11's 1.3).
    regs_per_ray: f64,
    /// Voxels per registration, as the last round found (with a margin;
    /// 1 before the first): with the sample of a round's own rays, what
    /// the next round's slots plan for.
    voxels_per_reg: f64,
    /// Blocks a batch when intersection passes read them on a thread of
    /// their own (0: on the shards' thread).
    read_ahead: usize,
    /// The kernels' instruction set.
    isa: Isa,
    // Buffers reused from call to call: allocating them afresh costs page
    // faults every round.
    dense_buf: Vec<Outcome>,
    spare_rays: Vec<RayRec>,
    set_buf: Vec<super::records::HitRec>,
    carried_buf: Vec<super::shade::Carried>,
    shade_outputs: Vec<super::shade::SetOutput>,
    /// Per-chunk outputs of the parallel shading by id, reused.
    chunk_outs: Vec<ChunkOut>,
    radix: crate::spill::RadixScratch,
    /// Accumulated over every call.
    pub stats: BfStats,
    pub tests: KindCounts,
    pub preprocess_seconds: f64,
    pub intersect_seconds: f64,
    pub shade_seconds: f64,
}

impl<'db, R: Elem> Tracer<'db, R> {
    /// Plans the grids and the budget and marks the voxels (one scan).
    /// `frame_corners` is the size of the frame this process holds beside
    /// the tracer (0 for a cluster worker, which holds none).
    pub fn new(
        db: &'db Database,
        opts: &RenderOptions,
        bf: &BfOptions,
        frame_corners: u64,
        progress: &dyn Progress,
    ) -> Result<Self, Error> {
        opts.validate()?;
        // Models are held whole (their triangles and grids) when they
        // take a small part of the budget; else each pass reads those it
        // needs, one at a time, and the budget keeps room for the
        // largest. Either way they are out of what the phases share.
        let t_models = Instant::now();
        let each = Models::estimate_each(db);
        let all: u64 = each.iter().sum();
        let largest = each.iter().copied().max().unwrap_or(0);
        let holding = match bf.models {
            _ if each.is_empty() => ModelHolding::Held,
            ModelHolding::Auto if all <= bf.memory / 4 => ModelHolding::Held,
            ModelHolding::Auto => ModelHolding::PerPass,
            h => h,
        };
        // Refused before reading when they clearly cannot fit (the
        // estimate errs high, up to 1.6 times on the dragon); else the
        // budget's plan says, with the bytes they take.
        let need = if holding == ModelHolding::Held {
            all
        } else {
            largest
        };
        if need > 2 * bf.memory {
            return Err(Error::Invalid(format!(
                "the scene's {} about {} in memory, more than the budget of {}; \
                 a model is held whole while it is tested (raise --memory, or convert \
                 the scene with --flatten-instances: copies are streamed like any object)",
                if holding == ModelHolding::Held {
                    "models need"
                } else {
                    "largest model needs"
                },
                crate::units::fmt_bytes(need),
                crate::units::fmt_bytes(bf.memory)
            )));
        }
        let threads = if opts.threads == 0 {
            crate::sys::cpus()
        } else {
            opts.threads
        };
        let (models, models_bytes) = match holding {
            ModelHolding::PerPass => {
                let m = Models::open(db, threads, opts.aggregates.depth_first())?;
                let b = m.bytes() + largest;
                (m, b)
            }
            _ => {
                let m = Models::load(db, threads, opts.aggregates.depth_first(), progress)?;
                let b = m.bytes();
                (m, b)
            }
        };
        let models_seconds = t_models.elapsed().as_secs_f64();
        let (specs, partition) = super::plan_grids(db, opts, bf.memory);
        if specs.len() > MAX_GRIDS {
            return Err(Error::Invalid(format!(
                "{} grids are more than the breadth-first tracer takes ({MAX_GRIDS}); render with --grids 1",
                specs.len()
            )));
        }
        // The voxel flags, a pass's coarse cells (four bytes per 64
        // voxels), the busy blocks (a bit per 64 voxels), the registered
        // voxels (a bit each), per block its voxel boxes (one per grid) and its
        // place in the file (which let passes skip it), and a bit per group
        // of objects.
        let voxels: u64 = specs.iter().map(|s| s.cells() as u64).sum();
        let cells = voxels
            + voxels / 16
            + specs
                .iter()
                .map(|s| 8 * (s.cells() as u64).div_ceil(64))
                .sum::<u64>()
            + specs
                .iter()
                .map(super::voxels::BusyBlocks::bytes_for)
                .sum::<u64>()
            + specs.len() as u64 * 4096
            + db.block_count()
                * (16 + specs.len() as u64 * std::mem::size_of::<super::skip::CellBox>() as u64)
            // Which groups of objects are aggregates: a bit each.
            + 8 * super::voxels::VoxelGrids::aggregate_words(db.object_count()) as u64;
        let store = StorePlan::new(bf.store, &specs);
        // Textures: held, or read through a cache, within the budget.
        let eps = epsilon(&db.bbox(), opts.precision);
        let (mut shade_scene, texture_bytes) =
            ShadeScene::open(db, opts.max_depth, eps, bf.memory)?;
        shade_scene.footprint = Some(crate::render::Footprint::of(
            &db.scene().view,
            opts.width,
            opts.height,
        ));
        // A reader thread needs a core beside the shards' and a few block
        // buffers: worth it when they are a small part of the budget.
        let read_ahead = if threads > 1 {
            crate::sdb::read_ahead_batch(db, bf.memory / READ_AHEAD_SHARE)
        } else {
            0
        };
        let budget = Budget::plan::<R>(
            bf.memory,
            super::FramePlan::new(frame_corners, bf.memory).bytes(frame_corners),
            cells,
            models_bytes + texture_bytes,
            db.scan_buffer_bytes() as u64
                + if read_ahead > 0 {
                    crate::sdb::read_ahead_bytes(db, read_ahead)
                } else {
                    0
                },
            &store,
            threads,
        )?;
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .map_err(|e| Error::Invalid(format!("cannot start threads: {e}")))?;
        let spill = SpillDir::new(bf.spill_dir.as_deref())?;
        let mut models = models;
        models.set_cutouts(crate::render::Cutouts::new(
            &models.material_table(&db.scene().materials),
            shade_scene.textures.clone(),
        ));

        let isa = Isa::choose(opts.simd)?;
        let t0 = Instant::now();
        progress.set_message("preprocess: marking voxels");
        let slack = crate::grid::box_slack(&db.scene().view.from, &specs);
        // The paper's passes test objects one by one.
        let aggregates = opts.aggregates.breadth_first() && !db.full_scans();
        let work = super::voxels::BuildThreads {
            pool: (threads > 1).then_some(&pool),
            read_ahead,
        };
        let (grids, pre) = VoxelGrids::build(db, specs, partition, aggregates, work, progress)?;
        let preprocess_seconds = models_seconds + t0.elapsed().as_secs_f64();
        let stats = BfStats {
            memory_budget_bytes: bf.memory,
            db_scans: 1,
            db_bytes_read: pre.bytes_read,
            store_number: match bf.store {
                super::StoreNumber::Fixed(n) => n.to_string(),
                super::StoreNumber::Adaptive => "adaptive".into(),
                super::StoreNumber::Budget => "budget".into(),
            },
            budget: Some(budget.clone()),
            models: (!models.is_empty()).then_some(holding),
            ..Default::default()
        };
        Ok(Tracer {
            db,
            grids,
            store,
            budget,
            pool,
            threads,
            spill,
            eps,
            slack,
            shading: bf.shading,
            shade_scene,
            materials: models.material_table(&db.scene().materials),
            models,
            slots: Slots::new(threads),
            regs_per_ray: f64::INFINITY,
            voxels_per_reg: 1.0,
            dense_buf: Vec::new(),
            spare_rays: Vec::new(),
            set_buf: Vec::new(),
            carried_buf: Vec::new(),
            shade_outputs: Vec::new(),
            chunk_outs: Vec::new(),
            radix: Default::default(),
            stats,
            tests: KindCounts::default(),
            preprocess_seconds,
            intersect_seconds: 0.0,
            read_ahead,
            isa,
            aggregates,
            shade_seconds: 0.0,
        })
    }

    /// The instruction set of the intersection kernels.
    pub fn isa(&self) -> Isa {
        self.isa
    }

    pub fn grid_stats(&self) -> Vec<crate::grid::GridStat> {
        self.grids.stats()
    }

    /// Intersects the `n` rays of `rays`, whose ids in the round are
    /// `first, first + 1, ...`; returns their results in that order, with
    /// those ids. `rays_resident` says whether the caller keeps the rays in
    /// memory meanwhile (which leaves less for the slots).
    pub fn intersect(
        &mut self,
        first: u64,
        rays: RaySource<'_>,
        n: u64,
        rays_resident: bool,
        progress: &dyn Progress,
    ) -> Result<(ResultReader, IntersectStats), Error> {
        let ti = Instant::now();
        let budget = &self.budget;
        let resident = budget.results_resident(n);
        let mut results = if resident {
            let mut v = std::mem::take(&mut self.dense_buf);
            v.clear();
            // Written (and so first touched, page by page) by every thread,
            // in place: a usize range is an indexed parallel iterator (a
            // u64 range is not, and would be collected in pieces first).
            self.pool.install(|| {
                use rayon::prelude::*;
                v.par_extend(
                    (0..n as usize)
                        .into_par_iter()
                        .map(|i| miss(first + i as u64)),
                );
            });
            Results::Dense { first, v }
        } else {
            Results::Sort(ExternalSorter::new(
                &self.spill,
                "results",
                budget.result_sort_records() as usize,
                result_key as fn(&Outcome) -> u64,
            ))
        };
        // Planned for what a sample of these rays registers, or else for
        // what the last round's did.
        let sampled = match &rays {
            RaySource::Indexed { len, ray } => super::intersect::sample_registrations::<R>(
                *len,
                *ray,
                &self.grids,
                &self.store,
                self.eps,
            ),
            RaySource::Stream(_) => None,
        };
        let regs_per_ray = sampled.map_or(self.regs_per_ray, |(m, _)| REGS_MARGIN * m);
        let voxels_per_reg = sampled.map_or(1.0, |(_, v)| v).min(self.voxels_per_reg);
        let streamed = !(matches!(rays, RaySource::Indexed { .. }) && resident);
        let dense_cells = budget.dense_cells(self.threads);
        let dense_index = self
            .grids
            .grids
            .iter()
            .any(|g| g.spec.cells() <= dense_cells);
        let (mut slots_n, mut registration_bytes) = budget.slots(
            rays_resident,
            resident,
            regs_per_ray,
            voxels_per_reg,
            streamed,
            dense_index,
        );
        if self.db.decoded_bytes() < CHEAP_SCAN_BYTES && slots_n > CACHE_SLOTS {
            // A pass over a small database costs little; a smaller ray set
            // keeps the scan's ray accesses in cache.
            registration_bytes = registration_bytes * CACHE_SLOTS / slots_n;
            slots_n = CACHE_SLOTS;
        }
        let mut setup = IntersectSetup {
            db: self.db,
            models: &self.models,
            models_per_pass: !self.models.all_held(),
            pairs_cap: (budget.total / 64).max(16 << 10) as usize,
            grids: &mut self.grids,
            store: self.store,
            slots: slots_n as usize,
            registration_bytes: registration_bytes as usize,
            dense_cells,
            carry: self.shading == super::Shading::Carry,
            read_ahead: self.read_ahead,
            isa: self.isa,
            eps: self.eps,
            aggregates: self.aggregates,
            slack: self.slack,
        };
        let ist = {
            let mut emit_sorted;
            let sink = match &mut results {
                Results::Dense { first, v } => ResultSink::Dense {
                    v: &mut v[..],
                    first: *first,
                },
                Results::Sort(sorter) => {
                    emit_sorted = move |mut r: Outcome| {
                        if r.res.prim.is_none() {
                            return Ok(()); // a miss: reported without being stored
                        }
                        r.res.ray += first;
                        sorter.push(r)
                    };
                    ResultSink::Each(&mut emit_sorted)
                }
            };
            intersect_rays::<R>(
                &mut setup,
                &self.pool,
                &mut self.slots,
                rays,
                n,
                sink,
                progress,
            )?
        };
        let st = &mut self.stats;
        st.passes.push(ist.passes);
        st.slots_per_round.push(slots_n.min(n).max(1));
        st.remaining_rays_per_pass
            .push(ist.remaining_rays_per_pass.clone());
        st.store_numbers.push(ist.store_numbers.clone());
        st.db_scans += ist.db_scans;
        st.db_bytes_read += ist.db_bytes_read;
        st.db_blocks_skipped += ist.db_blocks_skipped;
        st.model_reads += ist.model_reads;
        st.ray_voxel_registrations += ist.registrations;
        if ist.registered_rays > 0 {
            // The next round's rays are planned for what these made, with
            // a margin (a round's rays are much alike: eye rays, then
            // their shadow rays and reflections).
            self.regs_per_ray = REGS_MARGIN * ist.registrations as f64 / ist.registered_rays as f64;
            self.voxels_per_reg = (VOXELS_MARGIN * ist.registered_voxels as f64
                / ist.registrations.max(1) as f64)
                .min(1.0);
        }
        st.tests_skipped_last_voxel += ist.tests_skipped_last_voxel;
        st.tests_skipped_mailbox += ist.tests_skipped_mailbox;
        st.aggregate_walks += ist.aggregate_walks;
        self.tests += ist.intersection_tests;
        // The phases take turns with the budget: shading gets the slots'
        // share, unless they are small beside the budget (then keeping them
        // saves page faults in the next round).
        if self.slots.bytes() as u64 > self.budget.idle_allowance() {
            self.slots.release();
        }
        let reader = match results {
            Results::Dense { v, .. } => ResultReader::Dense { v, next: 0 },
            Results::Sort(s) => ResultReader::Sparse {
                hits: Box::new(s.finish()?),
                pending: None,
                next: first,
                end: first + n,
            },
        };
        self.intersect_seconds += ti.elapsed().as_secs_f64();
        Ok((reader, ist))
    }

    /// Gives back every buffer kept for reuse from call to call, keeping
    /// the grids: an idle tracer then holds its grids and little else (a
    /// cluster worker keeps idle tracers of other jobs beside a busy one).
    pub fn trim(&mut self) {
        self.slots.release();
        self.dense_buf = Vec::new();
        self.spare_rays = Vec::new();
        self.set_buf = Vec::new();
        self.carried_buf = Vec::new();
        self.shade_outputs = Vec::new();
        self.chunk_outs = Vec::new();
        self.radix = Default::default();
    }

    /// Results in ray order, one per ray, read from `outcomes` into the
    /// reusable result buffer (see [`Tracer::recycle`]).
    pub fn dense_results(&mut self, outcomes: impl Iterator<Item = Outcome>) -> ResultReader {
        let mut v = std::mem::take(&mut self.dense_buf);
        v.clear();
        v.extend(outcomes);
        ResultReader::Dense { v, next: 0 }
    }

    /// Hands a dense result buffer back for reuse.
    pub fn recycle(&mut self, results: ResultReader) {
        if let ResultReader::Dense { mut v, .. } = results {
            v.clear();
            if v.capacity() > self.dense_buf.capacity() {
                self.dense_buf = v;
            }
        }
    }

    /// Hands a round's ray buffer back for reuse by the next sort.
    pub fn recycle_rays(&mut self, mut rays: Vec<RayRec>) {
        rays.clear();
        if rays.capacity() > self.spare_rays.capacity() {
            self.spare_rays = rays;
        }
    }

    /// Shades the rays of `rays` (ids `first, first + 1, ...`) with
    /// their `results` in the same order: colour contributions go to
    /// `contribute` (pixel corner, fixed-point colour), the rays they spawn
    /// come back sorted by key, with their number.
    pub fn shade(
        &mut self,
        first: u64,
        rays: RaySource<'_>,
        results: &mut ResultReader,
        contribute: &mut dyn FnMut(u32, [i64; 3]),
        counts: &mut RayCounts,
    ) -> Result<(SortedRays, u64, ShadeStats), Error> {
        let ts = Instant::now();
        let mut next: NextRays = ExternalSorter::with_buffer(
            &self.spill,
            "rays",
            self.budget.next_ray_sort_records as usize,
            ray_key as fn(&RayRec) -> u64,
            std::mem::take(&mut self.spare_rays),
        );
        let mut setup = ShadeSetup {
            db: self.db,
            models: &self.models,
            set: &mut self.set_buf,
            carried: &mut self.carried_buf,
            outputs: &mut self.shade_outputs,
            radix: &mut self.radix,
            materials: &self.materials,
            shade: &self.shade_scene,
            set_cap: self.budget.shading_set_hits(self.shade_scene.lights.len()),
        };
        let sst = match (rays, results) {
            (RaySource::Indexed { len, ray: ray_at }, ResultReader::Dense { v, next: at }) => {
                let rest = &v[(*at).min(v.len())..];
                if rest.len() as u64 != len {
                    return Err(Error::Invalid(format!(
                        "{} intersection results for {len} rays",
                        rest.len()
                    )));
                }
                *at = v.len();
                shade_indexed(
                    &mut setup,
                    &self.pool,
                    first,
                    ray_at,
                    rest,
                    &mut self.chunk_outs,
                    contribute,
                    &mut next,
                    counts,
                )?
            }
            (rays, results) => {
                let mut stream_of_indexed;
                let rays: &mut dyn Iterator<Item = Result<RayRec, Error>> = match rays {
                    RaySource::Stream(it) => it,
                    RaySource::Indexed { len, ray: f } => {
                        stream_of_indexed = (0..len).map(move |i| Ok(f(i)));
                        &mut stream_of_indexed
                    }
                };
                let mut next_result = || results.next_outcome();
                shade_round(
                    &mut setup,
                    &self.pool,
                    first,
                    rays,
                    &mut next_result,
                    contribute,
                    &mut next,
                    counts,
                )?
            }
        };
        if let Some(e) = self.shade_scene.texture_error() {
            return Err(e);
        }
        self.stats.db_scans += sst.db_scans;
        self.stats.db_bytes_read += sst.db_bytes_read;
        self.stats.db_blocks_skipped += sst.db_blocks_skipped;
        self.stats.model_reads += sst.model_reads;
        // The hit set and its outputs are the shading phase's; the next
        // intersection gets their share back (unless they are small).
        let held = self.set_buf.capacity() * std::mem::size_of::<super::records::HitRec>()
            + self.carried_buf.capacity() * std::mem::size_of::<super::shade::Carried>()
            + self
                .shade_outputs
                .iter()
                .map(|o| o.rays.capacity() * std::mem::size_of::<RayRec>())
                .sum::<usize>()
            + self.chunk_outs.iter().map(ChunkOut::bytes).sum::<usize>()
            + self.radix.bytes();
        if held as u64 > self.budget.idle_allowance() {
            self.set_buf = Vec::new();
            self.carried_buf = Vec::new();
            self.shade_outputs = Vec::new();
            self.chunk_outs = Vec::new();
            self.radix = Default::default();
        }
        let count = next.len();
        let sorted = next.finish()?;
        self.shade_seconds += ts.elapsed().as_secs_f64();
        Ok((sorted, count, sst))
    }

    /// Keeps sorted rays in memory if the budget allows, else writes them
    /// to a file.
    pub fn hold_rays(&mut self, sorted: SortedRays, count: u64) -> Result<HeldRays, Error> {
        let t = Instant::now();
        let held = match sorted.into_vec() {
            Ok(v) if self.budget.rays_resident(count) => HeldRays::Memory(v),
            Ok(v) => {
                let mut w = RecordWriter::<RayRec>::create(&self.spill, "round")?;
                w.extend(&v)?;
                self.recycle_rays(v);
                HeldRays::File(w.finish()?)
            }
            Err(mut sorted) => {
                let mut w = RecordWriter::<RayRec>::create(&self.spill, "round")?;
                while let Some(r) = sorted.next()? {
                    w.push(&r)?;
                }
                HeldRays::File(w.finish()?)
            }
        };
        self.shade_seconds += t.elapsed().as_secs_f64();
        Ok(held)
    }

    /// The statistics so far, with the spill total brought up to date.
    pub fn finish_stats(&mut self) -> BfStats {
        self.stats.spill_bytes_written = self.spill.bytes_written();
        self.stats.textures = self.shade_scene.tile_reads();
        self.stats.clone()
    }
}

/// A round's rays between stages.
pub enum HeldRays {
    Memory(Vec<RayRec>),
    File(RecordFile<RayRec>),
}
