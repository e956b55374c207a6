//! One ray against a batch of triangles: the watertight test of
//! [`crate::intersect::triangle::intersect`] with the triangles in the
//! lanes, the same operations in the same order as the scalar test.
//!
//! The other kernels test one primitive against many rays, which is what
//! a breadth-first voxel's ray list and a depth-first packet's box tests
//! want. In a depth-first packet, though, the rays that reach one voxel
//! of a fine grid are few (two or three eye rays of a 512 x 512 image
//! per voxel of the dragon's grid) while the voxel lists several
//! triangles: there the lanes are better spent on the triangles, as a
//! BVH tracer's leaves do. A depth-first walk gathers a voxel's triangles
//! into a [`TriangleBatch`] once and tests each of its rays against them.

use super::rays::{LANES, Lanes, RayLanes};
use super::triangle::watertight;
use super::{for_chunks, ld};
use crate::simd::{Elem, Float, Job, Lanes as Simd};

/// Most triangles in a batch (a voxel listing more has a hierarchy).
pub const BATCH: usize = 64;

/// Triangles, one array per corner and coordinate, in the precision of
/// the tests.
pub struct TriangleBatch<R> {
    /// Triangles held.
    pub n: usize,
    /// `v[corner][axis][triangle]`.
    pub v: [[[R; BATCH]; 3]; 3],
}

impl<R: Elem> TriangleBatch<R> {
    pub fn new() -> Box<TriangleBatch<R>> {
        Box::new(TriangleBatch {
            n: 0,
            v: [[[R::ZERO; BATCH]; 3]; 3],
        })
    }

    /// Appends a triangle; returns its lane.
    #[inline(always)]
    pub fn push(&mut self, v: &[[f32; 3]; 3]) -> usize {
        let j = self.n;
        for (corner, p) in v.iter().enumerate() {
            for (axis, &x) in p.iter().enumerate() {
                self.v[corner][axis][j] = R::from_f32(x);
            }
        }
        self.n += 1;
        j
    }

    /// Every triangle held.
    #[inline(always)]
    pub fn all(&self) -> Lanes {
        if self.n >= BATCH {
            Lanes::MAX
        } else {
            (1 << self.n) - 1
        }
    }
}

/// The triangles of `m` that lane `i` of `rays` meets at some `t` with
/// `t_min < t < limit`, with their `t` in `t_out` (by triangle).
pub struct RayTriangles<'a, R> {
    pub batch: &'a TriangleBatch<R>,
    pub m: Lanes,
    pub rays: &'a RayLanes<R>,
    pub i: usize,
    pub limit: R,
    pub t_out: &'a mut [R; BATCH],
}

impl<R: Elem> Job for RayTriangles<'_, R> {
    type Out = Lanes;

    #[inline(always)]
    fn run<L: Simd>(self) -> Lanes {
        let RayTriangles {
            batch,
            m,
            rays,
            i,
            limit,
            t_out,
        } = self;
        let k = rays.axes[i].map(|k| usize::from(k).min(2));
        let o = [rays.o[k[0]][i], rays.o[k[1]][i], rays.o[k[2]][i]];
        let ray = Ray {
            o: [
                <R::V<L>>::splat(o[0]),
                <R::V<L>>::splat(o[1]),
                <R::V<L>>::splat(o[2]),
            ],
            s: [
                <R::V<L>>::splat(rays.sx[i]),
                <R::V<L>>::splat(rays.sy[i]),
                <R::V<L>>::splat(rays.sz[i]),
            ],
            t_min: <R::V<L>>::splat(rays.t_min[i]),
            limit: <R::V<L>>::splat(limit),
        };
        let mut hits = 0;
        for_chunks!(R::V<L>, m, |c, bits| {
            let h = chunk::<R, R::V<L>>(batch, k, &ray, c, bits, t_out);
            hits |= (h & bits) << c;
        });
        hits
    }
}

/// One ray's constants, in every lane.
struct Ray<V> {
    /// Origin in the ray's axes.
    o: [V; 3],
    /// Shear `sx`, `sy`, `sz`.
    s: [V; 3],
    t_min: V,
    limit: V,
}

#[inline(always)]
fn chunk<R: Elem, V: Float<Elem = R>>(
    batch: &TriangleBatch<R>,
    k: [usize; 3],
    ray: &Ray<V>,
    c: usize,
    bits: u64,
    t_out: &mut [R; BATCH],
) -> u64 {
    let (a, b, cc) = (
        corner(&batch.v[0], k, ray, c),
        corner(&batch.v[1], k, ray, c),
        corner(&batch.v[2], k, ray, c),
    );
    match watertight(&[a, b, cc], ray.s, (ray.t_min, ray.limit), bits) {
        Some((ok, t)) => {
            t.store(&mut t_out[c..c + V::N]);
            ok
        }
        None => 0,
    }
}

/// A corner of the triangles from lane `c`, relative to the ray's origin,
/// in the ray's axes `k`.
#[inline(always)]
fn corner<R: Elem, V: Float<Elem = R>>(
    v: &[[R; BATCH]; 3],
    k: [usize; 3],
    ray: &Ray<V>,
    c: usize,
) -> [V; 3] {
    [
        ld::<V>(&v[k[0]], c) - ray.o[0],
        ld::<V>(&v[k[1]], c) - ray.o[1],
        ld::<V>(&v[k[2]], c) - ray.o[2],
    ]
}

/// Keeps [`LANES`] and [`BATCH`] in step: a batch's triangles are masked
/// like a group's lanes.
const _: () = assert!(BATCH == LANES);
