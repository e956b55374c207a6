//! A group of rays walking the grids together.
//!
//! The group descends each grid's occupancy [`Pyramid`] from its one top
//! block: a block is entered with the lanes whose rays may meet its box
//! before their best hit so far (one [`BoxLanes`] kernel over the group),
//! its set children in front-to-back order, down to the voxels, whose
//! objects (and crowded voxels' hierarchies) are tested with the kernels.
//! Lanes drop out of a block as soon as their rays miss it or have found
//! a nearer hit, so coherent rays share the walk and incoherent ones
//! narrow it to their own. Rays that diverge (reflections off small spheres) walk alone through
//! a dense grid, voxel by voxel ([`diverge`]): the descent costs a box
//! test per block, a 3D-DDA step a few instructions per voxel.
//!
//! Each ray finds exactly the hit it finds alone, whatever the group:
//! every culling test is conservative (boxes grown by the scene's slack,
//! far above any rounding), an object is tested once per walk (mailbox)
//! against every lane that may meet its box, and the nearest hit wins,
//! ties to the smaller input id, whatever the order of the tests.

use super::lanes::{self, Found, Want};
use super::pyramid::BlockBounds;
use super::trace::{NO_OBJECT, Scratch};
use super::{Candidate, DfScene, ObjectGrid};
use crate::grid::Dda;
use crate::grid::nested::{Holds, MAX_PENDING, NESTED, high_first};
use crate::hit::{Hit, PrimId};
use crate::kernels::{
    BATCH, BoxLanes, LANES, Lanes, RayLanes, RayTriangles, Triangle, each_lane, widen,
};
use crate::math::Real;
use crate::objects::Slot;
use crate::scene::Aabb;
use crate::simd::{Elem, Job, Lanes as Simd};

/// The nearest hit found so far by each lane (distance and primitive),
/// and the bound a test must beat: just above the best distance, so that
/// an exact tie is seen and goes to the smaller id.
#[derive(Clone, Copy, Debug)]
pub struct Hits<R> {
    pub t: [f64; LANES],
    pub prim: [PrimId; LANES],
    pub upper: [R; LANES],
}

impl<R: Real> Hits<R> {
    /// No hit yet; each lane's bound is its ray's `t_max`.
    pub fn new(rays: &RayLanes<R>) -> Self {
        Hits {
            t: [f64::INFINITY; LANES],
            prim: [PrimId::NONE; LANES],
            upper: rays.t_max,
        }
    }

    /// Lane `i`'s hit.
    #[inline(always)]
    pub fn hit(&self, i: usize) -> Hit {
        Hit {
            t: self.t[i],
            prim: self.prim[i],
        }
    }

    /// Offers lane `i` a hit at `t` on primitive `prim`; whether it won.
    /// `ranks` gives each object's input id, by which ties go (empty: the
    /// ids are the positions).
    #[inline(always)]
    pub fn offer(&mut self, i: usize, t: R, prim: PrimId, ranks: &[u32]) -> bool {
        let t = t.to_f64();
        let h = self.hit(i);
        let wins = if ranks.is_empty() || t != h.t {
            h.loses_to(t, prim)
        } else {
            // An exact tie in a database in spatial order (rare: looked
            // up only then).
            let rank = |p: PrimId| ranks[p.world_index() as usize];
            h.loses_to_ranked(rank(h.prim), t, prim, rank(prim))
        };
        if wins {
            self.t[i] = t;
            self.prim[i] = prim;
            self.upper[i] = R::from_f64(t).next_up();
        }
        wins
    }
}

/// What a walk looks for, and what it does with a candidate's hits.
trait Goal<R: Elem> {
    /// The lanes still looking.
    fn live(&self) -> Lanes;
    /// Each lane's upper bound on the distance of a hit worth finding.
    fn limit(&self) -> &[R; LANES];
    const WANT: Want;
    /// Takes the hits `hit` of object `id`, found in `out` (which holds a
    /// placed model's triangles if `instance`).
    fn take(&mut self, s: &DfScene, id: u32, hit: Lanes, out: &Found<R>, instance: bool);
    /// Takes lane `i`'s hit at `t` on object `id`.
    fn take_lane(&mut self, s: &DfScene, i: usize, t: R, id: u32);
    /// Where lane `i`'s walk may end (in `f64`): past its best hit so
    /// far, or its ray's end.
    fn far(&self, rays: &RayLanes<R>, i: usize) -> f64;
    /// Whether lane `i` has found what it looks for before `t_exit`, so
    /// that no voxel beyond can change it.
    fn done_before(&self, i: usize, t_exit: f64) -> bool;
}

