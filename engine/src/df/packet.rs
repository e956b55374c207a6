//! Packets of rays walking a grid together: coherent grid traversal (Wald,
//! Ize, Kensler, Knoll and Parker, "Ray Tracing Animated Scenes using
//! Coherent Grid Traversal", SIGGRAPH 2006).
//!
//! The rays of a packet advance along one axis K (where all of them point
//! the same way) one slab of voxels at a time. In each slab the packet
//! covers a rectangle of voxels in the other two axes, found from bounds
//! on the rays' lines rather than from the rays one by one; every
//! candidate listed there whose box meets the packet's part of the slab is
//! tested against every ray still looking. Each ray so sees a superset of
//! the objects its own 3D-DDA walk would test, and each test is the scalar
//! test of the primitive kind with the ray's own data, so a ray finds
//! exactly the hit it finds alone: the nearest by distance, ties to the
//! smaller id, whatever the order of the tests. The walk costs per slab
//! about what one ray's walk costs per voxel, shared by the whole packet.

use super::DfScene;
use super::lanes::{LaneTests, Rays, lanes, width};
use super::nested::{Entry, high_first};
use super::single;
use super::trace::Scratch;
use crate::grid::GridSpec;
use crate::hit::{Hit, PrimId};
use crate::math::{Real, Vec3, Vec3Ext};
use crate::scene::Aabb;

pub use super::lanes::{LANES, Mask};

/// Bounds on a bundle of lines u(c) = a + s (c - c_ref), where u is one
/// coordinate across the walk axis and c the coordinate along it: every
/// line of the packet has its a in [a_lo, a_hi] and its slope s in
/// [s_lo, s_hi].
#[derive(Clone, Copy, Debug)]
struct LineBounds {
    c_ref: f64,
    a_lo: f64,
    a_hi: f64,
    s_lo: f64,
    s_hi: f64,
}

impl LineBounds {
    /// The lines of lanes `m` in axis `u` against axis `k`, referred to
    /// the plane c = `c_ref`, given each lane's slope du/dk. Every lane's
    /// direction must be non-zero on `k`.
    #[inline]
    fn of<R>(
        rays: &Rays<R>,
        m: Mask,
        k: usize,
        u: usize,
        c_ref: f64,
        s: &[f64; LANES],
    ) -> LineBounds {
        let (ou, ok) = (&rays.o[u], &rays.o[k]);
        let mut a = [0.0; LANES];
        for i in 0..width(m) {
            a[i] = ou[i] + s[i] * (c_ref - ok[i]);
        }
        let (a_lo, a_hi) = span(&a, m);
        let (s_lo, s_hi) = span(s, m);
        LineBounds {
            c_ref,
            a_lo,
            a_hi,
            s_lo,
            s_hi,
        }
    }

    /// The range of u over all the lines for c in [c0, c1], widened for
    /// rounding: the bound is bilinear in (s, c), so its extremes lie at
    /// the corners.
    #[inline(always)]
    fn range(&self, c0: f64, c1: f64) -> (f64, f64) {
        let (x0, x1) = (c0 - self.c_ref, c1 - self.c_ref);
        let p = [
            self.s_lo * x0,
            self.s_hi * x0,
            self.s_lo * x1,
            self.s_hi * x1,
        ];
        let lo = p[0].min(p[1]).min(p[2]).min(p[3]);
        let hi = p[0].max(p[1]).max(p[2]).max(p[3]);
        // Every term carries a relative rounding error of a few ulps (and
        // the slopes one of 1/d); this slack is a million times that.
        let slack = 1e-10 * (self.a_lo.abs() + self.a_hi.abs() + lo.abs() + hi.abs());
        (self.a_lo + lo - slack, self.a_hi + hi + slack)
    }
}

/// Slack, in voxels, added to each side of a slab's rectangle and to the
/// packet's part of a slab: far above the rounding of the line bounds, far
/// below a voxel.
const VOXEL_SLACK: f64 = 1e-4;

/// One axis of a grid, as the walk sees it.
#[derive(Clone, Copy, Debug)]
struct Axis {
    lo: f64,
    cell: f64,
    inv_cell: f64,
    res: u32,
    stride: usize,
}

