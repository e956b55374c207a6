//! Tracing ray trees a packet at a time: the eye rays of a small block of
//! frame slots find their hits together, and so, level by level, do the
//! rays they spawn (the shadow rays toward each light, the reflected and
//! the refracted rays). Each ray finds exactly the hit it would find
//! alone (see [`super::packet`]); colours are summed in fixed point, so
//! the order in which a slot's contributions arrive does not matter.

use super::DfScene;
use super::lanes::{LANES, LaneTests, Mask, PACKET_SIDE, Rays, lanes};
use super::packet::{self, Hits, Plan};
use super::single;
use crate::error::Error;
use crate::intersect::RayQ;
use crate::math::{Real, Vec3};
use crate::progress::Progress;
use crate::render::{
    EyeRays, Frame, KindCounts, Precision, RayCounts, RenderOptions, Spawn, shade, to_fixed,
};
use rayon::prelude::*;

/// Rows of frame slots per task: packets are square blocks of slots, so a
/// task takes a band of rows.
const BAND: usize = PACKET_SIDE;

/// A shadow ray waiting for its light's packet.
#[derive(Clone, Copy, Debug)]
struct ShadowRay {
    light: u32,
    lane: u16,
    dir: Vec3,
    dist: f64,
    color: [f32; 3],
}

/// What tracing one packet at one depth of the ray tree needs besides the
/// packet: its shadow rays, and the packets of rays it spawns. Kept per
/// depth, so that tracing allocates nothing.
struct Level<R> {
    /// The shadow rays of the packet's hits, lane by lane, each lane's in
    /// the order of the lights.
    shadows: Vec<ShadowRay>,
    toward_light: Rays<R>,
    reflect: Rays<R>,
    refract: Rays<R>,
    reflect_carry: Carry,
    refract_carry: Carry,
}

impl<R: Real> Level<R> {
    fn new(lights: usize) -> Box<Level<R>> {
        Box::new(Level {
            shadows: Vec::with_capacity(LANES * lights),
            toward_light: Rays::new(),
            reflect: Rays::new(),
            refract: Rays::new(),
            reflect_carry: Carry::EMPTY,
            refract_carry: Carry::EMPTY,
        })
    }
}

/// Per-thread state: the mailbox (the last query that tested each object),
/// the shadow cache, buffers, and counters.
pub struct Scratch<R = f64> {
    pub mail: Vec<u32>,
    stamp: u32,
    /// Last blocker found per (light, depth): tested first by the next
    /// shadow rays toward that light from that depth (Haines' shadow
    /// cache). Cleared at the start of every band, so what a band does
    /// never depends on which bands the same thread did before: counts are
    /// the same for any number of threads.
    pub shadow_cache: Vec<u32>,
    /// One level's buffers per depth (taken while that depth is traced).
    levels: Vec<Option<Box<Level<R>>>>,
    pub tests: KindCounts,
    pub rays: RayCounts,
    /// With profiling: nanoseconds spent finding hits and blockers.
    profile: bool,
    intersect_ns: u64,
}

pub const NO_OBJECT: u32 = u32::MAX;

impl<R: Real> Scratch<R> {
    fn new(objects: usize, lights: usize, max_depth: usize) -> Scratch<R> {
        Scratch {
            mail: vec![0; objects],
            stamp: 0,
            shadow_cache: vec![NO_OBJECT; lights * max_depth],
            levels: (0..=max_depth).map(|_| Some(Level::new(lights))).collect(),
            tests: KindCounts::default(),
            rays: RayCounts::default(),
            profile: false,
            intersect_ns: 0,
        }
    }

    /// A stamp no object's mailbox holds.
    #[inline]
    /// Makes sure the next `n` stamps are taken without the counter
    /// wrapping: a query that holds one stamp while it takes others (a
    /// packet walking some grids lane by lane) must not see the mailboxes
    /// cleared and its own stamp come round again.
    pub fn reserve_stamps(&mut self, n: u32) {
        if self.stamp > u32::MAX - n {
            self.mail.fill(0);
            self.stamp = 0;
        }
    }

