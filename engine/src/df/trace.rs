//! Tracing ray trees, one corner row per task.

use super::DfScene;
use crate::error::Error;
use crate::grid::Dda;
use crate::hit::{Hit, PrimId};
use crate::intersect::RayQ;
use crate::math::{Real, Vec3, Vec3Ext};
use crate::progress::Progress;
use crate::render::{
    EyeRays, Frame, KindCounts, Precision, RayCounts, RenderOptions, Spawn, shade, to_fixed,
};
use rayon::prelude::*;

/// Per-thread state: the mailbox (the last ray that tested each object),
/// the shadow cache, and counters.
struct Scratch {
    mail: Vec<u32>,
    stamp: u32,
    /// Last blocker found per (light, depth): tested first by the next
    /// shadow ray toward that light from that depth (Haines' shadow cache).
    /// Cleared at the start of every row, so what a row does never depends
    /// on which rows the same thread did before: counts are the same for
    /// any number of threads.
    shadow_cache: Vec<u32>,
    tests: KindCounts,
    rays: RayCounts,
    /// With profiling: nanoseconds spent finding hits and blockers.
    profile: bool,
    intersect_ns: u64,
}

const NO_OBJECT: u32 = u32::MAX;

impl Scratch {
    fn new(objects: usize, cache_slots: usize) -> Scratch {
        Scratch {
            mail: vec![0; objects],
            stamp: 0,
            shadow_cache: vec![NO_OBJECT; cache_slots],
            tests: KindCounts::default(),
            rays: RayCounts::default(),
            profile: false,
            intersect_ns: 0,
        }
    }

    /// A stamp no object's mailbox holds.
    #[inline]
    fn next_stamp(&mut self) -> u32 {
        if self.stamp == u32::MAX {
            self.mail.fill(0);
            self.stamp = 0;
        }
        self.stamp += 1;
        self.stamp
    }
}

pub fn thread_count(opts: &RenderOptions) -> usize {
    if opts.threads == 0 {
        crate::sys::cpus()
    } else {
        opts.threads
    }
}

pub fn render(
    scene: &DfScene,
    opts: &RenderOptions,
    progress: &dyn Progress,
) -> Result<(Frame, RayCounts, KindCounts, f64), Error> {
    match opts.precision {
        Precision::Double => render_in::<f64>(scene, opts, progress),
        Precision::Single => render_in::<f32>(scene, opts, progress),
    }
}

fn render_in<R: Real>(
    scene: &DfScene,
    opts: &RenderOptions,
    progress: &dyn Progress,
) -> Result<(Frame, RayCounts, KindCounts, f64), Error> {
    let cam = &scene.camera;
    let eye = EyeRays {
        camera: *cam,
        sampling: opts.sampling(),
    };
    let spp = eye.sampling.per_slot() as u64;
    let mut frame = Frame::with_sampling(cam.width, cam.height, eye.sampling);
    let row_len = frame.row_len();
    let rows = frame.slots.len() / row_len;
    let cache_slots = scene.shade.lights.len() * scene.shade.max_depth as usize;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(thread_count(opts))
        .build()
        .map_err(|e| Error::Invalid(format!("cannot start threads: {e}")))?;
    progress.set_total(rows as u64);
    progress.set_message("tracing");
    let per_row: Vec<(RayCounts, KindCounts, u64)> = pool.install(|| {
        frame
            .slots
            .par_chunks_mut(row_len)
            .enumerate()
            .map_init(
                || {
                    let mut sc = Scratch::new(scene.shapes.len(), cache_slots);
                    sc.profile = opts.profile;
                    sc
                },
                |sc, (row, out)| {
                    sc.shadow_cache.fill(NO_OBJECT);
                    for (col, acc) in out.iter_mut().enumerate() {
                        let first = (row * row_len + col) as u64 * spp;
                        for i in first..first + spp {
                            let (d, _) = eye.ray(i);
                            sc.rays.eye_rays += 1;
                            let mut add = |c: [f32; 3]| {
                                let f = to_fixed(c);
                                for k in 0..3 {
                                    acc[k] = acc[k].saturating_add(f[k]);
                                }
                            };
                            trace::<R>(scene, sc, cam.eye, d, 0.0, 1, 1.0, &mut add);
                        }
                    }
                    progress.inc(1);
                    (
                        std::mem::take(&mut sc.rays),
                        std::mem::take(&mut sc.tests),
                        std::mem::take(&mut sc.intersect_ns),
                    )
                },
            )
            .collect()
    });
    let mut rays = RayCounts::default();
    let mut tests = KindCounts::default();
    let mut ns = 0;
    for (r, t, n) in per_row {
        rays += r;
        tests += t;
        ns += n;
    }
    Ok((
        frame,
        rays,
        tests,
        ns as f64 * 1e-9 / thread_count(opts) as f64,
    ))
}

