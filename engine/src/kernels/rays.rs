//! A group of up to [`LANES`] rays held one array per coordinate, in the
//! precision of the tests: what the kernels test one primitive against.

use crate::math::{Real, V3, Vec3};
use crate::simd::{Isa, Job, Lanes as Simd};

/// Most rays in a group (a depth-first packet of 8 x 8 eye rays; a
/// breadth-first voxel's rays are tested 64 at a time).
pub const LANES: usize = 64;

/// A set of lanes of a group, one bit each.
pub type Lanes = u64;

/// Iterates over the lanes of a mask, lowest first.
#[inline(always)]
pub fn each_lane(mut m: Lanes) -> impl Iterator<Item = usize> {
    std::iter::from_fn(move || {
        (m != 0).then(|| {
            let i = m.trailing_zeros() as usize;
            m &= m - 1;
            i
        })
    })
}

/// Which of a ray's values a kernel reads (see [`RayLanes::set_q`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Need {
    /// Origin, direction and `d . d` (spheres).
    Sphere,
    /// Origin and the watertight test's axes and shear (triangles, and
    /// patches' triangles).
    Triangle,
    /// Everything.
    All,
}

impl Need {
    /// What the kernel of `kind` reads.
    pub fn of(kind: crate::shapes::ShapeKind) -> Need {
        use crate::shapes::ShapeKind;
        match kind {
            ShapeKind::Sphere => Need::Sphere,
            ShapeKind::Patch => Need::Triangle,
            _ => Need::All,
        }
    }
}

/// The rays of a group. Lane `i` holds the ray given to the `i`th
/// [`RayLanes::push`]; each is prepared exactly as a single ray is for the
/// scalar tests ([`crate::intersect::RayQ::with_inverse`]): origin,
/// direction and `1 / direction` computed in `f64` and rounded to `R`, so
/// that a kernel's lane finds the bits the scalar test finds.
#[repr(C, align(64))]
pub struct RayLanes<R> {
    /// Rays held.
    pub n: usize,
    pub o: [[R; LANES]; 3],
    pub d: [[R; LANES]; 3],
    /// `1 / d`, except where `d` is zero: the largest finite number of
    /// `d`'s sign there instead of an infinity, so that a box test never
    /// computes 0 x inf (see [`super::BoxLanes`]). No test divides by a
    /// zero component otherwise: the watertight test's `sz` is the
    /// reciprocal of the largest.
    pub inv: [[R; LANES]; 3],
    /// The interval of distances that count: a hit at `t` counts when
    /// `t_min < t < t_max` (the kernels take the upper end per call).
    pub t_min: [R; LANES],
    pub t_max: [R; LANES],
    /// The watertight triangle test's axes (Woop, Benthin and Wald): the
    /// index (0, 1 or 2, as a number) of the axes that become x, y and z
    /// after the direction's largest component is made z.
    pub kx: [R; LANES],
    pub ky: [R; LANES],
    pub kz: [R; LANES],
    /// The same as bytes, for the scalar fallbacks.
    pub axes: [[u8; 3]; LANES],
    /// Its shear constants.
    pub sx: [R; LANES],
    pub sy: [R; LANES],
    pub sz: [R; LANES],
    /// `d . d` and its reciprocal (the sphere test's).
    pub a: [R; LANES],
    pub inv_a: [R; LANES],
    /// Origin, direction and interval as given, in `f64`: what shading,
    /// instances (placed models are walked in `f64`) and the packets'
    /// bounds use.
    pub o64: [[f64; LANES]; 3],
    pub d64: [[f64; LANES]; 3],
    pub inv64: [[f64; LANES]; 3],
    pub t_min64: [f64; LANES],
    pub t_max64: [f64; LANES],
    /// Whether every ray held has the same axes (`axes[0]`): the
    /// triangle kernel then needs no per-lane selection of coordinates.
    pub same_axes: bool,
    /// Whether [`RayLanes::seal`] has run since the last push.
    sealed: bool,
}

/// Lanes of one pass of a loop over a group's lanes written for the
/// compiler to vectorise ([`RayLanes::seal`], the camera's directions):
/// a multiple of every vector width, dividing [`LANES`].
pub const CHUNK: usize = 16;
const _: () = assert!(LANES.is_multiple_of(CHUNK));

/// [`RayLanes::seal`], compiled for each instruction set.
struct Seal<'a, R>(&'a mut RayLanes<R>);

impl<R: Real> Job for Seal<'_, R> {
    type Out = ();

    #[inline(always)]
    fn run<L: Simd>(self) {
        self.0.derive();
    }
}

impl<R: Real> Default for RayLanes<R> {
    fn default() -> Self {
        Self::new()
    }
}

