//! The rays of a packet, one array per coordinate, and the tests of one
//! candidate against several of them.

use super::packet::Hits;
use super::{Candidate, DfScene};
use crate::hit::PrimId;
use crate::intersect::{RayQ, triangle};
use crate::math::{Real, V3, Vec3, Vec3Ext};
use crate::render::KindCounts;
use crate::scene::Aabb;
use crate::shapes::{Kind, Shape, SphereKind};

/// Eye rays go in packets of PACKET_SIDE x PACKET_SIDE pixel corners.
pub const PACKET_SIDE: usize = 8;

/// Most rays in a packet.
pub const LANES: usize = PACKET_SIDE * PACKET_SIDE;

/// A set of lanes, one bit each.
pub type Mask = u64;

/// How many lanes from the first a loop over the lanes `m` must cover: a
/// power of two from 8 up, so that lane-parallel loops over a few rays
/// stay short and still vectorise.
#[inline(always)]
pub fn width(m: Mask) -> usize {
    let top = (Mask::BITS - m.leading_zeros()) as usize;
    top.next_power_of_two().clamp(8, LANES)
}

/// Iterates over the lanes of a mask, lowest first.
#[inline(always)]
pub fn lanes(mut m: Mask) -> impl Iterator<Item = usize> {
    std::iter::from_fn(move || {
        (m != 0).then(|| {
            let i = m.trailing_zeros() as usize;
            m &= m - 1;
            i
        })
    })
}

/// The rays of a packet: origin, direction and 1/d, one array per axis;
/// the segment each may hit in; and each ray prepared for the tests.
pub struct Rays<R> {
    pub n: usize,
    pub o: [[f64; LANES]; 3],
    pub d: [[f64; LANES]; 3],
    pub inv: [[f64; LANES]; 3],
    pub t_min: [f64; LANES],
    /// Shadow rays: the distance to the light. Other rays: infinity.
    pub t_max: [f64; LANES],
    /// The same in the precision of the tests.
    pub rmin: [R; LANES],
    pub rmax: [R; LANES],
    pub q: [RayQ<R>; LANES],
}

impl<R: Real> Rays<R> {
    pub fn new() -> Self {
        let q = RayQ::new(V3::zero(), V3::splat(R::ONE));
        Rays {
            n: 0,
            o: [[0.0; LANES]; 3],
            d: [[0.0; LANES]; 3],
            inv: [[0.0; LANES]; 3],
            t_min: [0.0; LANES],
            t_max: [f64::INFINITY; LANES],
            rmin: [R::ZERO; LANES],
            rmax: [R::INFINITY; LANES],
            q: [q; LANES],
        }
    }

    /// Appends a ray; returns its lane.
    #[inline]
    pub fn push(&mut self, o: Vec3, d: Vec3, t_min: f64, t_max: f64) -> usize {
        let i = self.n;
        let inv = Vec3::new(1.0 / d.x, 1.0 / d.y, 1.0 / d.z);
        for a in 0..3 {
            self.o[a][i] = o[a];
            self.d[a][i] = d[a];
            self.inv[a][i] = inv[a];
        }
        self.t_min[i] = t_min;
        self.t_max[i] = t_max;
        self.rmin[i] = R::from_f64(t_min);
        self.rmax[i] = R::from_f64(t_max);
        self.q[i] = RayQ::with_inverse(o.cast(), d.cast(), inv.cast());
        self.n += 1;
        i
    }
}

impl<R: Copy> Rays<R> {
    /// Fills the lanes past the last ray with copies of the first, so that
    /// what is computed over all lanes (bounds, spans) is the packet's.
    #[inline]
    pub fn pad(&mut self) {
        for i in self.n.max(1)..width(self.all()) {
            for a in 0..3 {
                self.o[a][i] = self.o[a][0];
                self.d[a][i] = self.d[a][0];
                self.inv[a][i] = self.inv[a][0];
            }
            self.t_min[i] = self.t_min[0];
            self.t_max[i] = self.t_max[0];
        }
    }
}