impl Axis {
    fn of(g: &GridSpec, i: usize) -> Axis {
        let stride = match i {
            0 => 1,
            1 => g.res[0] as usize,
            _ => g.res[0] as usize * g.res[1] as usize,
        };
        Axis {
            lo: g.lo[i],
            cell: g.cell_size()[i],
            inv_cell: g.res[i] as f64 / (g.hi[i] - g.lo[i]),
            res: g.res[i],
            stride,
        }
    }

    /// The voxels overlapping [x0, x1], widened by the slack, or `None`
    /// if the range misses the grid.
    #[inline(always)]
    fn cells(&self, x0: f64, x1: f64) -> Option<(u32, u32)> {
        let f0 = (x0 - self.lo) * self.inv_cell - VOXEL_SLACK;
        let f1 = (x1 - self.lo) * self.inv_cell + VOXEL_SLACK;
        if !(f1 >= 0.0 && f0 < self.res as f64) {
            return None;
        }
        // Non-negative, so truncation is the floor; the casts saturate.
        let a = if f0 > 0.0 { f0 as u32 } else { 0 };
        let b = (f1 as u32).min(self.res - 1);
        Some((a, b))
    }
}

/// Whether lane `i` is in mask `m`.
#[inline(always)]
fn on(m: Mask, i: usize) -> bool {
    (m >> i) & 1 != 0
}

/// The least and the greatest of `x` over the lanes of `m` (not empty):
/// written lane-parallel, so that it vectorises.
#[inline(always)]
fn span(x: &[f64; LANES], m: Mask) -> (f64, f64) {
    let f = x[m.trailing_zeros() as usize & (LANES - 1)];
    let n = width(m);
    let mut lo = [0.0; LANES];
    for i in 0..n {
        lo[i] = if on(m, i) { x[i] } else { f };
    }
    let mut hi = lo;
    let mut w = n / 2;
    while w > 0 {
        for i in 0..w {
            lo[i] = min(lo[i], lo[i + w]);
            hi[i] = max(hi[i], hi[i + w]);
        }
        w /= 2;
    }
    (lo[0], hi[0])
}

/// The smaller of two numbers (the second if they are unordered): plain
/// comparisons, cheaper than `f64::min` and free to vectorise.
#[inline(always)]
fn min(a: f64, b: f64) -> f64 {
    if a < b { a } else { b }
}

#[inline(always)]
fn max(a: f64, b: f64) -> f64 {
    if a > b { a } else { b }
}

/// How a packet walks: along axis `k` (where all its rays point the same
/// way, `up` or down), between `c_lo` and `c_hi` along it (where the rays'
/// segments lie), with bounds on its lines in the other two axes.
pub struct Plan {
    k: usize,
    u: usize,
    v: usize,
    up: bool,
    c_lo: f64,
    c_hi: f64,
    reference: f64,
    bu: LineBounds,
    bv: LineBounds,
    /// Each lane's slopes du/dk and dv/dk, for culling lanes.
    su: [f64; LANES],
    sv: [f64; LANES],
    /// Lanes the loops over the packet cover (see [`width`]).
    w: usize,
    /// Whether the lines pass close enough to one point (at the reference
    /// plane) for culling lanes to pay.
    apex: bool,
    /// A distance far above any rounding of a hit's position, and above
    /// the grids' margin of a voxel: see [`DfScene::slack`].
    slack: f64,
    /// The grids (bit i: `s.grids[i]`) the lanes walk together; in the
    /// others (a dense model's fine grid, where the packet's rays spread
    /// over many voxels) each lane walks alone.
    together: u32,
}

