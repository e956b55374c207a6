//! Sphereflake: a sphere with nine children of a third its radius on each
//! sphere, recursively, over a square floor; three lights.

use super::matrix::{self as m, Axis, PI};
use super::out::Out;
use crate::error::Error;

pub fn generate(out: &mut Out, size: u32) -> Result<(), Error> {
    out.background(super::SKY)?;
    out.viewpoint(
        [2.1, 1.3, 1.7],
        [0.0; 3],
        [0.0, 0.0, 1.0],
        45.0,
        0.01,
        [512, 512],
    )?;
    out.light([4.0, 3.0, 2.0])?;
    out.light([1.0, -4.0, 4.0])?;
    out.light([-3.0, 1.0, 5.0])?;

    let radius = 1.0;
    out.color([1.0, 0.75, 0.33], 0.2, 0.8, 0.0, 0.0, 0.0, 0.0, 1.0)?;
    let (bx, by, bz) = (12.0 * radius, 12.0 * radius, -radius / 2.0);
    out.polygon(&[[bx, by, bz], [-bx, by, bz], [-bx, -by, bz], [bx, -by, bz]])?;

    out.color([1.0, 0.9, 0.7], 0.0, 0.5, 0.5, 0.5, 37.0, 0.0, 1.0)?;
    let set = child_directions();
    flake(
        out,
        &set,
        size,
        [0.0, 0.0, 0.0, radius / 2.0],
        [0.0, 0.0, 1.0, 1.0 / 3.0],
    )
}

/// The nine unit directions, relative to +Z, at which children sit: three
/// trios rotated 120 degrees apart about Z.
fn child_directions() -> [[f64; 4]; 9] {
    let dist = 1.0 / 2.0f64.sqrt();
    let mut trio = [
        [dist, dist, 0.0, 0.0],
        [dist, 0.0, -dist, 0.0],
        [0.0, dist, -dist, 0.0],
    ];
    let mut axis = [1.0, -1.0, 0.0];
    m::normalize(&mut axis);
    let mx = m::axis_rotate(axis, (2.0 / 6.0f64.sqrt()).asin());
    for t in &mut trio {
        *t = m::transform_coord(*t, &mx);
    }
    let mut set = [[0.0; 4]; 9];
    for s in 0..3 {
        let mx = m::rotate(Axis::Z, s as f64 * 2.0 * PI / 3.0);
        for v in 0..3 {
            set[s * 3 + v] = m::transform_coord(trio[v], &mx);
        }
    }
    set
}

/// `center` is (x, y, z, radius); `dir` is the unit direction from the
/// parent and, in w, the child/parent radius ratio.
fn flake(
    out: &mut Out,
    set: &[[f64; 4]; 9],
    depth: u32,
    center: [f64; 4],
    dir: [f64; 4],
) -> Result<(), Error> {
    out.sphere([center[0], center[1], center[2]], center[3])?;
    if depth == 0 {
        return Ok(());
    }
    let mx = if dir[2] >= 0.9999 {
        m::identity()
    } else if dir[2] <= -0.9999 {
        m::rotate(Axis::Y, PI)
    } else {
        let z = [0.0, 0.0, 1.0];
        let d = [dir[0], dir[1], dir[2]];
        let mut axis = m::cross(z, d);
        m::normalize(&mut axis);
        m::axis_rotate(axis, m::dot(z, d).acos())
    };
    let scale = center[3] * (1.0 + dir[3]);
    for s in set {
        let mut child = m::transform_coord(*s, &mx);
        for i in 0..3 {
            child[i] = child[i] * scale + center[i];
        }
        child[3] = center[3] * dir[3];
        let mut child_dir = [0.0; 4];
        for i in 0..3 {
            child_dir[i] = (child[i] - center[i]) / scale;
        }
        child_dir[3] = dir[3];
        flake(out, set, depth - 1, child, child_dir)?;
    }
    Ok(())
}