impl<R> Rays<R> {
    /// The lanes of `m` whose rays may meet box `b` grown by `pad` between
    /// their `t_min` and `limit`. Conservative: a zero direction rules a
    /// box out only when the origin lies outside its slab (see
    /// [`super::nested::slab`]).
    #[inline(always)]
    pub fn meeting(&self, m: Mask, b: &Aabb, pad: f64, limit: &[f64; LANES]) -> Mask {
        let lo: [f64; 3] = std::array::from_fn(|a| b.min[a] as f64 - pad);
        let hi: [f64; 3] = std::array::from_fn(|a| b.max[a] as f64 + pad);
        // Lane-parallel, with no short cuts, so that it vectorises.
        let mut inside = [false; LANES];
        for i in 0..width(m) {
            let (mut t0, mut t1) = (self.t_min[i], limit[i]);
            for a in 0..3 {
                let x = (lo[a] - self.o[a][i]) * self.inv[a][i];
                let y = (hi[a] - self.o[a][i]) * self.inv[a][i];
                let (near, far) = super::nested::slab(x, y);
                t0 = t0.max(near);
                t1 = t1.min(far);
            }
            inside[i] = t0 <= t1;
        }
        let mut out = 0;
        for (i, &x) in inside.iter().enumerate().take(width(m)) {
            out |= (x as Mask) << i;
        }
        out & m
    }

    /// Every lane in use.
    #[inline]
    pub fn all(&self) -> Mask {
        if self.n >= Mask::BITS as usize {
            Mask::MAX
        } else {
            (1 << self.n) - 1
        }
    }

    #[inline(always)]
    pub fn o(&self, i: usize) -> Vec3 {
        Vec3::new(self.o[0][i], self.o[1][i], self.o[2][i])
    }

    #[inline(always)]
    pub fn d(&self, i: usize) -> Vec3 {
        Vec3::new(self.d[0][i], self.d[1][i], self.d[2][i])
    }

    #[inline(always)]
    pub fn inv(&self, i: usize) -> Vec3 {
        Vec3::new(self.inv[0][i], self.inv[1][i], self.inv[2][i])
    }
}

/// One candidate, ready to be tested against the lanes of a packet: each
/// lane's test is exactly the scalar test of the candidate's kind.
pub struct LaneTests<'a, 't> {
    s: &'a DfScene<'t>,
    c: Candidate<'a, 't>,
    id: u32,
}

impl<'a, 't> LaneTests<'a, 't> {
    #[inline(always)]
    pub fn new(s: &'a DfScene<'t>, c: Candidate<'a, 't>, id: u32) -> Self {
        LaneTests { s, c, id }
    }

    /// Tests the lanes of `m`, each up to `to`'s limit for it, and
    /// gives `to` each hit: each lane's test is the scalar test of the
    /// object's kind.
    #[inline(always)]
    fn hits<R: Real>(
        &self,
        rays: &Rays<R>,
        m: Mask,
        to: &mut impl LaneSink<R>,
        tests: &mut KindCounts,
    ) {
        match &self.c {
            Candidate::Instance(_, pl) => {
                let models = &self.s.models;
                for i in lanes(m) {
                    let (q, lo, hi) = (&rays.q[i], rays.rmin[i], to.limit(i));
                    let (o, d) = (rays.o(i), rays.d(i));
                    if to.nearest() {
                        if let Some((t, p)) = models.nearest(pl, q, o, d, lo, hi, tests) {
                            to.hit(i, t, PrimId::instance(self.id, p));
                        }
                    } else if models.blocks(pl, q, o, d, lo, hi, tests) {
                        to.hit(i, hi, PrimId::NONE);
                    }
                }
            }
            Candidate::Face { v, .. } => {
                let [a, b, c] = *v;
                for i in lanes(m) {
                    if let Some(t) =
                        triangle::intersect(a, b, c, &rays.q[i], rays.rmin[i], to.limit(i))
                    {
                        to.hit(i, t, PrimId::object(self.id));
                    }
                }
            }
            Candidate::Record(h) => match &h.shape {
                Shape::Sphere(sp) => {
                    for i in lanes(m) {
                        let (q, lo, hi) = (&rays.q[i], rays.rmin[i], to.limit(i));
                        if let Some(t) = SphereKind::intersect(sp, None, &h.bbox, q, lo, hi) {
                            to.hit(i, t, PrimId::object(self.id));
                        }
                    }
                }
                Shape::Polygon(p) if p.vertices.len() == 3 => {
                    let (a, b, c) = (p.vertices[0], p.vertices[1], p.vertices[2]);
                    for i in lanes(m) {
                        if let Some(t) =
                            triangle::intersect(a, b, c, &rays.q[i], rays.rmin[i], to.limit(i))
                        {
                            to.hit(i, t, PrimId::object(self.id));
                        }
                    }
                }
                _ => {
                    for i in lanes(m) {
                        let (q, lo, hi) = (&rays.q[i], rays.rmin[i], to.limit(i));
                        if let Some(t) = self.c.intersect(self.s, q, lo, hi) {
                            to.hit(i, t, PrimId::object(self.id));
                        }
                    }
                }
            },
        }
    }