impl<R: Real> RayLanes<R> {
    pub fn new() -> Self {
        let z = [R::ZERO; LANES];
        RayLanes {
            n: 0,
            o: [z; 3],
            d: [[R::ONE; LANES]; 3],
            inv: [[R::ONE; LANES]; 3],
            t_min: z,
            t_max: [R::INFINITY; LANES],
            kx: z,
            ky: [R::ONE; LANES],
            kz: [R::TWO; LANES],
            axes: [[0, 1, 2]; LANES],
            sx: z,
            sy: z,
            sz: [R::ONE; LANES],
            a: [R::ONE; LANES],
            inv_a: [R::ONE; LANES],
            o64: [[0.0; LANES]; 3],
            d64: [[1.0; LANES]; 3],
            inv64: [[1.0; LANES]; 3],
            t_min64: [0.0; LANES],
            t_max64: [f64::INFINITY; LANES],
            same_axes: true,
            sealed: true,
        }
    }

    /// Forgets every ray.
    #[inline]
    pub fn clear(&mut self) {
        self.n = 0;
        self.same_axes = true;
        self.sealed = true;
    }

    /// Whether no more rays fit.
    #[inline]
    pub fn is_full(&self) -> bool {
        self.n == LANES
    }

    /// Every lane in use.
    #[inline]
    pub fn all(&self) -> Lanes {
        if self.n >= LANES {
            Lanes::MAX
        } else {
            (1 << self.n) - 1
        }
    }

    /// Appends the ray `o + t d`, `t_min < t < t_max` (`d` not zero);
    /// returns its lane. Only the ray as given is stored: what the
    /// kernels read is derived for all the group's rays at once by
    /// [`RayLanes::seal`], which must come before any test.
    #[inline]
    pub fn push(&mut self, o: Vec3, d: Vec3, t_min: f64, t_max: f64) -> usize {
        let i = self.n;
        assert!(i < LANES, "a ray group holds {LANES} rays");
        for a in 0..3 {
            self.o64[a][i] = o[a];
            self.d64[a][i] = d[a];
        }
        self.t_min64[i] = t_min;
        self.t_max64[i] = t_max;
        self.n += 1;
        self.sealed = false;
        i
    }

    /// Whether what the kernels read has been derived for every ray
    /// pushed.
    #[inline]
    pub fn is_sealed(&self) -> bool {
        self.sealed
    }

    /// Derives, for every ray pushed, what the kernels read: each
    /// prepared exactly as a single ray is for the scalar tests
    /// ([`crate::intersect::RayQ::with_inverse`]), in loops over the lanes
    /// compiled for the instruction set `isa` (the same operations lane by
    /// lane on every width: see [`crate::simd`]).
    pub fn seal(&mut self, isa: Isa) {
        isa.run(Seal(self));
    }

    /// [`RayLanes::seal`]'s work: first what vectorises (reciprocals,
    /// roundings to `R`, `d . d`), sixteen lanes at a time (lanes from
    /// `n` to the next multiple of sixteen are computed too, from
    /// whatever they hold, and never read), then the watertight test's
    /// choice of axes, ray by ray.
    #[inline(always)]
    fn derive(&mut self) {
        let n = self.n.min(LANES);
        for c in (0..n).step_by(CHUNK) {
            for i in c..c + CHUNK {
                let mut dr = [R::ZERO; 3];
                for a in 0..3 {
                    let inv = 1.0 / self.d64[a][i];
                    self.inv64[a][i] = inv;
                    self.o[a][i] = R::from_f64(self.o64[a][i]);
                    dr[a] = R::from_f64(self.d64[a][i]);
                    self.d[a][i] = dr[a];
                    let ir = R::from_f64(inv);
                    self.inv[a][i] = if ir.is_finite() {
                        ir
                    } else if ir > R::ZERO {
                        R::MAX
                    } else {
                        -R::MAX
                    };
                }
                self.t_min[i] = R::from_f64(self.t_min64[i]);
                self.t_max[i] = R::from_f64(self.t_max64[i]);
                // `V3::dot`'s order.
                let a = dr[0] * dr[0] + dr[1] * dr[1] + dr[2] * dr[2];
                self.a[i] = a;
                self.inv_a[i] = R::ONE / a;
            }
        }
        // As `RayQ::with_inverse`, in the precision of the tests.
        for i in 0..n {
            let dr = V3::new(self.d[0][i], self.d[1][i], self.d[2][i]);
            let kz = dr.max_axis();
            let (mut kx, mut ky) = ((kz + 1) % 3, (kz + 2) % 3);
            if dr[kz] < R::ZERO {
                std::mem::swap(&mut kx, &mut ky);
            }
            // The reciprocal as rounded, not made finite.
            let sz = R::from_f64(self.inv64[kz][i]);
            self.axes[i] = [kx as u8, ky as u8, kz as u8];
            self.kx[i] = R::from_f64(kx as f64);
            self.ky[i] = R::from_f64(ky as f64);
            self.kz[i] = R::from_f64(kz as f64);
            self.sx[i] = dr[kx] * sz;
            self.sy[i] = dr[ky] * sz;
            self.sz[i] = sz;
        }
        self.same_axes = self.axes[1..n.max(1)].iter().all(|&x| x == self.axes[0]);
        self.sealed = true;
    }