/// 1/d per axis.
#[inline(always)]
fn recip(d: Vec3) -> Vec3 {
    Vec3::new(1.0 / d.x, 1.0 / d.y, 1.0 / d.z)
}

/// Follows one ray and everything it spawns, adding colour through `add`.
#[allow(clippy::too_many_arguments)]
fn trace<R: Real>(
    s: &DfScene,
    sc: &mut Scratch,
    o: Vec3,
    d: Vec3,
    t_min: f64,
    depth: u8,
    weight: f32,
    add: &mut impl FnMut([f32; 3]),
) {
    let t0 = sc.profile.then(std::time::Instant::now);
    let hit = nearest::<R>(s, sc, o, d, t_min);
    if let Some(t0) = t0 {
        sc.intersect_ns += t0.elapsed().as_nanos() as u64;
    }
    let Some((t, id)) = hit else {
        add(s.shade.background(weight));
        return;
    };
    let id = id as usize;
    if depth == 1 {
        sc.rays.eye_hit_rays += 1;
    }
    let surf = s.shapes[id].surface(&RayQ::from_vec3(o, d), t);
    let mat = &s.materials[s.material_of[id] as usize];
    let eps = s.shade.eps;
    let max_depth = s.shade.max_depth as usize;
    shade(
        &s.shade,
        d,
        depth,
        weight,
        &surf,
        mat,
        &mut |spawn| match spawn {
            Spawn::Shadow {
                light,
                dir,
                dist,
                color,
            } => {
                sc.rays.shadow_rays += 1;
                let slot = light as usize * max_depth + depth as usize - 1;
                let t0 = sc.profile.then(std::time::Instant::now);
                let blocked = occluded::<R>(s, sc, slot, surf.p, dir, eps, dist);
                if let Some(t0) = t0 {
                    sc.intersect_ns += t0.elapsed().as_nanos() as u64;
                }
                if !blocked {
                    add(color);
                }
            }
            Spawn::Reflect { dir, weight } => {
                sc.rays.reflect_rays += 1;
                trace::<R>(s, sc, surf.p, dir, eps, depth + 1, weight, add);
            }
            Spawn::Refract { dir, weight } => {
                sc.rays.refract_rays += 1;
                trace::<R>(s, sc, surf.p, dir, eps, depth + 1, weight, add);
            }
        },
    );
}

/// The best hit so far, and the bound a test must beat: just above the
/// best distance, so that an exact tie is seen and goes to the smaller id.
struct Best<R> {
    hit: Hit,
    upper: R,
}

