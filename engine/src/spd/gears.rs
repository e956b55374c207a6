//! A cube of size^3 meshing gears; each gear is two concave 144-gons and
//! 144 side rectangles. Reflective ground square, five lights.

use super::matrix::{self as m, Axis, PI};
use super::out::Out;
use crate::error::Error;

const TEETH: usize = 36;
const OUTER_EDGE_RATIO: f64 = 0.995;
const INNER_EDGE_RATIO: f64 = 0.9;
const DEPTH_RATIO: f64 = 0.1;

/// `1.0 - INNER_EDGE_RATIO`, kept as the SPD computes it.
fn edge_diff() -> f64 {
    1.0 - INNER_EDGE_RATIO
}

pub fn generate(out: &mut Out, size: u32) -> Result<(), Error> {
    out.background(super::SKY)?;
    out.viewpoint(
        [-1.1, -2.1, 2.6],
        [0.0; 3],
        [0.0, 0.0, 1.0],
        45.0,
        1.0,
        [512, 512],
    )?;
    out.light([2.0, 4.0, 4.0])?;
    out.light([-2.0, 4.0, 3.0])?;
    out.light([2.0, -2.5, 2.5])?;
    out.light([-1.0, -4.0, 2.0])?;
    out.light([-1.111, -2.121, 2.626])?; // just behind the eye

    out.color([1.0, 0.85, 0.7], 0.0, 0.3, 0.6, 0.3, 37.0, 0.0, 0.0)?;
    out.polygon(&[
        [2.0, 2.0, 0.0],
        [-2.0, 2.0, 0.0],
        [-2.0, -2.0, 0.0],
        [2.0, -2.0, 0.0],
    ])?;

    let sf = size as f64;
    let outer_radius = 1.0 / (sf - (size - 1) as f64 * edge_diff() / 2.0);
    let zero = [-1.0 + outer_radius, -1.0 + outer_radius, 1.0];
    let step = outer_radius * (2.0 - edge_diff());
    let offset = [step, step, -1.0 / sf];
    let n = size as usize;
    for iz in 0..n {
        let cz = zero[2] + iz as f64 * offset[2];
        for iy in 0..n {
            let cy = zero[1] + iy as f64 * offset[1];
            for ix in 0..n {
                let cx = zero[0] + ix as f64 * offset[0];
                let frac = |a: f64| a - (a as i32) as f64;
                let mut c = [
                    0.01 + frac((ix * 3 + iy * 2 + iz + 1) as f64 * 5.0 / 7.0),
                    0.01 + frac((iy * 3 + iz * 2 + ix + 1) as f64 * 3.0 / 7.0),
                    0.01 + frac((iz * 3 + ix * 2 + iy + 1) as f64 * 2.0 / 7.0),
                ];
                let mut scale = if c[0] > c[1] { c[0] } else { c[1] };
                scale = if scale > c[2] { scale } else { c[2] };
                for x in &mut c {
                    *x /= scale;
                }
                if (ix * 4 + iy * 2 + iz) % 5 == 0 {
                    out.color(c, 0.0, 0.2, 0.0, 0.0, 0.0, 0.8, 1.1)?;
                } else {
                    out.color(c, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0)?;
                }
                let angle = PI * ((ix + iy + iz) % 2) as f64 / TEETH as f64;
                let half = 1.0 / (2.0 * sf);
                let thickness = if DEPTH_RATIO < half {
                    DEPTH_RATIO
                } else {
                    half
                };
                gear(
                    out,
                    [cx, cy, cz],
                    angle,
                    OUTER_EDGE_RATIO * outer_radius,
                    (1.0 - edge_diff()) * outer_radius,
                    thickness,
                )?;
            }
        }
    }
    Ok(())
}

/// The four outline points of one tooth.
fn tooth(
    angle: f64,
    tooth_angle: f64,
    center: [f64; 3],
    outer: [f64; 3],
    inner: [f64; 3],
    pts: &mut [[f64; 3]],
) {
    let place =
        |a: f64, p: [f64; 3]| m::add(m::transform_vector(p, &m::rotate(Axis::Z, a)), center);
    pts[0] = place(angle - 0.19 * tooth_angle, outer);
    pts[1] = place(angle + 0.19 * tooth_angle, outer);
    pts[2] = place(angle + 0.3 * tooth_angle, inner);
    pts[3] = place(angle + 0.7 * tooth_angle, inner);
}

fn gear(
    out: &mut Out,
    center: [f64; 3],
    offset: f64,
    outer_r: f64,
    inner_r: f64,
    thickness: f64,
) -> Result<(), Error> {
    let mut outer = [outer_r, 0.0, 0.0];
    let mut inner = [inner_r, 0.0, 0.0];
    let tooth_angle = 2.0 * PI / TEETH as f64;
    let mut pts = [[0.0; 3]; 4 * TEETH];
    for t in 0..TEETH {
        let a = offset + 2.0 * PI * t as f64 / TEETH as f64;
        tooth(
            a,
            tooth_angle,
            center,
            outer,
            inner,
            &mut pts[t * 4..t * 4 + 4],
        );
    }
    out.polygon(&pts)?;
    for s in 0..4 * TEETH {
        let next = (s + 1) % (4 * TEETH);
        let mut side = [pts[s], pts[s], pts[next], pts[next]];
        side[1][2] -= thickness;
        side[2][2] -= thickness;
        out.polygon(&side)?;
    }
    outer[2] = -thickness;
    inner[2] = -thickness;
    for t in 0..TEETH {
        let a = offset - 2.0 * PI * t as f64 / TEETH as f64;
        tooth(
            a,
            -tooth_angle,
            center,
            outer,
            inner,
            &mut pts[t * 4..t * 4 + 4],
        );
    }
    out.polygon(&pts)
}