    /// Puts ray `q`, prepared for the scalar tests, in lane `i`, with the
    /// interval `t_min < t < t_max`: the very values the scalar tests read
    /// of `q` (its reciprocal made finite as [`RayLanes::set`] does), so
    /// that a kernel's lane finds what the scalar test finds on `q`; only
    /// those the kernels of `need` read. The `f64` copies are left as they
    /// were: no kernel reads them.
    #[inline(always)]
    pub fn set_q(
        &mut self,
        i: usize,
        q: &crate::intersect::RayQ<R>,
        t_min: R,
        t_max: R,
        need: Need,
    ) {
        self.t_min[i] = t_min;
        self.t_max[i] = t_max;
        for a in 0..3 {
            self.o[a][i] = q.o[a];
        }
        if need != Need::Triangle {
            for a in 0..3 {
                self.d[a][i] = q.d[a];
            }
            self.a[i] = q.a;
            self.inv_a[i] = q.inv_a;
        }
        if need == Need::Sphere {
            return;
        }
        if need == Need::All {
            for a in 0..3 {
                let inv = q.inv[a];
                self.inv[a][i] = if inv.is_finite() {
                    inv
                } else if inv > R::ZERO {
                    R::MAX
                } else {
                    -R::MAX
                };
            }
        }
        let axes = [q.kx, q.ky, q.kz];
        self.axes[i] = axes;
        self.kx[i] = R::from_f64(q.kx as f64);
        self.ky[i] = R::from_f64(q.ky as f64);
        self.kz[i] = R::from_f64(q.kz as f64);
        self.sx[i] = q.sx;
        self.sy[i] = q.sy;
        self.sz[i] = q.sz();
        if i == 0 {
            self.same_axes = true;
        } else {
            self.same_axes &= axes == self.axes[0];
        }
    }

    /// Copies lane `from` of `src` into lane `to`.
    #[inline]
    pub fn copy_lane(&mut self, to: usize, src: &RayLanes<R>, from: usize) {
        for a in 0..3 {
            self.o[a][to] = src.o[a][from];
            self.d[a][to] = src.d[a][from];
            self.inv[a][to] = src.inv[a][from];
            self.o64[a][to] = src.o64[a][from];
            self.d64[a][to] = src.d64[a][from];
            self.inv64[a][to] = src.inv64[a][from];
        }
        self.t_min[to] = src.t_min[from];
        self.t_max[to] = src.t_max[from];
        self.t_min64[to] = src.t_min64[from];
        self.t_max64[to] = src.t_max64[from];
        self.kx[to] = src.kx[from];
        self.ky[to] = src.ky[from];
        self.kz[to] = src.kz[from];
        self.axes[to] = src.axes[from];
        self.sx[to] = src.sx[from];
        self.sy[to] = src.sy[from];
        self.sz[to] = src.sz[from];
        self.a[to] = src.a[from];
        self.inv_a[to] = src.inv_a[from];
        if to == 0 {
            self.same_axes = true;
        } else {
            self.same_axes &= self.axes[to] == self.axes[0];
        }
    }

    /// Lane `i`'s origin, direction and `1 / direction` in `f64`.
    #[inline(always)]
    pub fn o(&self, i: usize) -> Vec3 {
        Vec3::new(self.o64[0][i], self.o64[1][i], self.o64[2][i])
    }

    #[inline(always)]
    pub fn d(&self, i: usize) -> Vec3 {
        Vec3::new(self.d64[0][i], self.d64[1][i], self.d64[2][i])
    }

    #[inline(always)]
    pub fn inv(&self, i: usize) -> Vec3 {
        Vec3::new(self.inv64[0][i], self.inv64[1][i], self.inv64[2][i])
    }

    /// Lane `i` as a single ray for the scalar tests.
    #[inline]
    pub fn ray(&self, i: usize) -> crate::intersect::RayQ<R> {
        crate::intersect::RayQ::with_inverse(
            V3::new(self.o[0][i], self.o[1][i], self.o[2][i]),
            V3::new(self.d[0][i], self.d[1][i], self.d[2][i]),
            V3::new(self.inv[0][i], self.inv[1][i], self.inv[2][i]),
        )
    }
}