impl Plan {
    /// How the lanes `m` would walk together; `reference` is a point near
    /// which their lines pass (their common origin, if they have one).
    /// `None` if their directions do not all point the same way along any
    /// axis, or if walking together would not pay.
    pub fn new<R>(s: &DfScene, rays: &Rays<R>, m: Mask, reference: Vec3) -> Option<Plan> {
        // The first grid of more than one voxel sets the culling's scale.
        let g = s.grids.iter().find(|g| !g.single_cell())?;
        if s.grids.len() > 32 {
            return None;
        }
        // Along the largest component of the first ray's direction, if
        // every ray points the same way along it.
        let first = m.trailing_zeros() as usize;
        let k = rays.d(first).max_axis();
        let up = rays.d[k][first] > 0.0;
        let (u, v) = ((k + 1) % 3, (k + 2) % 3);
        let (ok, dk, ik) = (&rays.o[k], &rays.d[k], &rays.inv[k]);
        let mut same = true;
        let mut ends = [[0.0; LANES]; 2];
        let mut su = [0.0; LANES];
        let mut sv = [0.0; LANES];
        let w = width(m);
        for i in 0..w {
            same &= !on(m, i) || if up { dk[i] > 0.0 } else { dk[i] < 0.0 };
            let (a, b) = (ok[i] + dk[i] * rays.t_min[i], ok[i] + dk[i] * rays.t_max[i]);
            ends[0][i] = min(a, b);
            ends[1][i] = max(a, b);
            su[i] = rays.d[u][i] * ik[i];
            sv[i] = rays.d[v][i] * ik[i];
        }
        if !same {
            return None;
        }
        let (c_lo, _) = span(&ends[0], m);
        let (_, c_hi) = span(&ends[1], m);
        let bu = LineBounds::of(rays, m, k, u, reference[k], &su);
        let bv = LineBounds::of(rays, m, k, v, reference[k], &sv);
        let cell = g.spec.cell_size();
        let mut plan = Plan {
            k,
            u,
            v,
            up,
            c_lo,
            c_hi,
            reference: reference[k],
            bu,
            bv,
            su,
            sv,
            w,
            apex: bu.a_hi - bu.a_lo < s.tune.apex * cell[u]
                && bv.a_hi - bv.a_lo < s.tune.apex * cell[v],
            slack: s.slack,
            together: 0,
        };
        // Grids the rays do not reach cost nothing either way.
        let mut worth = 0;
        let mut together = 0;
        for (i, g) in s.grids.iter().enumerate() {
            if g.single_cell() || !plan.reaches(&g.spec) {
                together |= 1 << i;
            } else if plan.worth_it(&g.spec, m, s.tune.worth) {
                together |= 1 << i;
                worth += 1;
            }
        }
        plan.together = together;
        (worth > 0).then_some(plan)
    }

    /// Whether the lanes walk grid `i` together.
    #[inline(always)]
    pub fn together(&self, i: usize) -> bool {
        self.together >> i & 1 != 0
    }

    /// Whether any ray's segment reaches grid `g`'s extent along k.
    fn reaches(&self, g: &GridSpec) -> bool {
        max(self.c_lo, g.lo[self.k]) <= min(self.c_hi, g.hi[self.k])
    }

    /// The lanes whose lines may pass through box `b`: for lines through
    /// (about) one point, the slopes toward the box from that point bound
    /// the slopes of the lines that meet it. All lanes if the box reaches
    /// the reference plane.
    #[inline(always)]
    fn lanes_meeting(&self, b: &Aabb) -> Mask {
        if !self.apex {
            return Mask::MAX;
        }
        let e = self.slack;
        let x0 = b.min[self.k] as f64 - e - self.reference;
        let x1 = b.max[self.k] as f64 + e - self.reference;
        if !(x0 > 0.0 || x1 < 0.0) {
            return Mask::MAX;
        }
        let (r0, r1) = (1.0 / x0, 1.0 / x1);
        // Lane i's line is u = a_i + s_i x with a_i in [a_lo, a_hi]; a
        // point of the box has u - a_i in [ulo, uhi] and x in [x0, x1],
        // so s_i = (u - a_i) / x lies between the corners' quotients.
        let range = |lo: f64, hi: f64, bl: &LineBounds| {
            let (ulo, uhi) = (lo - e - bl.a_hi, hi + e - bl.a_lo);
            let q = [ulo * r0, ulo * r1, uhi * r0, uhi * r1];
            let smin = min(min(q[0], q[1]), min(q[2], q[3]));
            let smax = max(max(q[0], q[1]), max(q[2], q[3]));
            // The quotients and the lanes' slopes (taken through 1/d)
            // are each a few ulps off.
            let tol = 1e-9 * (smin.abs() + smax.abs());
            (smin - tol, smax + tol)
        };
        let (ulo, uhi) = range(b.min[self.u] as f64, b.max[self.u] as f64, &self.bu);
        let (vlo, vhi) = range(b.min[self.v] as f64, b.max[self.v] as f64, &self.bv);
        // Lane-parallel, with no short cuts, so that it vectorises.
        let mut inside = [false; LANES];
        for i in 0..self.w {
            let (su, sv) = (self.su[i], self.sv[i]);
            inside[i] = (su >= ulo) & (su <= uhi) & (sv >= vlo) & (sv <= vhi);
        }
        let mut m = 0;
        for i in 0..self.w {
            m |= (inside[i] as Mask) << i;
        }
        m
    }