struct Nearest<'b, R> {
    best: &'b mut Hits<R>,
    all: Lanes,
}

impl<R: Elem> Goal<R> for Nearest<'_, R> {
    #[inline(always)]
    fn live(&self) -> Lanes {
        self.all
    }

    #[inline(always)]
    fn limit(&self) -> &[R; LANES] {
        &self.best.upper
    }

    const WANT: Want = Want::Nearest;

    #[inline(always)]
    fn take(&mut self, s: &DfScene, id: u32, hit: Lanes, out: &Found<R>, instance: bool) {
        let ranks = s.objects.ranks();
        for i in each_lane(hit) {
            let prim = if instance {
                PrimId::instance(id, out.prim[i])
            } else {
                PrimId::object(id)
            };
            self.best.offer(i, out.t[i], prim, ranks);
        }
    }

    #[inline(always)]
    fn take_lane(&mut self, s: &DfScene, i: usize, t: R, id: u32) {
        self.best.offer(i, t, PrimId::object(id), s.objects.ranks());
    }

    #[inline(always)]
    fn far(&self, rays: &RayLanes<R>, i: usize) -> f64 {
        if self.best.prim[i] == PrimId::NONE {
            rays.t_max64[i]
        } else {
            self.best.t[i].next_up()
        }
    }

    #[inline(always)]
    fn done_before(&self, i: usize, t_exit: f64) -> bool {
        self.best.prim[i] != PrimId::NONE && self.best.t[i] < t_exit
    }
}

struct Any<'r, R> {
    t_max: &'r [R; LANES],
    open: Lanes,
    blocker: u32,
}

impl<R: Elem> Goal<R> for Any<'_, R> {
    #[inline(always)]
    fn live(&self) -> Lanes {
        self.open
    }

    #[inline(always)]
    fn limit(&self) -> &[R; LANES] {
        self.t_max
    }

    const WANT: Want = Want::Any;

    #[inline(always)]
    fn take_lane(&mut self, _: &DfScene, i: usize, _: R, id: u32) {
        self.open &= !(1 << i);
        self.blocker = id;
    }

    fn take(&mut self, _: &DfScene, id: u32, hit: Lanes, _: &Found<R>, _: bool) {
        if hit != 0 {
            self.open &= !hit;
            self.blocker = id;
        }
    }

    #[inline(always)]
    fn far(&self, rays: &RayLanes<R>, i: usize) -> f64 {
        rays.t_max64[i]
    }

    #[inline(always)]
    fn done_before(&self, i: usize, _: f64) -> bool {
        self.open >> i & 1 == 0
    }
}

/// A walk, run with the lanes of the render's instruction set: the walk
/// and the kernels it calls are compiled as one function for each.
struct Walk<'a, 't, 's, R, G> {
    s: &'a DfScene<'t>,
    sc: &'s mut Scratch<R>,
    rays: &'a RayLanes<R>,
    goal: G,
    tested: [u32; 2],
    /// Each lane walks alone.
    apart: bool,
}

impl<R: Elem, G: Goal<R>> Job for Walk<'_, '_, '_, R, G> {
    type Out = G;

    #[inline(always)]
    fn run<L: Simd>(mut self) -> G {
        walk::<R, L, G>(
            self.s,
            self.sc,
            self.rays,
            &mut self.goal,
            self.tested,
            self.apart,
        );
        self.goal
    }
}

/// The nearest hits of the lanes `m` of `rays`, offered to `best`; with
/// `apart`, each lane walks alone (see [`diverge`]).
pub fn nearest<R: Elem>(
    s: &DfScene,
    sc: &mut Scratch<R>,
    rays: &RayLanes<R>,
    m: Lanes,
    best: &mut Hits<R>,
    apart: bool,
) {
    debug_assert!(rays.is_sealed(), "rays tested before they are sealed");
    let isa = sc.isa;
    isa.run(Walk {
        s,
        sc,
        rays,
        goal: Nearest { best, all: m },
        tested: [NO_OBJECT; 2],
        apart,
    });
}

/// The lanes of `m` that something blocks before their `t_max`, and one
/// object that blocks some (or `NO_OBJECT`). The objects `tested` (or
/// `NO_OBJECT`), already tried on these lanes, are not tested again;
/// with `apart`, each lane walks alone.
pub fn occluded<R: Elem>(
    s: &DfScene,
    sc: &mut Scratch<R>,
    rays: &RayLanes<R>,
    m: Lanes,
    tested: [u32; 2],
    apart: bool,
) -> (Lanes, u32) {
    debug_assert!(rays.is_sealed(), "rays tested before they are sealed");
    let isa = sc.isa;
    let goal = isa.run(Walk {
        s,
        sc,
        rays,
        goal: Any {
            t_max: &rays.t_max,
            open: m,
            blocker: NO_OBJECT,
        },
        tested,
        apart,
    });
    (m & !goal.open, goal.blocker)
}

