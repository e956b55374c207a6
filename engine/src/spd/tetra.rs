//! Recursive tetrahedral pyramid (Sierpinski tetrahedron) of 4^size
//! triangles; one light.

use super::out::Out;
use crate::error::Error;

pub fn generate(out: &mut Out, size: u32) -> Result<(), Error> {
    out.background(super::SKY)?;
    out.viewpoint(
        [1.022846, -3.177154, -2.174512],
        [-0.004103, -0.004103, 0.216539],
        [-0.816497, -0.816497, 0.816497],
        45.0,
        1.0,
        [512, 512],
    )?;
    out.light([2.0, -18.0, -5.0])?;
    out.color([1.0, 0.2, 0.2], 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0)?;
    tetra(out, size, [0.0, 0.0, 0.0, 1.0])
}

/// The corners (+-1, +-1, +-1) with an even number of minus signs, in the
/// SPD's loop order.
const CORNERS: [[f64; 3]; 4] = [
    [-1.0, -1.0, 1.0],
    [-1.0, 1.0, -1.0],
    [1.0, -1.0, -1.0],
    [1.0, 1.0, 1.0],
];

/// `c` is (x, y, z, half-size of the enclosing cube).
fn tetra(out: &mut Out, depth: u32, c: [f64; 4]) -> Result<(), Error> {
    if depth <= 1 {
        let pts = CORNERS.map(|d| [c[0] + d[0] * c[3], c[1] + d[1] * c[3], c[2] + d[2] * c[3]]);
        for face in 0..4 {
            let mut ord = [face % 4, (face + 1) % 4, (face + 2) % 4];
            if face % 2 == 1 {
                ord.swap(0, 2);
            }
            out.polygon(&ord.map(|i| pts[i]))?;
        }
        return Ok(());
    }
    for d in CORNERS {
        let sub = [
            c[0] + d[0] * c[3] / 2.0,
            c[1] + d[1] * c[3] / 2.0,
            c[2] + d[2] * c[3] / 2.0,
            c[3] / 2.0,
        ];
        tetra(out, depth - 1, sub)?;
    }
    Ok(())
}