    /// Whether walking together pays in grid `g`: roughly how many voxels
    /// the packet covers per slab (halfway through the grid), against how
    /// many its rays would visit per slab walked one by one.
    fn worth_it(&self, g: &GridSpec, m: Mask, worth: f64) -> bool {
        let (ka, ua, va) = (
            Axis::of(g, self.k),
            Axis::of(g, self.u),
            Axis::of(g, self.v),
        );
        let lo = max(self.c_lo, ka.lo);
        let hi = min(self.c_hi, g.hi[self.k]);
        if !(lo <= hi) {
            return false;
        }
        let mid = 0.5 * (lo + hi);
        let half = 0.5 * ka.cell;
        let (ulo, uhi) = self.bu.range(mid - half, mid + half);
        let (vlo, vhi) = self.bv.range(mid - half, mid + half);
        let wu = (uhi - ulo) * ua.inv_cell + 1.0;
        let wv = (vhi - vlo) * va.inv_cell + 1.0;
        let (fu, fv) = (ka.cell * ua.inv_cell, ka.cell * va.inv_cell);
        let mut single = 0.0;
        for i in 0..self.w {
            let visits = 1.0 + self.su[i].abs() * fu + self.sv[i].abs() * fv;
            single += if on(m, i) { visits } else { 0.0 };
        }
        wu * wv <= worth * single
    }
}

/// A packet's walk through one grid: the slabs along k from the first
/// that any ray's segment reaches to the last.
struct SlabWalk<'p> {
    plan: &'p Plan,
    k: Axis,
    u: Axis,
    v: Axis,
    bu: LineBounds,
    bv: LineBounds,
    /// The part of the rays' extent along k within the grid.
    c_min: f64,
    c_max: f64,
    /// The current slab and the last one.
    slab: u32,
    last: u32,
}

/// The packet's part of a slab: its rectangle of voxels (the index of the
/// first and the ranges along u and v), and the box the rays pass through
/// in it, for culling candidates.
struct Slab {
    base: usize,
    u0: u32,
    u1: u32,
    v0: u32,
    v1: u32,
    lo: [f64; 3],
    hi: [f64; 3],
}

impl Slab {
    /// Whether a box may meet the packet in this slab.
    #[inline(always)]
    fn meets(&self, b: &Aabb) -> bool {
        let mut ok = true;
        for i in 0..3 {
            ok &= ((b.max[i] as f64) >= self.lo[i]) & ((b.min[i] as f64) <= self.hi[i]);
        }
        ok
    }
}