/// Walks every grid (the large objects' first: one ground polygon found
/// early prunes the walk through the main grid).
#[inline(always)]
fn walk<R: Elem, L: Simd, G: Goal<R>>(
    s: &DfScene,
    sc: &mut Scratch<R>,
    rays: &RayLanes<R>,
    goal: &mut G,
    tested: [u32; 2],
    apart: bool,
) {
    sc.mailbox.begin();
    for id in tested {
        if id != NO_OBJECT {
            sc.mailbox.untested(id, goal.live());
        }
    }
    for (i, g) in s.grids.iter().enumerate().rev() {
        if goal.live() == 0 {
            return;
        }
        if g.single_cell() {
            // A one-voxel grid (a few large objects): no walk needed.
            visit_voxel::<R, L, G>(s, sc, g, 0, goal.live(), rays, goal);
        } else if apart && g.dense() {
            // Voxel by voxel through a grid with few empty voxels to skip.
            for lane in each_lane(goal.live()) {
                walk_lane::<R, L, G>(s, sc, g, lane, rays, goal);
            }
        } else {
            walk_grid::<R, L, G>(s, sc, g, &s.blocks[i], rays, goal);
        }
    }
}

/// Whether the rays of lanes `m` had better walk one at a time, voxel by
/// voxel: only in a scene with a dense grid (few empty voxels to skip),
/// and only if they are too few to share a pyramid's descent or point too
/// many ways for their walks to overlap (the spread of their unit
/// directions). Lone walks find the same hits; only time and test counts
/// differ, and those depend on the rays alone.
pub(super) fn diverge<R: Real>(s: &DfScene, rays: &RayLanes<R>, m: Lanes) -> bool {
    if !s.has_dense {
        return false;
    }
    if m.count_ones() <= 2 {
        return true;
    }
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    // Spawned rays (the only ones asked about) have unit directions.
    for i in each_lane(m) {
        for a in 0..3 {
            let u = rays.d64[a][i];
            lo[a] = lo[a].min(u);
            hi[a] = hi[a].max(u);
        }
    }
    let spread = (0..3).map(|a| hi[a] - lo[a]).fold(0.0, f64::max);
    spread > SPREAD
}

/// The spread of unit directions (largest range of a coordinate) above
/// which a group's rays walk alone: measured on the SPD scenes, reflected
/// rays off the balls' and rings' spheres spread wider and gain; the
/// teapot's and mount's reflections stay below it.
const SPREAD: f64 = 0.5;

/// Lane `lane` alone through grid `g`, voxel by voxel (the 3D-DDA of
/// Amanatides and Woo), left as soon as its hit lies before the current
/// voxel's far side.
#[inline(always)]
fn walk_lane<R: Elem, L: Simd, G: Goal<R>>(
    s: &DfScene,
    sc: &mut Scratch<R>,
    g: &ObjectGrid,
    lane: usize,
    rays: &RayLanes<R>,
    goal: &mut G,
) {
    let bit: Lanes = 1 << lane;
    let (o, d, inv) = (rays.o(lane), rays.d(lane), rays.inv(lane));
    let Some(mut w) = Dda::start(&g.spec, o, d, inv, rays.t_min64[lane], goal.far(rays, lane))
    else {
        return;
    };
    loop {
        visit_voxel::<R, L, G>(s, sc, g, w.index, bit, rays, goal);
        if goal.done_before(lane, w.t_exit()) || !w.advance() {
            return;
        }
    }
}

/// A box grown by `pad` and rounded outward to `R`.
#[inline(always)]
fn grown<R: Real>(lo: [f64; 3], hi: [f64; 3], pad: f64) -> ([R; 3], [R; 3]) {
    (
        lo.map(|x| widen(x - pad, false)),
        hi.map(|x| widen(x + pad, true)),
    )
}

/// Most blocks a descent keeps pending: up to seven siblings per level of
/// a grid's pyramid (a grid has at most 4096 voxels a side: 13 levels).
const MAX_BLOCKS: usize = 7 * 13 + 1;

