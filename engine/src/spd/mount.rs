//! Fractal mountain (Carpenter's midpoint displacement on a square grid) of
//! 2 * 4^size triangles, with a pyramid of four glass spheres; one light.
//!
//! Heights come from the SPD's portable Gaussian generator seeded by the
//! SPD's original (faulty, repetitive) hash of the grid position, which the
//! SPD keeps for comparison with published images. That hash shifts by
//! `23 - size`, `15 - size` and `7 - size` bits; from size 8 on a count
//! goes negative, which C leaves undefined. We reproduce what the SPD does
//! when built with GCC on x86-64 (the shift count taken modulo 64), so
//! large mountains match that build.

use super::matrix::{self as m, Axis, PI};
use super::out::Out;
use crate::error::Error;

const FRACTAL_DIMENSION: f64 = 2.2;
const MOUNTAIN_NO: i64 = 21;
const CORNER: f64 = -1.0;
const WIDTH: f64 = 2.0;

pub fn generate(out: &mut Out, size: u32) -> Result<(), Error> {
    out.background(super::SKY)?;
    out.viewpoint(
        [-1.6, 1.6, 1.7],
        [0.0; 3],
        [0.0, 0.0, 1.0],
        45.0,
        0.01,
        [512, 512],
    )?;
    out.light([-100.0, -100.0, 100.0])?;

    out.color([1.0, 1.0, 1.0], 0.0, 0.1, 0.1, 0.4, 6.7, 0.9, 1.5)?;
    spheres(out, [-0.8, 0.8, 1.0, 0.17])?;

    out.color([0.5, 0.45, 0.35], 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0)?;
    let num_pts = 1i64 << size;
    let ratio = 2.0 / (2.0f64.ln() / (FRACTAL_DIMENSION - 1.0)).exp();
    let roughness = (ratio * ratio - 1.0).sqrt();
    let mut g = Grower {
        out,
        fnum_pts: num_pts as f64,
        size,
        roughness,
    };
    g.grow(num_pts, 0, 0, [0.0; 4])
}

/// A tetrahedral pyramid of four spheres resting at `c` (x, y, z, radius).
fn spheres(out: &mut Out, c: [f64; 4]) -> Result<(), Error> {
    let mut axis = [1.0, 1.0, 0.0];
    m::normalize(&mut axis);
    let angle = (-1.0f64 / 3.0).acos();
    let pt = [0.0, 0.0, c[3] * (3.0f64 / 2.0).sqrt()];
    out.sphere(m::add([c[0], c[1], c[2]], pt), c[3])?;
    let new_pt = m::transform_vector(pt, &m::axis_rotate(axis, angle));
    for i in 0..3 {
        let mx = m::rotate(Axis::Z, i as f64 * 2.0 * PI / 3.0);
        let p = m::add(m::transform_vector(new_pt, &mx), [c[0], c[1], c[2]]);
        out.sphere(p, c[3])?;
    }
    Ok(())
}

/// The SPD's original hash of a grid position, with GCC/x86-64 shift
/// semantics for out-of-range counts.
fn hash_rand(a: i64, b: i64, c: u32) -> i64 {
    let sh = |v: i64, n: i32| (v as u64).wrapping_shl(n as u32);
    let c = c as i32;
    (sh(a, 23 - c)
        .wrapping_add(sh(b, 15 - c))
        .wrapping_add(sh(a, 7 - c))
        & 0xffff) as i64
}

/// The SPD's portable Gaussian deviate (Numerical Recipes' GASDEV over a
/// small linear congruential generator).
fn gauss_rand(seed: i64) -> f64 {
    const M1: i64 = 134456;
    const IA1: i64 = 8121;
    const IC1: i64 = 28411;
    let mut ix2 = seed;
    loop {
        let ix1 = (IC1 + ix2 * IA1) % M1;
        ix2 = (IC1 + ix1 * IA1) % M1;
        let v1 = ix1 as f64 * 2.0 * 1.0 / M1 as f64 - 1.0;
        let v2 = ix2 as f64 * 2.0 * 1.0 / M1 as f64 - 1.0;
        let r = v1 * v1 + v2 * v2;
        if r < 1.0 {
            let fac = (-2.0 * r.ln() / r).sqrt();
            return v1 * fac;
        }
    }
}

struct Grower<'o, 'a> {
    out: &'o mut Out<'a>,
    fnum_pts: f64,
    size: u32,
    roughness: f64,
}

impl Grower<'_, '_> {
    /// Heights are `[lower-left, lower-right, upper-right, upper-left]`.
    fn grow(&mut self, width: i64, llx: i64, lly: i64, z: [f64; 4]) -> Result<(), Error> {
        let [ll, lr, ur, ul] = z;
        if width == 1 {
            let lx = CORNER + llx as f64 * WIDTH / self.fnum_pts;
            let rx = CORNER + (llx + 1) as f64 * WIDTH / self.fnum_pts;
            let ly = CORNER + lly as f64 * WIDTH / self.fnum_pts;
            let uy = CORNER + (lly + 1) as f64 * WIDTH / self.fnum_pts;
            let corner = |k: usize| match k {
                0 => [lx, ly, ll],
                1 => [rx, ly, lr],
                2 => [rx, uy, ur],
                _ => [lx, uy, ul],
            };
            for tri in 0..2 {
                let v = [0, 1, 2].map(|i| corner((i + tri * 2) % 4));
                self.out.polygon(&v)?;
            }
            return Ok(());
        }
        let half = width >> 1;
        let hside = half as f64 * WIDTH / self.fnum_pts;
        let rise = hside * self.roughness;
        let sf = self.size;
        let r = |a: i64, b: i64| gauss_rand(MOUNTAIN_NO + hash_rand(a, b, sf));
        let lower = (ll + lr) / 2.0 + rise * r(llx + half, lly);
        let right = (lr + ur) / 2.0 + rise * r(llx + width, lly + half);
        let upper = (ur + ul) / 2.0 + rise * r(llx + half, lly + width);
        let left = (ul + ll) / 2.0 + rise * r(llx, lly + half);
        // The SPD's literal, not sqrt(2) to full precision.
        #[allow(clippy::approx_constant)]
        let middle = (ll + lr + ur + ul) / 4.0 + 1.4142136 * rise * r(llx + half, lly + half);
        self.grow(half, llx, lly, [ll, lower, middle, left])?;
        self.grow(half, llx + half, lly, [lower, lr, right, middle])?;
        self.grow(half, llx + half, lly + half, [middle, right, ur, upper])?;
        self.grow(half, llx, lly + half, [left, middle, upper, ul])
    }
}