impl<'p> SlabWalk<'p> {
    /// The walk through grid `g`, or `None` if the rays' extent along k
    /// misses it.
    fn new(g: &GridSpec, plan: &'p Plan) -> Option<SlabWalk<'p>> {
        let ka = Axis::of(g, plan.k);
        let c_min = max(plan.c_lo, ka.lo);
        let c_max = min(plan.c_hi, g.hi[plan.k]);
        if !(c_min <= c_max) {
            return None;
        }
        let slab_of = |c: f64, slack: f64| {
            let f = (c - ka.lo) * ka.inv_cell + slack;
            if f > 0.0 {
                (f as u32).min(ka.res - 1)
            } else {
                0
            }
        };
        let (first, last) = (slab_of(c_min, -VOXEL_SLACK), slab_of(c_max, VOXEL_SLACK));
        let (slab, last) = if plan.up {
            (first, last)
        } else {
            (last, first)
        };
        Some(SlabWalk {
            plan,
            k: ka,
            u: Axis::of(g, plan.u),
            v: Axis::of(g, plan.v),
            bu: plan.bu,
            bv: plan.bv,
            c_min,
            c_max,
            slab,
            last,
        })
    }

    /// Narrows the bounds to the lanes `m` still walking.
    fn rebound<R>(&mut self, rays: &Rays<R>, m: Mask) {
        let p = self.plan;
        self.bu = LineBounds::of(rays, m, p.k, p.u, p.reference, &p.su);
        self.bv = LineBounds::of(rays, m, p.k, p.v, p.reference, &p.sv);
    }

    /// The packet's part of the current slab (`None` if it passes outside
    /// the grid there), and the coordinate along k where the rays leave
    /// the slab.
    #[inline(always)]
    fn slab(&self) -> (Option<Slab>, f64) {
        let k = &self.k;
        let near = k.lo + self.slab as f64 * k.cell;
        let far = k.lo + (self.slab + 1) as f64 * k.cell;
        let c_far = if self.plan.up { far } else { near };
        let slack = VOXEL_SLACK * k.cell + self.plan.slack;
        let (c0, c1) = (max(near, self.c_min) - slack, min(far, self.c_max) + slack);
        let (ulo, uhi) = self.bu.range(c0, c1);
        let (vlo, vhi) = self.bv.range(c0, c1);
        let cells = match (self.u.cells(ulo, uhi), self.v.cells(vlo, vhi)) {
            (Some((u0, u1)), Some((v0, v1))) => {
                let p = self.plan;
                let mut lo = [0.0; 3];
                let mut hi = [0.0; 3];
                let e = self.plan.slack;
                let (su, sv) = (VOXEL_SLACK * self.u.cell + e, VOXEL_SLACK * self.v.cell + e);
                (lo[p.k], hi[p.k]) = (c0, c1);
                (lo[p.u], hi[p.u]) = (ulo - su, uhi + su);
                (lo[p.v], hi[p.v]) = (vlo - sv, vhi + sv);
                Some(Slab {
                    base: self.slab as usize * k.stride,
                    u0,
                    u1,
                    v0,
                    v1,
                    lo,
                    hi,
                })
            }
            _ => None,
        };
        (cells, c_far)
    }

    /// Moves to the next slab; `false` past the last.
    #[inline(always)]
    fn advance(&mut self) -> bool {
        if self.slab == self.last {
            return false;
        }
        if self.plan.up {
            self.slab += 1;
        } else {
            self.slab -= 1;
        }
        true
    }

    /// Calls `visit` with the index of every voxel of the packet's part of
    /// the current slab, with the slab, until it returns `false`; returns
    /// where the rays leave the slab.
    #[inline(always)]
    fn voxels(&self, mut visit: impl FnMut(usize, &Slab) -> bool) -> f64 {
        let (cells, c_far) = self.slab();
        if let Some(c) = cells {
            for v in c.v0..=c.v1 {
                let row = c.base + v as usize * self.v.stride;
                for u in c.u0..=c.u1 {
                    if !visit(row + u as usize * self.u.stride, &c) {
                        return c_far;
                    }
                }
            }
        }
        c_far
    }

    /// The lanes of `m` whose rays leave the current slab, at `c_far`,
    /// beyond their `limit`.
    #[inline(always)]
    fn passed<R>(&self, rays: &Rays<R>, m: Mask, c_far: f64, limit: &[f64; LANES]) -> Mask {
        let k = self.plan.k;
        let (ok, ik) = (&rays.o[k], &rays.inv[k]);
        let mut out = 0;
        for i in 0..self.plan.w {
            let t_far = (c_far - ok[i]) * ik[i];
            out |= ((limit[i] < t_far) as Mask) << i;
        }
        out & m
    }

    /// Where along k the first of the lanes `m` reaches its `limit`: no
    /// lane can be done before the walk passes it.
    #[inline(always)]
    fn stop<R>(&self, rays: &Rays<R>, m: Mask, limit: &[f64; LANES]) -> f64 {
        let k = self.plan.k;
        let (ok, dk) = (&rays.o[k], &rays.d[k]);
        let mut c = if self.plan.up {
            f64::INFINITY
        } else {
            f64::NEG_INFINITY
        };
        for i in 0..self.plan.w {
            let at = ok[i] + dk[i] * limit[i];
            let on = on(m, i) && limit[i] < f64::INFINITY;
            c = if !on {
                c
            } else if self.plan.up {
                min(c, at)
            } else {
                max(c, at)
            };
        }
        c
    }

    /// Whether the walk, leaving the slab at `c_far`, has passed `stop`.
    #[inline(always)]
    fn past(&self, c_far: f64, stop: f64) -> bool {
        if self.plan.up {
            c_far > stop
        } else {
            c_far < stop
        }
    }
}

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
    pub fn new() -> Self {
        Hits {
            t: [f64::INFINITY; LANES],
            prim: [PrimId::NONE; LANES],
            upper: [R::INFINITY; LANES],
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
            true
        } else {
            false
        }
    }
}