/// The pyramid's descent through grid `g`, whose blocks' boxes are
/// `blocks`.
#[inline(always)]
fn walk_grid<R: Elem, L: Simd, G: Goal<R>>(
    s: &DfScene,
    sc: &mut Scratch<R>,
    g: &ObjectGrid,
    blocks: &BlockBounds,
    rays: &RayLanes<R>,
    goal: &mut G,
) {
    let spec = &g.spec;
    let first = goal.live().trailing_zeros() as usize & (LANES - 1);
    let order = ChildOrder::of(rays.d(first));
    let mut stack = [(0u8, [0u32; 3], 0 as Lanes); MAX_BLOCKS];
    stack[0] = (g.pyramid.height() as u8, [0; 3], goal.live());
    let mut sp = 1;
    while sp > 0 {
        sp -= 1;
        let (level, c, lanes) = stack[sp];
        let lanes = lanes & goal.live();
        if lanes == 0 {
            continue;
        }
        let l = level as usize;
        let (lo, hi) = blocks.of::<R>(l, c);
        let lanes = BoxLanes {
            lo,
            hi,
            rays,
            m: lanes,
            limit: goal.limit(),
        }
        .run::<L>();
        if lanes == 0 {
            continue;
        }
        if l == 0 {
            visit_voxel::<R, L, G>(s, sc, g, spec.index(c), lanes, rays, goal);
            if goal.live() == 0 {
                break;
            }
            continue;
        }
        // The set children, nearest last on the stack (popped first).
        let kids = g.pyramid.kids(l, c);
        for k in (0..8).rev() {
            let j = order.0[k];
            if kids >> j & 1 != 0 {
                stack[sp] = (
                    level - 1,
                    [
                        c[0] * 2 + (j & 1) as u32,
                        c[1] * 2 + (j >> 1 & 1) as u32,
                        c[2] * 2 + (j >> 2 & 1) as u32,
                    ],
                    lanes,
                );
                sp += 1;
            }
        }
    }
}

/// The order in which a walk enters a block's eight children: front to
/// back for a direction, the axis it moves fastest along varying
/// slowest, so that blocks nearer along it come first.
struct ChildOrder([u8; 8]);

impl ChildOrder {
    fn of(d: crate::math::Vec3) -> ChildOrder {
        // Axes from the slowest along `d` to the fastest.
        let mut axes = [0usize, 1, 2];
        axes.sort_by(|&a, &b| d[a].abs().total_cmp(&d[b].abs()));
        let flip = (d.x < 0.0) as u8 | ((d.y < 0.0) as u8) << 1 | ((d.z < 0.0) as u8) << 2;
        ChildOrder(std::array::from_fn(|k| {
            let mut j = 0u8;
            for (bit, &a) in axes.iter().enumerate() {
                j |= ((k >> bit & 1) as u8) << a;
            }
            j ^ flip
        }))
    }
}

/// Tests the objects of voxel `index` of grid `g` against the lanes
/// `lanes` that reach it and have not tested them yet; a crowded voxel's
/// hierarchy (and an aggregate's below it) is descended with the lanes
/// that meet each box. (Plain loops: a closure here might not be inlined
/// into the function compiled for the instruction set, and the kernels
/// with it.)
#[inline(always)]
fn visit_voxel<R: Elem, L: Simd, G: Goal<R>>(
    s: &DfScene,
    sc: &mut Scratch<R>,
    g: &ObjectGrid,
    index: usize,
    lanes: Lanes,
    rays: &RayLanes<R>,
    goal: &mut G,
) {
    let f = lanes.trailing_zeros() as usize & (LANES - 1);
    let hf = high_first(rays.d(f));
    let h = g.hierarchies();
    // The voxel's faces go in a batch, tested ray by ray once the list is
    // read; other objects one by one, against the lanes.
    sc.batch.n = 0;
    for &e in g.cell(index) {
        if goal.live() == 0 {
            return;
        }
        if e & NESTED == 0 {
            let slot = s.objects.slot(e);
            let m = sc.mailbox.untested(e, lanes & goal.live());
            if m == 0 {
                continue;
            }
            if let Slot::Face(face) = slot {
                sc.tests.add_n(face.kind(), m.count_ones() as u64);
                let j = sc.batch.push(&s.objects.positions(&face));
                sc.batch_ids[j] = e;
                sc.batch_lanes[j] = m;
            } else {
                test::<R, L, G>(s, sc, e, slot, rays, m, goal);
            }
            continue;
        }
        let mut pending = [(0u32, 0 as Lanes); MAX_PENDING];
        pending[0] = (e & !NESTED, lanes);
        let mut sp = 1;
        while sp > 0 {
            sp -= 1;
            let (n, lm) = pending[sp];
            let lm = lm & goal.live();
            if lm == 0 {
                continue;
            }
            let (b, holds) = h.node(n, hf);
            let (lo, hi) = box_of::<R>(b, s.slack);
            let lm = BoxLanes {
                lo,
                hi,
                rays,
                m: lm,
                limit: goal.limit(),
            }
            .run::<L>();
            if lm == 0 {
                continue;
            }
            match holds {
                Holds::Children(near, far) => {
                    pending[sp] = (far, lm);
                    pending[sp + 1] = (near, lm);
                    sp += 2;
                }
                Holds::Leaf(ids) => {
                    for &id in ids {
                        if id & NESTED != 0 {
                            pending[sp] = (id & !NESTED, lm);
                            sp += 1;
                        } else {
                            entry::<R, L, G>(s, sc, id, lm, rays, goal);
                        }
                    }
                }
            }
        }
    }
    if sc.batch.n > 0 {
        test_batch::<R, L, G>(s, sc, rays, goal);
    }
}