    /// Offers each lane of `m` its hit on the candidate, if any; returns
    /// the lanes whose best hit it became.
    #[inline(always)]
    pub fn nearest<R: Real>(
        &self,
        rays: &Rays<R>,
        m: Mask,
        best: &mut Hits<R>,
        tests: &mut KindCounts,
    ) -> Mask {
        tests.add_n(self.c.kind(), m.count_ones() as u64);
        let mut to = Nearest {
            best,
            won: 0,
            ranks: self.s.objects.ranks(),
        };
        self.hits(rays, m, &mut to, tests);
        to.won
    }

    /// Clears from `*m` the lanes the candidate blocks (a hit anywhere in
    /// their segments); whether it blocked any.
    #[inline(always)]
    pub fn blocks<R: Real>(&self, rays: &Rays<R>, m: &mut Mask, tests: &mut KindCounts) -> bool {
        tests.add_n(self.c.kind(), m.count_ones() as u64);
        let mut to = Blocked {
            rmax: &rays.rmax,
            hit: 0,
        };
        self.hits(rays, *m, &mut to, tests);
        *m &= !to.hit;
        to.hit != 0
    }
}

/// Where [`LaneTests::hits`] gets each lane's limit and puts its hits.
trait LaneSink<R> {
    fn limit(&self, i: usize) -> R;
    fn hit(&mut self, i: usize, t: R, prim: PrimId);
    /// Whether it keeps the nearest hit (not any hit at all).
    fn nearest(&self) -> bool;
}

/// Hits offered to each lane's best so far.
struct Nearest<'b, R> {
    best: &'b mut Hits<R>,
    won: Mask,
    /// The objects' input ids, for ties (see [`Hits::offer`]).
    ranks: &'b [u32],
}

impl<R: Real> LaneSink<R> for Nearest<'_, R> {
    #[inline(always)]
    fn limit(&self, i: usize) -> R {
        self.best.upper[i]
    }

    #[inline(always)]
    fn hit(&mut self, i: usize, t: R, prim: PrimId) {
        self.won |= (self.best.offer(i, t, prim, self.ranks) as Mask) << i;
    }

    fn nearest(&self) -> bool {
        true
    }
}

/// Lanes blocked anywhere along their segments.
struct Blocked<'r, R> {
    rmax: &'r [R; LANES],
    hit: Mask,
}

impl<R: Real> LaneSink<R> for Blocked<'_, R> {
    #[inline(always)]
    fn limit(&self, i: usize) -> R {
        self.rmax[i]
    }

    #[inline(always)]
    fn hit(&mut self, i: usize, _: R, _: PrimId) {
        self.hit |= 1 << i;
    }

    fn nearest(&self) -> bool {
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lanes_along_a_face_meet_the_box() {
        let b = Aabb {
            min: [0.0; 3],
            max: [1.0; 3],
        };
        let mut rays = Rays::<f64>::new();
        // In the face planes y = 0 and y = 1, then just outside y = 0,
        // then an ordinary ray through the box, then one that passes by.
        rays.push(Vec3::new(-1.0, 0.0, 0.5), Vec3::X, 0.0, f64::INFINITY);
        rays.push(Vec3::new(-1.0, 1.0, 0.5), Vec3::X, 0.0, f64::INFINITY);
        rays.push(Vec3::new(-1.0, -1e-9, 0.5), Vec3::X, 0.0, f64::INFINITY);
        rays.push(
            Vec3::new(-1.0, -1.0, 0.5),
            Vec3::new(1.0, 1.0, 0.0),
            0.0,
            f64::INFINITY,
        );
        rays.push(
            Vec3::new(-1.0, -1.0, 0.5),
            Vec3::new(1.0, -1.0, 0.0),
            0.0,
            f64::INFINITY,
        );
        rays.pad();
        let limit = [f64::INFINITY; LANES];
        assert_eq!(rays.meeting(rays.all(), &b, 0.0, &limit), 0b01011);
        assert_eq!(rays.meeting(rays.all(), &b, 1e-8, &limit), 0b01111);
        // A limit before the box rules the ordinary ray out.
        let mut short = limit;
        short[3] = 0.5;
        assert_eq!(rays.meeting(0b01000, &b, 0.0, &short), 0);
    }
}
