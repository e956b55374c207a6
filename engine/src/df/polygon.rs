//! Many-sided polygons (the gears' faces have 144 vertices) tested
//! without walking every edge: the crossings test only counts edges that
//! straddle the hit point's v coordinate, so the edges are binned by their
//! v range once, and a test looks only at the edges of the hit point's bin.
//!
//! The result is bit for bit that of the polygon kind's own test
//! ([`crate::shapes::PolygonKind`]): the same box cull, the same plane
//! hit, and for every edge that can straddle, the same crossing
//! arithmetic with the edge's ends in the same order. Edges that cannot
//! straddle contribute nothing there either, and the parity of the
//! crossings does not depend on the order they are counted in.

use crate::intersect::RayQ;
use crate::math::{Real, V3};
use crate::scene::Aabb;
use crate::shapes::PolygonPlane;

/// Fewer vertices than this are tested edge by edge.
pub const MIN_VERTICES: usize = 12;

/// A polygon's edges binned by their range along the projection's v axis.
#[derive(Clone, Debug)]
pub struct EdgeBins {
    plane: PolygonPlane,
    v_lo: f64,
    v_hi: f64,
    /// Bins per unit of v.
    scale: f64,
    /// Edge `e` runs from vertex `e - 1` (the last for `e = 0`) to vertex
    /// `e`, as the crossings test walks them; bin `b` lists the edges
    /// `edges[start[b]..start[b + 1]]`.
    start: Vec<u32>,
    edges: Vec<u16>,
}