/// A voxel that is not crowded lists no more faces than a batch holds.
const _: () = assert!(crate::grid::nested::MIN_OBJECTS <= BATCH);

/// Tests the faces gathered in the batch, each against the lanes that
/// met it and had not tested it: ray by ray, all of a ray's faces at
/// once.
#[inline(always)]
fn test_batch<R: Elem, L: Simd, G: Goal<R>>(
    s: &DfScene,
    sc: &mut Scratch<R>,
    rays: &RayLanes<R>,
    goal: &mut G,
) {
    // Each lane's faces (a transpose of the faces' lanes).
    let mut union = 0;
    for j in 0..sc.batch.n {
        union |= sc.batch_lanes[j];
    }
    let mut faces = [0 as Lanes; LANES];
    for j in 0..sc.batch.n {
        for i in each_lane(sc.batch_lanes[j]) {
            faces[i] |= 1 << j;
        }
    }
    for i in each_lane(union) {
        if goal.live() >> i & 1 == 0 {
            continue;
        }
        let hit = RayTriangles {
            batch: &sc.batch,
            m: faces[i],
            rays,
            i,
            limit: goal.limit()[i],
            t_out: &mut sc.batch_t,
        }
        .run::<L>();
        for j in each_lane(hit) {
            goal.take_lane(s, i, sc.batch_t[j], sc.batch_ids[j]);
        }
    }
}

/// Object `id`, met by the lanes `lm`: tested against those that have not
/// tested it yet.
#[inline(always)]
fn entry<R: Elem, L: Simd, G: Goal<R>>(
    s: &DfScene,
    sc: &mut Scratch<R>,
    id: u32,
    lm: Lanes,
    rays: &RayLanes<R>,
    goal: &mut G,
) {
    let m = sc.mailbox.untested(id, lm & goal.live());
    if m != 0 {
        test::<R, L, G>(s, sc, id, s.objects.slot(id), rays, m, goal);
    }
}

/// Tests object `id`, whose slot is `slot`, against the lanes `m`.
#[inline(always)]
fn test<R: Elem, L: Simd, G: Goal<R>>(
    s: &DfScene,
    sc: &mut Scratch<R>,
    id: u32,
    slot: Slot,
    rays: &RayLanes<R>,
    m: Lanes,
    goal: &mut G,
) {
    // Faces (the bulk of a mesh) straight to the triangle kernel; other
    // objects through their kind's test.
    let r = match slot {
        Slot::Record(r) => r,
        Slot::Face(f) => {
            let v = s.objects.positions(&f);
            sc.tests.add_n(f.kind(), m.count_ones() as u64);
            let hit = Triangle {
                v: &v,
                rays,
                m,
                limit: goal.limit(),
                t_out: &mut sc.found.t,
            }
            .run::<L>();
            if hit != 0 {
                goal.take(s, id, hit, &sc.found, false);
            }
            return;
        }
    };
    let c = s.record_candidate(r);
    let hit = lanes::test::<R, L>(
        s,
        c,
        rays,
        m,
        goal.limit(),
        G::WANT,
        &mut sc.found,
        &mut sc.tests,
    );
    let instance = matches!(c, Candidate::Instance(..));
    goal.take(s, id, hit, &sc.found, instance);
}

#[inline(always)]
fn box_of<R: Real>(b: &Aabb, pad: f64) -> ([R; 3], [R; 3]) {
    grown(b.min.map(f64::from), b.max.map(f64::from), pad)
}