/// The nearest hit beyond `t_min`: smallest distance, ties to the smaller
/// object id. Grids are walked voxel by voxel and left as soon as the best
/// hit lies before the current voxel's far side.
#[inline]
fn nearest<R: Real>(
    s: &DfScene,
    sc: &mut Scratch,
    o: Vec3,
    d: Vec3,
    t_min: f64,
) -> Option<(f64, u32)> {
    let inv = recip(d);
    let q = RayQ::<R>::with_inverse(o.cast(), d.cast(), inv.cast());
    let stamp = sc.next_stamp();
    let rmin = R::from_f64(t_min);
    let mut best = Best {
        hit: Hit::NONE,
        upper: R::INFINITY,
    };
    // The large objects' grid first: one ground polygon found early prunes
    // the walk through the main grid.
    for g in s.grids.iter().rev() {
        if g.single_cell() {
            // A one-voxel grid (a few large objects): no walk needed.
            for &id in g.cell(0) {
                test_nearest(s, sc, stamp, &q, rmin, id, &mut best);
            }
            continue;
        }
        let Some(mut w) = Dda::start(&g.spec, o, d, inv, t_min, best.hit.t.next_up()) else {
            continue;
        };
        loop {
            for &id in g.cell(w.index) {
                test_nearest(s, sc, stamp, &q, rmin, id, &mut best);
            }
            if (best.hit.is_some() && best.hit.t < w.t_exit()) || !w.advance() {
                break;
            }
        }
    }
    // Objects of the database are the only primitives here.
    best.hit.prim.object_index().map(|id| (best.hit.t, id))
}

/// Tests one candidate for the nearest hit, unless this ray tested it
/// already (mailbox).
#[inline(always)]
fn test_nearest<R: Real>(
    s: &DfScene,
    sc: &mut Scratch,
    stamp: u32,
    q: &RayQ<R>,
    rmin: R,
    id: u32,
    best: &mut Best<R>,
) {
    let m = &mut sc.mail[id as usize];
    if *m == stamp {
        return;
    }
    *m = stamp;
    let shape = &s.shapes[id as usize];
    sc.tests.add(shape.kind());
    if let Some(t) = shape.intersect(s.prep(id), &s.bboxes[id as usize], q, rmin, best.upper) {
        let t = t.to_f64();
        let prim = PrimId::object(id);
        if best.hit.loses_to(t, prim) {
            best.hit = Hit { t, prim };
            best.upper = R::from_f64(t).next_up();
        }
    }
}

/// Whether anything lies between `t_min` and `t_max` along the ray; tries
/// the cached blocker of `slot` first and stops at the first blocker.
#[allow(clippy::too_many_arguments)]
#[inline]
fn occluded<R: Real>(
    s: &DfScene,
    sc: &mut Scratch,
    slot: usize,
    o: Vec3,
    d: Vec3,
    t_min: f64,
    t_max: f64,
) -> bool {
    let inv = recip(d);
    let q = RayQ::<R>::with_inverse(o.cast(), d.cast(), inv.cast());
    let stamp = sc.next_stamp();
    let (rmin, rmax) = (R::from_f64(t_min), R::from_f64(t_max));
    let cached = sc.shadow_cache[slot];
    if cached != NO_OBJECT && blocks(s, sc, stamp, &q, rmin, rmax, cached) {
        return true;
    }
    for g in s.grids.iter().rev() {
        if g.single_cell() {
            for &id in g.cell(0) {
                if blocks(s, sc, stamp, &q, rmin, rmax, id) {
                    sc.shadow_cache[slot] = id;
                    return true;
                }
            }
            continue;
        }
        let Some(mut w) = Dda::start(&g.spec, o, d, inv, t_min, t_max) else {
            continue;
        };
        loop {
            for &id in g.cell(w.index) {
                if blocks(s, sc, stamp, &q, rmin, rmax, id) {
                    sc.shadow_cache[slot] = id;
                    return true;
                }
            }
            if !w.advance() {
                break;
            }
        }
    }
    false
}

/// Whether object `id` blocks the shadow ray, unless tested already.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn blocks<R: Real>(
    s: &DfScene,
    sc: &mut Scratch,
    stamp: u32,
    q: &RayQ<R>,
    rmin: R,
    rmax: R,
    id: u32,
) -> bool {
    let m = &mut sc.mail[id as usize];
    if *m == stamp {
        return false;
    }
    *m = stamp;
    let shape = &s.shapes[id as usize];
    sc.tests.add(shape.kind());
    shape
        .intersect(s.prep(id), &s.bboxes[id as usize], q, rmin, rmax)
        .is_some()
}