/// The nearest hits of the lanes `m` of a packet walking as `plan` says,
/// offered to `best`.
pub fn nearest<R: Real>(
    s: &DfScene,
    sc: &mut Scratch<R>,
    rays: &Rays<R>,
    m: Mask,
    plan: &Plan,
    best: &mut Hits<R>,
) {
    // This packet's stamp and one for each lane in each grid it may walk
    // lane by lane, without the counter wrapping between them.
    sc.reserve_stamps(1 + (LANES * s.grids.len()) as u32);
    let stamp = sc.next_stamp();
    let hf = high_first(rays.d((m.trailing_zeros() as usize).min(LANES - 1)));
    // The large objects' grid first: one ground polygon found early prunes
    // the walk through the main grid.
    for (gi, g) in s.grids.iter().enumerate().rev() {
        if !plan.together(gi) {
            for i in lanes(m) {
                let (o, d, inv) = (rays.o(i), rays.d(i), rays.inv(i));
                let t_min = rays.t_min[i];
                let lane_stamp = sc.next_stamp();
                single::nearest_in(s, sc, g, lane_stamp, &rays.q[i], o, d, inv, t_min, best, i);
            }
            continue;
        }
        if g.single_cell() {
            // Inside a hierarchy, each box is tested for the lanes that met
            // its parent, and a leaf's objects for those that met the leaf.
            g.visit(0, hf, m, &mut |e| match e {
                Entry::Box(b, lm) => {
                    Some(rays.meeting(lm, b, s.slack, &best.t)).filter(|&x| x != 0)
                }
                Entry::Object(id, lm) => {
                    if sc.mail[id as usize] != stamp {
                        sc.mail[id as usize] = stamp;
                        LaneTests::new(s, s.candidate(id), id).nearest(
                            rays,
                            lm,
                            best,
                            &mut sc.tests,
                        );
                    }
                    Some(lm)
                }
            });
            continue;
        }
        let Some(mut w) = SlabWalk::new(&g.spec, plan) else {
            continue;
        };
        let mut live = m;
        let mut stop = w.stop(rays, live, &best.t);
        loop {
            let mut found = 0;
            let c_far = w.voxels(|cell, slab| {
                g.visit(cell, hf, live, &mut |e| match e {
                    // Inside a hierarchy, each box is tested for the lanes
                    // that met its parent (their segments up to their best
                    // hits; the slopes test of `lanes_meeting` costs more
                    // than it saves there), and a leaf's objects for those
                    // that met the leaf.
                    Entry::Box(b, lm) => Some(lm)
                        .filter(|_| slab.meets(b))
                        .map(|lm| rays.meeting(lm, b, s.slack, &best.t))
                        .filter(|&lm| lm != 0),
                    Entry::Object(id, lm) => {
                        let i = id as usize;
                        if sc.mail[i] == stamp {
                            return Some(lm);
                        }
                        let c = s.candidate(id);
                        let bbox = c.bbox();
                        if !slab.meets(&bbox) {
                            return Some(lm);
                        }
                        sc.mail[i] = stamp;
                        let t = lm & plan.lanes_meeting(&bbox);
                        if t != 0 {
                            found |= LaneTests::new(s, c, id).nearest(rays, t, best, &mut sc.tests);
                        }
                        Some(lm)
                    }
                });
                true
            });
            if found != 0 {
                stop = w.stop(rays, live, &best.t);
            }
            // A lane is done once its best hit lies before the slab's far
            // side.
            if w.past(c_far, stop) {
                let done = w.passed(rays, live, c_far, &best.t);
                live &= !done;
                if live == 0 {
                    break;
                }
                stop = w.stop(rays, live, &best.t);
                if done != 0 {
                    w.rebound(rays, live);
                }
            }
            if !w.advance() {
                break;
            }
        }
    }
}

