//! The Utah teapot tessellated into smoothly shaded triangles (size^2
//! quads of two triangles per patch), standing on a size x size
//! checkerboard; two lights.

use super::matrix::{self as m, Mat4};
use super::out::Out;
use super::teapot_data::{PATCHES, VERTS};
use crate::error::Error;

pub fn generate(out: &mut Out, size: u32) -> Result<(), Error> {
    out.background(super::SKY)?;
    out.viewpoint(
        [4.86, 7.2, 5.4],
        [0.0; 3],
        [0.0, 0.0, 1.0],
        45.0,
        1.0,
        [512, 512],
    )?;
    out.light([-3.1, 9.8, 12.1])?;
    out.light([11.3, 5.1, 8.8])?;
    checkerboard(out, size)?;
    teapot(out, size)
}

fn square(size: u32, s: u32, t: u32) -> [[f64; 3]; 4] {
    let sf = size as f64;
    let mut v = [[0.0; 3]; 4];
    for (i, p) in v.iter_mut().enumerate() {
        // Vertices 0 and 3 are low in x, 1 and 2 high; 0 and 1 low in y.
        let ds = if i % 3 != 0 { 1 } else { 0 };
        let dt = if i / 2 != 0 { 1 } else { 0 };
        p[0] = 4.0 * (2.0 * (s + ds) as f64 / sf - 1.0);
        p[1] = 4.0 * (2.0 * (t + dt) as f64 / sf - 1.0);
        p[2] = 0.0;
    }
    v
}

fn checkerboard(out: &mut Out, size: u32) -> Result<(), Error> {
    for (color, odd) in [([1.0, 1.0, 1.0], true), ([0.5, 0.5, 0.5], false)] {
        out.color(color, 0.0, 0.5, 0.5, 0.5, 30.0, 0.0, 0.0)?;
        for s in 0..size {
            for t in 0..size {
                if ((s + t) % 2 == 1) == odd {
                    out.polygon(&square(size, s, t))?;
                }
            }
        }
    }
    Ok(())
}

/// The Bezier basis matrix.
const BEZIER: Mat4 = [
    [-1.0, 3.0, -3.0, 1.0],
    [3.0, -6.0, 3.0, 0.0],
    [-3.0, 3.0, 0.0, 0.0],
    [1.0, 0.0, 0.0, 0.0],
];

fn teapot(out: &mut Out, size: u32) -> Result<(), Error> {
    out.color([1.0, 0.5, 0.1], 0.0, 0.75, 0.25, 0.25, 37.0, 0.0, 0.0)?;
    let bt = m::transpose(&BEZIER);
    let sf = size as f64;
    for patch in &PATCHES {
        // M G M^T for each of x, y, z.
        let mut mgm = [m::zero(); 3];
        for (i, out_m) in mgm.iter_mut().enumerate() {
            let mut g = m::zero();
            for r in 0..4 {
                for c in 0..4 {
                    g[r][c] = VERTS[patch[r * 4 + c] as usize][i];
                }
            }
            *out_m = m::multiply(&m::multiply(&BEZIER, &g), &bt);
        }
        for s in 0..size {
            for t in 0..size {
                for tri in 0..2 {
                    let mut st = [[0.0; 2]; 3];
                    for (v, p) in st.iter_mut().enumerate() {
                        let k = (v + tri * 2) % 4;
                        p[0] = (s + if k / 2 != 0 { 1 } else { 0 }) as f64 / sf;
                        p[1] = (t + if k % 3 != 0 { 1 } else { 0 }) as f64 / sf;
                    }
                    let (vert, mut norm) = evaluate(&mgm, &st);
                    if keep_triangle(&vert, &mut norm) {
                        out.polypatch(&vert, &norm)?;
                    }
                }
            }
        }
    }
    Ok(())
}

/// Points and unit normals of the patch at three (s, t) parameters.
fn evaluate(mgm: &[Mat4; 3], st: &[[f64; 2]; 3]) -> ([[f64; 3]; 3], [[f64; 3]; 3]) {
    let mut vert = [[0.0; 3]; 3];
    let mut norm = [[0.0; 3]; 3];
    for v in 0..3 {
        let (s, t) = (st[v][0], st[v][1]);
        // Power vectors (s^3, s^2, s, 1) and their derivatives.
        let (mut sp, mut tp, mut dsp, mut dtp) = ([0.0; 4], [0.0; 4], [0.0; 4], [0.0; 4]);
        let (mut sval, mut tval) = (1.0, 1.0);
        let (mut dsval, mut dtval) = (0.0, 0.0);
        for p in (0..4).rev() {
            sp[p] = sval;
            tp[p] = tval;
            sval *= s;
            tval *= t;
            if p == 3 {
                dsp[p] = 0.0;
                dtp[p] = 0.0;
                dsval = 1.0;
                dtval = 1.0;
            } else {
                dsp[p] = dsval * (3 - p) as f64;
                dtp[p] = dtval * (3 - p) as f64;
                dsval *= s;
                dtval *= t;
            }
        }
        let dot4 = |a: [f64; 4], b: [f64; 4]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3];
        let (mut sdir, mut tdir) = ([0.0; 3], [0.0; 3]);
        for i in 0..3 {
            vert[v][i] = dot4(m::transform_coord(sp, &mgm[i]), tp);
            sdir[i] = dot4(m::transform_coord(dsp, &mgm[i]), tp);
            tdir[i] = dot4(m::transform_coord(sp, &mgm[i]), dtp);
        }
        norm[v] = m::cross(tdir, sdir);
        m::normalize(&mut norm[v]);
    }
    (vert, norm)
}

/// The lid's and the bottom's patches meet in a point on the Z axis. A
/// triangle with two vertices there is degenerate and dropped; one with a
/// single vertex there gets the axis as that vertex's normal.
fn keep_triangle(vert: &[[f64; 3]; 3], norm: &mut [[f64; 3]; 3]) -> bool {
    let mut count = 0;
    let mut at = 0;
    for i in (0..3).rev() {
        if vert[i][0].abs() <= 0.0001 && vert[i][1].abs() <= 0.0001 {
            count += 1;
            at = i;
        }
    }
    if count > 1 {
        return false;
    }
    if count == 1 {
        norm[at] = if vert[at][2] > 1.5 {
            [0.0, 0.0, 1.0]
        } else {
            [0.0, 0.0, -1.0]
        };
    }
    true
}
