//! Tracing ray trees a packet at a time: the eye rays of a small block of
//! frame slots find their hits together, and so, level by level, do the
//! rays they spawn (the shadow rays toward each light, the reflected and
//! the refracted rays). Each ray finds exactly the hit it would find
//! alone (see [`super::packet`]); colours are summed in fixed point, so
//! the order in which a slot's contributions arrive does not matter.

use super::DfScene;
use super::lanes::Found;
use super::walk::{self, Hits};
use crate::error::Error;
use crate::intersect::RayQ;
use crate::kernels::{BATCH, LANES, Lanes, RayLanes, TriangleBatch, each_lane};
use crate::math::Vec3;
use crate::progress::Progress;
use crate::render::{
    EyeRays, Frame, KindCounts, Precision, RayCounts, RenderOptions, Spawn, shade, to_fixed,
};
use crate::simd::{Elem, Isa};
use rayon::prelude::*;

/// Eye rays go in packets of PACKET_SIDE x PACKET_SIDE frame slots.
pub const PACKET_SIDE: usize = 8;

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
    toward_light: RayLanes<R>,
    reflect: RayLanes<R>,
    refract: RayLanes<R>,
    reflect_carry: Carry,
    refract_carry: Carry,
}

impl<R: Elem> Level<R> {
    fn new(lights: usize) -> Box<Level<R>> {
        Box::new(Level {
            shadows: Vec::with_capacity(LANES * lights),
            toward_light: RayLanes::new(),
            reflect: RayLanes::new(),
            refract: RayLanes::new(),
            reflect_carry: Carry::EMPTY,
            refract_carry: Carry::EMPTY,
        })
    }
}

/// Per-thread state: the mailbox, the shadow cache, buffers, and
/// counters.
pub struct Scratch<R = f64> {
    /// The kernels' instruction set.
    pub isa: Isa,
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
    /// What the last candidate's test found.
    pub found: Box<Found<R>>,
    /// Which lanes of the current walk tested which objects.
    pub mailbox: super::mailbox::Mailbox,
    /// A voxel's faces, their ids, the lanes that test each, and the
    /// distances a ray finds to them.
    pub batch: Box<TriangleBatch<R>>,
    pub batch_ids: [u32; BATCH],
    pub batch_lanes: [Lanes; BATCH],
    pub batch_t: [R; BATCH],
}

pub const NO_OBJECT: u32 = u32::MAX;