    pub fn next_stamp(&mut self) -> u32 {
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
    let mut frame = Frame::with_sampling(cam.width, cam.height, eye.sampling);
    let row_len = frame.row_len();
    let rows = frame.slots.len() / row_len;
    let lights = scene.shade.lights.len();
    let max_depth = scene.shade.max_depth as usize;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(thread_count(opts))
        .build()
        .map_err(|e| Error::Invalid(format!("cannot start threads: {e}")))?;
    progress.set_total(rows as u64);
    progress.set_message("tracing");
    let per_band: Vec<(RayCounts, KindCounts, u64)> = pool.install(|| {
        frame
            .slots
            .par_chunks_mut(row_len * BAND)
            .enumerate()
            .map_init(
                || {
                    let mut sc = Scratch::<R>::new(scene.len(), lights, max_depth);
                    sc.profile = opts.profile;
                    sc
                },
                |sc, (band, out)| {
                    sc.shadow_cache.fill(NO_OBJECT);
                    trace_band::<R>(scene, sc, &eye, band * BAND * row_len, row_len, out);
                    progress.inc((out.len() / row_len) as u64);
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
    for (r, t, n) in per_band {
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

/// Where a packet's rays send their colour: the frame slot (within the
/// band) and the weight of each lane.
#[derive(Clone, Copy)]
struct Carry {
    slot: [u32; LANES],
    weight: [f32; LANES],
}

impl Carry {
    const EMPTY: Carry = Carry {
        slot: [0; LANES],
        weight: [0.0; LANES],
    };
}

/// Traces the eye rays of a band of slot rows starting at slot `first`,
/// in packets of square blocks of slots.
fn trace_band<R: Real>(
    s: &DfScene,
    sc: &mut Scratch<R>,
    eye: &EyeRays,
    first: usize,
    row_len: usize,
    out: &mut [[i64; 3]],
) {
    let spp = eye.sampling.per_slot() as usize;
    // Blocks of side x side slots, of at most LANES rays when they fit.
    let mut side = s.tune.eye_side;
    while side > 1 && side * side * spp > LANES {
        side /= 2;
    }
    let rows = out.len() / row_len;
    let origin = eye.camera.eye;
    let mut rays = Rays::<R>::new();
    let mut carry = Carry::EMPTY;
    for by in (0..rows).step_by(side) {
        for bx in (0..row_len).step_by(side) {
            for y in by..(by + side).min(rows) {
                for x in bx..(bx + side).min(row_len) {
                    let slot = y * row_len + x;
                    let i0 = ((first + slot) * spp) as u64;
                    for i in i0..i0 + spp as u64 {
                        let (d, _) = eye.ray(i);
                        let lane = rays.push(origin, d, 0.0, f64::INFINITY);
                        carry.slot[lane] = slot as u32;
                        carry.weight[lane] = 1.0;
                        if rays.n == LANES {
                            sc.rays.eye_rays += rays.n as u64;
                            rays.pad();
                            trace_packet(s, sc, &rays, &carry, 1, Some(origin), out);
                            rays.n = 0;
                        }
                    }
                }
            }
            if rays.n > 0 {
                sc.rays.eye_rays += rays.n as u64;
                rays.pad();
                trace_packet(s, sc, &rays, &carry, 1, Some(origin), out);
                rays.n = 0;
            }
        }
    }
}

#[inline]
fn add(out: &mut [[i64; 3]], slot: u32, c: [f32; 3]) {
    let f = to_fixed(c);
    let acc = &mut out[slot as usize];
    for k in 0..3 {
        acc[k] = acc[k].saturating_add(f[k]);
    }
}

/// Follows a packet of rays of tree depth `depth` (eye rays: 1) and
/// everything they spawn, adding colour to `out`. `reference` is a point
/// the rays' lines pass through (the eye), if there is one.
fn trace_packet<R: Real>(
    s: &DfScene,
    sc: &mut Scratch<R>,
    rays: &Rays<R>,
    carry: &Carry,
    depth: u8,
    reference: Option<Vec3>,
    out: &mut [[i64; 3]],
) {
    let t0 = sc.profile.then(std::time::Instant::now);
    let mut best = Hits::<R>::new();
    nearest_all(s, sc, rays, reference, &mut best);
    if let Some(t0) = t0 {
        sc.intersect_ns += t0.elapsed().as_nanos() as u64;
    }
    let eps = s.shade.eps;
    let mut lv = sc.levels[depth as usize]
        .take()
        .expect("one packet per depth at a time");
    let Level {
        shadows,
        toward_light,
        reflect,
        refract,
        reflect_carry,
        refract_carry,
    } = &mut *lv;
    shadows.clear();
    reflect.n = 0;
    refract.n = 0;
    let mut points = [Vec3::ZERO; LANES];
    // Where each lane's shadow rays end in `shadows`.
    let mut ends = [0u32; LANES];
    for i in 0..rays.n {
        let (slot, weight) = (carry.slot[i], carry.weight[i]);
        let (o, d) = (rays.o(i), rays.d(i));
        let hit = best.hit(i);
        if let Some((surf, mat)) = hit
            .is_some()
            .then(|| s.surface_of(hit.prim, &RayQ::from_vec3(o, d), hit.t))
            .flatten()
        {
            if depth == 1 {
                sc.rays.eye_hit_rays += 1;
            }
            points[i] = surf.p;
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
                        shadows.push(ShadowRay {
                            light,
                            lane: i as u16,
                            dir,
                            dist,
                            color,
                        });
                    }
                    Spawn::Reflect { dir, weight } => {
                        sc.rays.reflect_rays += 1;
                        let j = reflect.push(surf.p, dir, eps, f64::INFINITY);
                        reflect_carry.slot[j] = slot;
                        reflect_carry.weight[j] = weight;
                    }
                    Spawn::Refract { dir, weight } => {
                        sc.rays.refract_rays += 1;
                        let j = refract.push(surf.p, dir, eps, f64::INFINITY);
                        refract_carry.slot[j] = slot;
                        refract_carry.weight[j] = weight;
                    }
                },
            );
        } else {
            add(out, slot, s.shade.background(weight));
        }
        ends[i] = shadows.len() as u32;
    }
    // The shadow rays toward each light, as one packet: each lane's are
    // in the order of the lights, so the next light is the least of the
    // lanes' next ones.
    let max_depth = s.shade.max_depth as usize;
    let mut next = [0u32; LANES];
    if rays.n > 1 {
        next[1..rays.n].copy_from_slice(&ends[..rays.n - 1]);
    }
    let mut member = [0u32; LANES];
    loop {
        let mut light = u32::MAX;
        for i in 0..rays.n {
            if next[i] < ends[i] {
                light = light.min(shadows[next[i] as usize].light);
            }
        }
        if light == u32::MAX {
            break;
        }
        toward_light.n = 0;
        for i in 0..rays.n {
            if next[i] < ends[i] && shadows[next[i] as usize].light == light {
                let r = &shadows[next[i] as usize];
                let j = toward_light.push(points[i], r.dir, eps, r.dist);
                member[j] = next[i];
                next[i] += 1;
            }
        }
        toward_light.pad();
        let slot = light as usize * max_depth + depth as usize - 1;
        let t0 = sc.profile.then(std::time::Instant::now);
        let lit = occluded_all(s, sc, toward_light, slot, s.shade.lights[light as usize].0);
        if let Some(t0) = t0 {
            sc.intersect_ns += t0.elapsed().as_nanos() as u64;
        }
        for j in lanes(lit) {
            let r = &shadows[member[j] as usize];
            add(out, carry.slot[r.lane as usize], r.color);
        }
    }
    for (next, next_carry) in [
        (&mut *reflect, &*reflect_carry),
        (&mut *refract, &*refract_carry),
    ] {
        if next.n > 0 {
            next.pad();
            trace_packet(s, sc, next, next_carry, depth + 1, None, out);
        }
    }
    sc.levels[depth as usize] = Some(lv);
}

/// The mean of the origins of the lanes `m`.
fn mean_origin<R>(rays: &Rays<R>, m: Mask) -> Vec3 {
    let mut sum = Vec3::ZERO;
    for i in lanes(m) {
        sum += rays.o(i);
    }
    sum / m.count_ones() as f64
}

/// The nearest hit of every ray of the packet: walking together if they
/// are coherent enough, else one by one.
fn nearest_all<R: Real>(
    s: &DfScene,
    sc: &mut Scratch<R>,
    rays: &Rays<R>,
    reference: Option<Vec3>,
    best: &mut Hits<R>,
) {
    let all = rays.all();
    let mut rest = all;
    let min_packet = s.tune.min_packet;
    if rays.n as u32 >= min_packet && (reference.is_some() || s.tune.spawn_packets) {
        let whole = reference.unwrap_or_else(|| mean_origin(rays, all));
        if let Some(plan) = Plan::new(s, rays, all, whole) {
            packet::nearest(s, sc, rays, all, &plan, best);
            return;
        }
        for m in octants(rays, all) {
            if m != all && m.count_ones() >= min_packet {
                let at = reference.unwrap_or_else(|| mean_origin(rays, m));
                if let Some(plan) = Plan::new(s, rays, m, at) {
                    packet::nearest(s, sc, rays, m, &plan, best);
                    rest &= !m;
                }
            }
        }
    }
    for i in lanes(rest) {
        single::nearest(
            s,
            sc,
            &rays.q[i],
            rays.o(i),
            rays.d(i),
            rays.inv(i),
            rays.t_min[i],
            best,
            i,
        );
    }
}

/// The lanes of `m` in each octant of directions: a packet that is not
/// coherent as a whole may be in parts.
fn octants<R>(rays: &Rays<R>, m: Mask) -> [Mask; 8] {
    let mut octants = [0 as Mask; 8];
    for i in lanes(m) {
        let o = (rays.d[0][i] < 0.0) as usize
            | ((rays.d[1][i] < 0.0) as usize) << 1
            | ((rays.d[2][i] < 0.0) as usize) << 2;
        octants[o] |= 1 << i;
    }
    octants
}

/// The lanes of a packet of shadow rays toward the light at `light` that
/// nothing blocks; `slot` is their shadow cache slot. The cached blocker
/// is tried on every lane first; if it blocks most of them the cache is
/// doing the work, and the rest go one by one (each updating the cache as
/// it finds a blocker), else they walk together where they can.
fn occluded_all<R: Real>(
    s: &DfScene,
    sc: &mut Scratch<R>,
    rays: &Rays<R>,
    slot: usize,
    light: Vec3,
) -> Mask {
    let all = rays.all();
    let cached = sc.shadow_cache[slot];
    let mut open = all;
    if cached != NO_OBJECT {
        LaneTests::new(s, s.candidate(cached), cached).blocks(rays, &mut open, &mut sc.tests);
    }
    let mut lit = open;
    let mut rest = open;
    let min_packet = s.tune.min_packet;
    let cache_works = 2 * open.count_ones() < all.count_ones();
    if open.count_ones() >= min_packet && s.tune.shadow_packets && !cache_works {
        let split = octants(rays, open).into_iter().filter(|&m| m != open);
        for m in std::iter::once(open).chain(split) {
            if m.count_ones() < min_packet {
                continue;
            }
            let Some(plan) = Plan::new(s, rays, m, light) else {
                continue;
            };
            let mut unblocked = m;
            let mut last = NO_OBJECT;
            packet::occluded(s, sc, rays, &mut unblocked, &plan, cached, &mut last);
            if last != NO_OBJECT {
                sc.shadow_cache[slot] = last;
            }
            lit &= !(m & !unblocked);
            rest &= !m;
            if rest == 0 {
                break;
            }
        }
    }
    for i in lanes(rest) {
        if single::occluded(
            s,
            sc,
            slot,
            &rays.q[i],
            rays.o(i),
            rays.d(i),
            rays.inv(i),
            rays.t_min[i],
            rays.t_max[i],
            cached,
        ) {
            lit &= !(1 << i);
        }
    }
    lit
}