impl EdgeBins {
    /// The bins of polygon `v` with plane `plane` (as the polygon kind
    /// prepares it); `None` for a polygon of fewer than `MIN_VERTICES`
    /// vertices or more than `u16` can number.
    pub fn new(v: &[[f32; 3]], plane: &PolygonPlane) -> Option<EdgeBins> {
        let n = v.len();
        if n < MIN_VERTICES || n > u16::MAX as usize {
            return None;
        }
        let iv = plane.iv as usize;
        let (mut v_lo, mut v_hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for p in v {
            v_lo = v_lo.min(p[iv] as f64);
            v_hi = v_hi.max(p[iv] as f64);
        }
        let bins = n;
        let scale = if v_hi > v_lo {
            bins as f64 / (v_hi - v_lo)
        } else {
            0.0
        };
        // The bin of a v is computed here and in `inside` by the same
        // operations, each rounded monotonically (a subtraction, a
        // product by a positive number, a cut to an integer, a clamp):
        // every v of an edge's range, a point's v that the edge can
        // straddle among them, falls in a bin between those of its ends.
        let bin = |x: f64| Self::bin_of(x, v_lo, scale, bins);
        let range = |e: usize| {
            let (a, b) = (v[(e + n - 1) % n][iv] as f64, v[e][iv] as f64);
            (bin(a.min(b)), bin(a.max(b)))
        };
        let mut count = vec![0u32; bins + 1];
        for e in 0..n {
            let (lo, hi) = range(e);
            for c in &mut count[lo..=hi] {
                *c += 1;
            }
        }
        let mut start = Vec::with_capacity(bins + 1);
        let mut acc = 0;
        for c in &count {
            start.push(acc);
            acc += c;
        }
        let mut fill = start.clone();
        let mut edges = vec![0u16; acc as usize];
        for e in 0..n {
            let (lo, hi) = range(e);
            for f in &mut fill[lo..=hi] {
                edges[*f as usize] = e as u16;
                *f += 1;
            }
        }
        Some(EdgeBins {
            plane: *plane,
            v_lo,
            v_hi,
            scale,
            start,
            edges,
        })
    }

    /// The bin of `x` (at least `v_lo`), of `bins` bins `1 / scale` wide.
    #[inline(always)]
    fn bin_of(x: f64, v_lo: f64, scale: f64, bins: usize) -> usize {
        (((x - v_lo) * scale) as usize).min(bins - 1)
    }

    /// Nearest `t` in `(t_min, t_max)` at which `ray` meets polygon `v`
    /// (whose bins these are and whose box is `bbox`): exactly
    /// `PolygonKind::intersect`.
    #[inline]
    pub fn intersect<R: Real>(
        &self,
        v: &[[f32; 3]],
        bbox: &Aabb,
        ray: &RayQ<R>,
        t_min: R,
        t_max: R,
    ) -> Option<R> {
        // As the polygon kind: the box first, then the plane.
        if !ray.may_hit_box(bbox, t_min, t_max) {
            return None;
        }
        let pl = &self.plane;
        let n = V3::<R>::from_f64(pl.n);
        let denom = n.dot(ray.d);
        if denom == R::ZERO {
            return None;
        }
        let p0 = V3::<R>::from_f32(v[0]);
        let t = n.dot(p0 - ray.o) / denom;
        if !(t > t_min && t < t_max) {
            return None;
        }
        let p = ray.at(t);
        let (iu, iv) = (pl.iu as usize, pl.iv as usize);
        self.inside(v, p[iu], p[iv]).then_some(t)
    }

    /// Whether the point (`pu`, `pv`) of the polygon's plane, in its
    /// projection's axes, lies inside polygon `v` (whose bins these are):
    /// the crossings test over the edges of the point's bin.
    #[inline]
    pub fn inside<R: Real>(&self, v: &[[f32; 3]], pu: R, pv: R) -> bool {
        let pl = &self.plane;
        let (iu, iv) = (pl.iu as usize, pl.iv as usize);
        // No edge straddles a v outside the polygon's range (nor a NaN).
        let x = pv.to_f64();
        if !(x >= self.v_lo && x <= self.v_hi) {
            return false;
        }
        let b = Self::bin_of(x, self.v_lo, self.scale, self.start.len() - 1);
        let mut inside = false;
        let count = v.len();
        for &e in &self.edges[self.start[b] as usize..self.start[b + 1] as usize] {
            let e = e as usize;
            let (a, b) = (v[if e == 0 { count - 1 } else { e - 1 }], v[e]);
            let (au, av) = (R::from_f32(a[iu]), R::from_f32(a[iv]));
            let (bu, bv) = (R::from_f32(b[iu]), R::from_f32(b[iv]));
            if (av > pv) != (bv > pv) {
                let x = au + (pv - av) * (bu - au) / (bv - av);
                if pu < x {
                    inside = !inside;
                }
            }
        }
        inside
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shapes::{Kind, Polygon, PolygonKind};

    /// A small generator of reproducible numbers in [0, 1).
    struct Rng(u64);

    impl Rng {
        fn next(&mut self) -> f64 {
            self.0 = self
                .0
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (self.0 >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    /// A gear's outline: `teeth` teeth, in a tilted plane, with its first
    /// vertex on the outline's lowest v and some vertices repeated.
    fn gear(teeth: usize, tilt: f32) -> Vec<[f32; 3]> {
        let mut v = Vec::new();
        for i in 0..teeth * 4 {
            let a = i as f32 / (teeth * 4) as f32 * std::f32::consts::TAU;
            let r = if (i / 2) % 2 == 0 { 1.0 } else { 0.8 };
            let (x, y) = (r * a.cos(), r * a.sin());
            v.push([x, y, tilt * x + 0.5]);
            if i % 7 == 0 {
                v.push([x, y, tilt * x + 0.5]);
            }
        }
        v
    }

    fn check<R: Real>(v: &[[f32; 3]], rng: &mut Rng, rays: usize) -> usize {
        let shape = Polygon { vertices: v };
        let plane = PolygonKind::prepare(&shape).expect("many-sided");
        let bins = EdgeBins::new(v, &plane).expect("many-sided");
        let bbox = PolygonKind::bounds(&shape);
        let mut hits = 0;
        for i in 0..rays {
            // Rays from all around toward points on and near the polygon,
            // some through its vertices exactly, some along its plane.
            let target = if i % 5 == 0 {
                let p = v[i % v.len()];
                V3::new(p[0] as f64, p[1] as f64, p[2] as f64)
            } else {
                V3::new(
                    rng.next() * 2.4 - 1.2,
                    rng.next() * 2.4 - 1.2,
                    rng.next() * 0.2 + 0.4,
                )
            };
            let o = V3::new(
                rng.next() * 6.0 - 3.0,
                rng.next() * 6.0 - 3.0,
                if i % 11 == 0 {
                    0.5
                } else {
                    rng.next() * 6.0 - 3.0
                },
            );
            let d = target - o;
            if d == V3::zero() {
                continue;
            }
            let q = RayQ::<R>::new(o.cast(), d.cast());
            let (lo, hi) = if i % 3 == 0 {
                (R::ZERO, R::INFINITY)
            } else {
                (R::from_f64(rng.next()), R::from_f64(rng.next() * 2.0))
            };
            let want = PolygonKind::intersect(&shape, Some(&plane), &bbox, &q, lo, hi);
            let got = bins.intersect(v, &bbox, &q, lo, hi);
            assert_eq!(
                want.map(|t| t.to_f64().to_bits()),
                got.map(|t| t.to_f64().to_bits()),
                "ray {i}: {o:?} -> {d:?}"
            );
            hits += want.is_some() as usize;
        }
        hits
    }

    #[test]
    fn binned_crossings_match_the_polygon_test_bit_for_bit() {
        let mut rng = Rng(7);
        for (teeth, tilt) in [(36, 0.0), (36, 0.3), (5, 2.5), (64, -1.0)] {
            let v = gear(teeth, tilt);
            let hits = check::<f64>(&v, &mut rng, 20_000) + check::<f32>(&v, &mut rng, 20_000);
            assert!(hits > 5_000, "{hits} hits: the rays should often hit");
        }
    }

    #[test]
    fn few_vertices_are_not_binned() {
        let v = gear(2, 0.0);
        let plane = PolygonKind::prepare(&Polygon { vertices: &v[..8] }).expect("plane");
        assert!(EdgeBins::new(&v[..8], &plane).is_none());
    }
}
