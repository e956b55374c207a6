//! A pyramid of objects, each six pentagonal rings (30 cylinders, 30
//! spheres) joining the edge midpoints of a dodecahedron, seen from the
//! pyramid's point; a wall behind for shadows; three lights.

use super::matrix::{self as m, Axis, PI};
use super::out::Out;
use crate::error::Error;

const SPREAD_OUT: f64 = 1.0;

pub fn generate(out: &mut Out, size: u32) -> Result<(), Error> {
    let radius = 0.07412; // of cylinders and spheres
    let spread = 1.0 / (PI / 8.0).sin();
    let (y_diff, xz_diff) = if SPREAD_OUT <= spread {
        (spread / SPREAD_OUT, 1.0)
    } else {
        (1.0, SPREAD_OUT / spread)
    };

    out.background(super::SKY)?;
    let from = [-1.0, -spread, 0.5];
    let at = [from[0], from[1] + 1.0, from[2]];
    out.viewpoint(from, at, [0.0, 0.0, 1.0], 45.0, 1.0, [512, 512])?;
    out.light([3.0, -spread, 3.0])?;
    out.light([-4.0, -spread, 1.0])?;
    out.light([2.0, -spread, -4.0])?;

    // The wall just spans the 45 degree view, plus 1%.
    out.color([1.0, 1.0, 1.0], 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0)?;
    let wy = y_diff * (size + 1) as f64;
    let wx = 1.01 * (wy - from[1]) * (PI / 8.0).tan();
    let wz = wx;
    out.polygon(&[
        [wx + from[0], wy, wz + from[2]],
        [-wx + from[0], wy, wz + from[2]],
        [-wx + from[0], wy, -wz + from[2]],
        [wx + from[0], wy, -wz + from[2]],
    ])?;

    const COLORS: [[f64; 3]; 6] = [
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
        [0.0, 1.0, 1.0],
        [1.0, 0.0, 1.0],
        [1.0, 1.0, 0.0],
    ];
    let dodec = dodecahedron(radius);
    for depth in 0..size as i64 {
        let oy = y_diff * (depth + 1) as f64;
        for oz_i in 0..=depth {
            let oz = xz_diff * (2 * oz_i - depth) as f64;
            for ox_i in 0..=depth {
                let ox = xz_diff * (2 * ox_i - depth) as f64;
                let offset = [ox, oy, oz];
                for elem in 0..30 {
                    let base = m::add(dodec[elem], offset);
                    let prev = if elem % 5 == 0 {
                        out.color(COLORS[elem / 5], 0.0, 0.5, 0.2, 0.3, 37.0, 0.0, 0.0)?;
                        elem + 4
                    } else {
                        elem - 1
                    };
                    let apex = m::add(dodec[prev], offset);
                    out.cylcone(base, radius, apex, radius)?;
                    out.sphere(base, radius)?;
                }
            }
        }
    }
    Ok(())
}

/// The 30 ring points: one pentagon in the XY plane, and five copies
/// tilted by the dodecahedron's dihedral angle and turned about Z.
fn dodecahedron(minor_radius: f64) -> [[f64; 3]; 30] {
    let scale = 1.0 / (1.0 + minor_radius);
    let mut v = [[0.0; 3]; 30];
    for (i, p) in v.iter_mut().enumerate().take(5) {
        let a = i as f64 * 2.0 * PI / 5.0;
        *p = [scale * a.cos(), scale * a.sin(), 0.0];
    }
    let x_rot = 2.0 * ((PI / 3.0).cos() / (PI / 5.0).sin()).acos();
    let xm = m::rotate(Axis::X, x_rot);
    for p in 1..6 {
        let z_rot = PI * (2.0 * (p - 1) as f64 + 1.0) / 5.0;
        let zm = m::rotate(Axis::Z, z_rot);
        for i in 0..5 {
            let t = m::transform_point(v[i], &xm);
            v[5 * p + i] = m::transform_point(t, &zm);
        }
    }
    v
}