impl<R: Elem> Scratch<R> {
    fn new(isa: Isa, lights: usize, max_depth: usize) -> Scratch<R> {
        Scratch {
            isa,
            shadow_cache: vec![NO_OBJECT; lights * max_depth],
            levels: (0..=max_depth).map(|_| Some(Level::new(lights))).collect(),
            tests: KindCounts::default(),
            rays: RayCounts::default(),
            profile: false,
            intersect_ns: 0,
            found: Found::new(),
            mailbox: Default::default(),
            batch: TriangleBatch::new(),
            batch_ids: [0; BATCH],
            batch_lanes: [0; BATCH],
            batch_t: [R::ZERO; BATCH],
        }
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

fn render_in<R: Elem>(
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
    let isa = Isa::choose(opts.simd)?;
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
                    let mut sc = Scratch::<R>::new(isa, lights, max_depth);
                    sc.profile = opts.profile;
                    sc
                },
                |sc, (band, out)| {
                    // The frame is zero already, but its pages are not
                    // yet in memory: written first, each comes as a fresh
                    // page on this thread. Read first (a colour added),
                    // it would map the shared zero page, and the write
                    // after would copy it and flush the mapping from
                    // every other core's TLB: an interrupt to each, which
                    // on a virtual machine cost a second thread all it
                    // gained (the dragon's eye rays at 1024 x 1024 took
                    // as long on two threads as on one).
                    out.fill([0; 3]);
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
fn trace_band<R: Elem>(
    s: &DfScene,
    sc: &mut Scratch<R>,
    eye: &EyeRays,
    first: usize,
    row_len: usize,
    out: &mut [[i64; 3]],
) {
    let spp = eye.sampling.per_slot() as usize;
    // Blocks of side x side slots, of at most LANES rays when they fit.
    let mut side = PACKET_SIDE;
    while side > 1 && side * side * spp > LANES {
        side /= 2;
    }
    let rows = out.len() / row_len;
    // The band's first row of slots in the whole frame's slot grid.
    let row0 = (first / row_len) as u32;
    let mut packet = EyePacket {
        x: [0.0; LANES],
        y: [0.0; LANES],
        n: 0,
        carry: Carry::EMPTY,
        rays: RayLanes::<R>::new(),
    };
    for by in (0..rows).step_by(side) {
        for bx in (0..row_len).step_by(side) {
            // The block's slots in Z order, so that the lanes of any
            // aligned square of slots are neighbours: the rays that reach
            // a voxel or a block of the grid fill few vectors.
            debug_assert!(side * side <= 1 << 16);
            for k in 0..side * side {
                let (x, y) = (bx + even_bits(k), by + even_bits(k >> 1));
                if x >= row_len || y >= rows {
                    continue;
                }
                let slot = y * row_len + x;
                for i in 0..spp as u32 {
                    let j = packet.n;
                    (packet.x[j], packet.y[j]) = eye.point(x as u32, row0 + y as u32, i);
                    packet.carry.slot[j] = slot as u32;
                    packet.carry.weight[j] = 1.0;
                    packet.n += 1;
                    if packet.n == LANES {
                        packet.trace(s, sc, eye, out);
                    }
                }
            }
            if packet.n > 0 {
                packet.trace(s, sc, eye, out);
            }
        }
    }
}

/// Eye rays gathered for a packet: the image points they pass through
/// and where their colour goes.
struct EyePacket<R> {
    x: [f64; LANES],
    y: [f64; LANES],
    n: usize,
    carry: Carry,
    rays: RayLanes<R>,
}

impl<R: Elem> EyePacket<R> {
    /// Makes the rays through the points gathered (their directions all
    /// at once), traces them, and empties the packet.
    fn trace(&mut self, s: &DfScene, sc: &mut Scratch<R>, eye: &EyeRays, out: &mut [[i64; 3]]) {
        let mut d = [[0.0; LANES]; 3];
        eye.camera
            .directions_at(sc.isa, &self.x, &self.y, self.n, &mut d);
        let rays = &mut self.rays;
        rays.clear();
        for j in 0..self.n {
            let dir = Vec3::new(d[0][j], d[1][j], d[2][j]);
            rays.push(eye.camera.eye, dir, 0.0, f64::INFINITY);
        }
        rays.seal(sc.isa);
        sc.rays.eye_rays += self.n as u64;
        trace_packet(s, sc, rays, &self.carry, 1, out);
        self.n = 0;
    }
}

/// The even bits of `k` (below 2^16), packed: the x of Z-order index `k`
/// (and of `k >> 1`, its y).
#[inline]
fn even_bits(k: usize) -> usize {
    let mut x = k & 0x5555;
    x = (x | x >> 1) & 0x3333;
    x = (x | x >> 2) & 0x0f0f;
    (x | x >> 4) & 0x00ff
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
/// everything they spawn, adding colour to `out`.
fn trace_packet<R: Elem>(
    s: &DfScene,
    sc: &mut Scratch<R>,
    rays: &RayLanes<R>,
    carry: &Carry,
    depth: u8,
    out: &mut [[i64; 3]],
) {
    let t0 = sc.profile.then(std::time::Instant::now);
    let mut best = Hits::<R>::new(rays);
    // Eye rays leave one point through neighbouring pixels: they walk
    // together. The rays they spawn may not.
    let apart = depth > 1 && walk::diverge(s, rays, rays.all());
    walk::nearest(s, sc, rays, rays.all(), &mut best, apart);
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
    reflect.clear();
    refract.clear();
    let mut points = [Vec3::ZERO; LANES];
    // Where each lane's shadow rays end in `shadows`.
    let mut ends = [0u32; LANES];
    for i in 0..rays.n {
        let (slot, weight) = (carry.slot[i], carry.weight[i]);
        let (o, d) = (rays.o(i), rays.d(i));
        let hit = best.hit(i);
        // `RayQ::from_vec3(o, d)`, with the reciprocals the seal computed
        // in `f64` already.
        let q = || RayQ::with_inverse(o.into(), d.into(), rays.inv(i).into());
        if let Some((surf, mat)) = hit
            .is_some()
            .then(|| s.surface_of(hit.prim, &q(), hit.t))
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
                    Spawn::Emit { color } => add(out, slot, color),
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
        toward_light.clear();
        for i in 0..rays.n {
            if next[i] < ends[i] && shadows[next[i] as usize].light == light {
                let r = &shadows[next[i] as usize];
                let j = toward_light.push(points[i], r.dir, eps, r.dist);
                member[j] = next[i];
                next[i] += 1;
            }
        }
        toward_light.seal(sc.isa);
        let slot = light as usize * max_depth + depth as usize - 1;
        let t0 = sc.profile.then(std::time::Instant::now);
        let lit = occluded_all(s, sc, toward_light, slot);
        if let Some(t0) = t0 {
            sc.intersect_ns += t0.elapsed().as_nanos() as u64;
        }
        for j in each_lane(lit) {
            let r = &shadows[member[j] as usize];
            add(out, carry.slot[r.lane as usize], r.color);
        }
    }
    for (next, next_carry) in [
        (&mut *reflect, &*reflect_carry),
        (&mut *refract, &*refract_carry),
    ] {
        if next.n > 0 {
            next.seal(sc.isa);
            trace_packet(s, sc, next, next_carry, depth + 1, out);
        }
    }
    sc.levels[depth as usize] = Some(lv);
}

/// The lanes a shadow cache's blocker blocks.
struct CachedBlocker<'a, 't, R> {
    s: &'a DfScene<'t>,
    c: super::Candidate<'a, 't>,
    rays: &'a RayLanes<R>,
    m: Lanes,
    found: &'a mut Found<R>,
    tests: &'a mut KindCounts,
}

impl<R: Elem> crate::simd::Job for CachedBlocker<'_, '_, R> {
    type Out = Lanes;

    #[inline(always)]
    fn run<L: crate::simd::Lanes>(self) -> Lanes {
        let rays = self.rays;
        super::lanes::test::<R, L>(
            self.s,
            self.c,
            rays,
            self.m,
            &rays.t_max,
            super::lanes::Want::Any,
            self.found,
            self.tests,
        )
    }
}

/// The lanes of a packet of shadow rays (toward one light) that nothing
/// blocks; `slot` is their shadow cache slot. The cached blocker is tried
/// on every lane first (Haines' shadow cache), then the lanes it leaves
/// open walk the grids together; a blocker they find becomes the cached
/// one.
fn occluded_all<R: Elem>(
    s: &DfScene,
    sc: &mut Scratch<R>,
    rays: &RayLanes<R>,
    slot: usize,
) -> Lanes {
    let all = rays.all();
    let cached = sc.shadow_cache[slot];
    let mut open = all;
    if cached != NO_OBJECT {
        open &= !blocked_by(s, sc, cached, rays, all);
    }
    if open == 0 {
        return 0;
    }
    if !walk::diverge(s, rays, open) {
        let (blocked, blocker) = walk::occluded(s, sc, rays, open, [cached, NO_OBJECT], false);
        if blocker != NO_OBJECT {
            sc.shadow_cache[slot] = blocker;
        }
        return open & !blocked;
    }
    // Few rays left: one at a time, each trying the blocker the one
    // before it found (Haines' cache kept ray to ray).
    let mut lit = open;
    for i in each_lane(open) {
        let bit: Lanes = 1 << i;
        let latest = sc.shadow_cache[slot];
        if latest != cached && blocked_by(s, sc, latest, rays, bit) != 0 {
            lit &= !bit;
            continue;
        }
        let (blocked, blocker) = walk::occluded(s, sc, rays, bit, [cached, latest], true);
        if blocked != 0 {
            lit &= !bit;
            sc.shadow_cache[slot] = blocker;
        }
    }
    lit
}

/// The lanes of `m` that object `id` blocks.
fn blocked_by<R: Elem>(
    s: &DfScene,
    sc: &mut Scratch<R>,
    id: u32,
    rays: &RayLanes<R>,
    m: Lanes,
) -> Lanes {
    sc.isa.run(CachedBlocker {
        s,
        c: s.candidate(id),
        rays,
        m,
        found: &mut sc.found,
        tests: &mut sc.tests,
    })
}