/// Clears from `*m` the lanes of a packet of shadow rays walking as `plan`
/// says that something blocks. `tested` (the shadow cache's blocker, if
/// any) has been tried on these lanes already and is skipped; `last` is
/// set to a blocker found.
pub fn occluded<R: Real>(
    s: &DfScene,
    sc: &mut Scratch<R>,
    rays: &Rays<R>,
    m: &mut Mask,
    plan: &Plan,
    tested: u32,
    last: &mut u32,
) {
    sc.reserve_stamps(1 + (LANES * s.grids.len()) as u32);
    let stamp = sc.next_stamp();
    let hf = high_first(rays.d((m.trailing_zeros() as usize).min(LANES - 1)));
    if tested != super::trace::NO_OBJECT {
        sc.mail[tested as usize] = stamp;
    }
    for (gi, g) in s.grids.iter().enumerate().rev() {
        if *m == 0 {
            return;
        }
        if !plan.together(gi) {
            for i in lanes(*m) {
                let (o, d, inv) = (rays.o(i), rays.d(i), rays.inv(i));
                let (t_min, t_max) = (rays.t_min[i], rays.t_max[i]);
                let lane_stamp = sc.next_stamp();
                let id =
                    single::blocker_in(s, sc, g, lane_stamp, &rays.q[i], o, d, inv, t_min, t_max);
                if id != super::trace::NO_OBJECT {
                    *last = id;
                    *m &= !(1 << i);
                }
            }
            continue;
        }
        if g.single_cell() {
            g.visit(0, hf, *m, &mut |e| match e {
                Entry::Box(b, lm) => {
                    Some(rays.meeting(lm & *m, b, s.slack, &rays.t_max)).filter(|&x| x != 0)
                }
                Entry::Object(id, lm) => {
                    if sc.mail[id as usize] != stamp {
                        sc.mail[id as usize] = stamp;
                        let mut t = lm & *m;
                        let before = t;
                        if LaneTests::new(s, s.candidate(id), id).blocks(
                            rays,
                            &mut t,
                            &mut sc.tests,
                        ) {
                            *last = id;
                            *m &= !(before & !t);
                        }
                    }
                    Some(lm).filter(|_| *m != 0)
                }
            });
            continue;
        }
        let Some(mut w) = SlabWalk::new(&g.spec, plan) else {
            continue;
        };
        let mut live = *m;
        let mut blocked: Mask = 0;
        let mut stop = w.stop(rays, live, &rays.t_max);
        loop {
            let start = live;
            let c_far = w.voxels(|cell, slab| {
                g.visit(cell, hf, live, &mut |e| match e {
                    Entry::Box(b, lm) => Some(lm & live)
                        .filter(|&lm| lm != 0 && slab.meets(b))
                        .map(|lm| rays.meeting(lm, b, s.slack, &rays.t_max))
                        .filter(|&lm| lm != 0),
                    Entry::Object(id, lm) => {
                        let i = id as usize;
                        if sc.mail[i] == stamp {
                            return Some(lm);
                        }
                        let c = s.candidate(id);
                        let bbox = c.bbox();
                        if !slab.meets(&bbox) {
                            return Some(lm);
                        }
                        sc.mail[i] = stamp;
                        let mut t = lm & live & plan.lanes_meeting(&bbox);
                        if t == 0 {
                            return Some(lm);
                        }
                        let before = t;
                        if LaneTests::new(s, c, id).blocks(rays, &mut t, &mut sc.tests) {
                            *last = id;
                            live &= !(before & !t);
                            blocked |= before & !t;
                        }
                        Some(lm).filter(|_| live != 0)
                    }
                })
            });
            if live == 0 {
                break;
            }
            // A lane is also done once its segment ends before the slab's
            // far side.
            if w.past(c_far, stop) {
                live &= !w.passed(rays, live, c_far, &rays.t_max);
                if live == 0 {
                    break;
                }
                stop = w.stop(rays, live, &rays.t_max);
            }
            if !w.advance() {
                break;
            }
            if live != start {
                w.rebound(rays, live);
            }
        }
        *m &= !blocked;
    }
}
