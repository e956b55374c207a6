//! One box against many rays: which lanes may meet it.
//!
//! Two tests: [`BoxLanes`], the conservative culling test of a traversal
//! (a grid's region, a hierarchy's node, an object's box grown by a
//! pad), and [`MayHitBox`], exactly the scalar pre-test
//! [`crate::intersect::RayQ::may_hit_box`] that some primitives' tests
//! begin with (so it must give the same answer bit for bit).

use super::rays::{LANES, Lanes, RayLanes};
use super::{for_chunks, lane_mask, ld};
use crate::math::Real;
use crate::simd::{Elem, Float, Job, Lanes as Simd, Mask};

/// The lanes of `m` whose rays may meet the box `[lo, hi]` at some `t`
/// in `[t_min, limit]` (`t_min` is never negative). Callers grow the box
/// by a pad far above the rounding of the arithmetic, so that no box a
/// ray touches is missed.
///
/// Along an axis where a ray's direction is zero, `1 / d` is the largest
/// finite number ([`RayLanes::inv`]), never an infinity: an origin on a
/// face of the grown box gives `0`, not NaN, and an origin inside the
/// grown box is at least the pad from its faces, so its slab spans every
/// `t` from `0` to far beyond any distance in the scene. (An origin
/// outside the slab may be let through a tiny distance: a box let
/// through costs time, never a hit.)
pub struct BoxLanes<'a, R> {
    pub lo: [R; 3],
    pub hi: [R; 3],
    pub rays: &'a RayLanes<R>,
    pub m: Lanes,
    pub limit: &'a [R; LANES],
}

impl<R: Elem> Job for BoxLanes<'_, R> {
    type Out = Lanes;

    #[inline(always)]
    fn run<L: Simd>(self) -> Lanes {
        let mut out = 0;
        for_chunks!(R::V<L>, self.m, |c, bits| {
            let h = meets::<R, R::V<L>>(&self.lo, &self.hi, self.rays, c, self.limit);
            out |= (h & bits) << c;
        });
        out
    }
}

/// Lanes from `c` meeting the box (relative to `c`).
#[inline(always)]
pub(super) fn meets<R: Elem, V: Float<Elem = R>>(
    lo: &[R; 3],
    hi: &[R; 3],
    rays: &RayLanes<R>,
    c: usize,
    limit: &[R; LANES],
) -> u64 {
    let mut t0 = ld::<V>(&rays.t_min, c);
    let mut t1 = ld::<V>(limit, c);
    for i in 0..3 {
        let o = ld::<V>(&rays.o[i], c);
        let inv = ld::<V>(&rays.inv[i], c);
        let a = (V::splat(lo[i]) - o) * inv;
        let z = (V::splat(hi[i]) - o) * inv;
        t0 = t0.max(a.min(z));
        t1 = t1.min(a.max(z));
    }
    t0.le(t1).bits() & lane_mask::<V>()
}

/// The lanes of `m` for which `may_hit_box(b, t_min, limit)` holds: the
/// scalar test, lane by lane, with its early exits.
pub struct MayHitBox<'a, R> {
    pub b: &'a crate::scene::Aabb,
    pub rays: &'a RayLanes<R>,
    pub m: Lanes,
    pub limit: &'a [R; LANES],
}

impl<R: Elem> Job for MayHitBox<'_, R> {
    type Out = Lanes;

    #[inline(always)]
    fn run<L: Simd>(self) -> Lanes {
        let mut out = 0;
        for_chunks!(R::V<L>, self.m, |c, bits| {
            let h = may_hit_box::<R, R::V<L>>(self.b, self.rays, c, self.limit);
            out |= (h & bits) << c;
        });
        out
    }
}

/// [`MayHitBox`] for the lanes from `c` (relative to `c`).
#[inline(always)]
pub(super) fn may_hit_box<R: Elem, V: Float<Elem = R>>(
    b: &crate::scene::Aabb,
    rays: &RayLanes<R>,
    c: usize,
    limit: &[R; LANES],
) -> u64 {
    let mut t0 = ld::<V>(&rays.t_min, c);
    let mut t1 = ld::<V>(limit, c);
    let zero = V::splat(R::ZERO);
    let eps = V::splat(R::EPSILON * R::from_f32(16.0));
    let d = [
        ld::<V>(&rays.d[0], c),
        ld::<V>(&rays.d[1], c),
        ld::<V>(&rays.d[2], c),
    ];
    // Lanes the scalar test has returned `false` for.
    let mut out = V::splat(R::ZERO).lt(zero);
    if d[0].eq(zero).or(d[1].eq(zero)).or(d[2].eq(zero)).bits() & lane_mask::<V>() == 0 {
        // No direction with a zero component among these lanes (nearly
        // always): the same arithmetic without the zero direction's
        // cases, which would select what is computed here anyway.
        for i in 0..3 {
            let (a, z) = slab::<R, V>(b, rays, c, i, eps);
            t0 = t0.max(a);
            t1 = t1.min(z);
            out = out.or(t0.gt(t1));
        }
        return out.not().bits() & lane_mask::<V>();
    }
    for (i, &d) in d.iter().enumerate() {
        let (lo, hi) = (
            V::splat(R::from_f32(b.min[i])),
            V::splat(R::from_f32(b.max[i])),
        );
        let o = ld::<V>(&rays.o[i], c);
        let flat = d.eq(zero);
        // A zero direction: out if the origin is outside the slab, and
        // the axis changes nothing.
        out = out.or(flat.and(o.lt(lo).or(o.gt(hi))));
        let (a, z) = slab::<R, V>(b, rays, c, i, eps);
        t0 = V::select(flat, t0, t0.max(a));
        t1 = V::select(flat, t1, t1.min(z));
        out = out.or(flat.not().and(t0.gt(t1)));
    }
    out.not().bits() & lane_mask::<V>()
}

/// The scalar pre-test's slab along axis `i` for the lanes from `c`: the
/// entry and exit distances, each moved out by its slack (meaningless
/// for a lane whose direction along `i` is zero, which the caller
/// leaves out).
#[inline(always)]
fn slab<R: Elem, V: Float<Elem = R>>(
    b: &crate::scene::Aabb,
    rays: &RayLanes<R>,
    c: usize,
    i: usize,
    eps: V,
) -> (V, V) {
    let (lo, hi) = (
        V::splat(R::from_f32(b.min[i])),
        V::splat(R::from_f32(b.max[i])),
    );
    let o = ld::<V>(&rays.o[i], c);
    let inv = ld::<V>(&rays.inv[i], c);
    let (a0, z0) = ((lo - o) * inv, (hi - o) * inv);
    let swap = a0.gt(z0);
    let (a, z) = (V::select(swap, z0, a0), V::select(swap, a0, z0));
    let slack = a.abs().max(z.abs()) * eps;
    (a - slack, z + slack)
}

/// `x` made a value of `R` no smaller (or, with `up` false, no larger):
/// boxes are `f32`, and a box test in `f32` takes them as they are.
#[inline(always)]
pub fn widen<R: Real>(x: f64, up: bool) -> R {
    let r = R::from_f64(x);
    let back = r.to_f64();
    if (up && back < x) || (!up && back > x) {
        if up { r.next_up() } else { -(-r).next_up() }
    } else {
        r
    }
}
