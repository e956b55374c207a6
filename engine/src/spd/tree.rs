//! A tree after Aono and Kunii: each branch a cone capped by a sphere,
//! forking twice per level; a square field below; seven lights.

use super::matrix::{self as m, Axis, Mat4, PI};
use super::out::Out;
use crate::error::Error;

const BR_ANGLE: [f64; 2] = [40.0, 25.0];
const BR_CONTRACTION: [f64; 2] = [0.65, 0.70];
const BR_DIAMETER: f64 = 0.67;
const DIV_ANGLE: f64 = 140.0;
const WIDTH_HEIGHT_RATIO: f64 = 0.15;

pub fn generate(out: &mut Out, size: u32) -> Result<(), Error> {
    out.background(super::SKY)?;
    out.viewpoint(
        [4.5, 0.4, 2.0],
        [0.0, 0.0, 1.5],
        [0.0, 0.0, 1.0],
        45.0,
        1.0,
        [512, 512],
    )?;
    for l in [
        [-5.0, 5.0, 50.0],
        [30.0, -30.0, 30.0],
        [-40.0, -30.0, 20.0],
        [10.0, 30.0, 40.0],
        [-30.0, 40.0, 10.0],
        [50.0, 25.0, 20.0],
        [-10.0, -60.0, 30.0],
    ] {
        out.light(l)?;
    }
    out.color([0.2, 0.7, 0.2], 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0)?;
    out.polygon(&[
        [50.0, 50.0, 0.0],
        [-50.0, 50.0, 0.0],
        [-50.0, -50.0, 0.0],
        [50.0, -50.0, 0.0],
    ])?;
    out.color([0.55, 0.4, 0.2], 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0)?;

    // Each child branch: rotate about X by its branching angle, about Z by
    // its divergence, then contract and move to the parent's tip.
    let mut growth = [m::identity(); 2];
    for i in 0..2 {
        let divergence = if i == 0 { 90.0 } else { DIV_ANGLE + 90.0 };
        let r = m::multiply(
            &m::rotate(Axis::X, BR_ANGLE[i] * PI / 180.0),
            &m::rotate(Axis::Z, divergence * PI / 180.0),
        );
        let mut st = m::identity();
        st[0][0] = BR_CONTRACTION[i];
        st[1][1] = BR_CONTRACTION[i];
        st[2][2] = BR_CONTRACTION[i];
        st[3][2] = 1.0;
        growth[i] = m::multiply(&r, &st);
    }
    branch(out, &growth, &m::identity(), 1.0, size)
}

fn branch(
    out: &mut Out,
    growth: &[Mat4; 2],
    cur: &Mat4,
    scale: f64,
    depth: u32,
) -> Result<(), Error> {
    let base = m::transform_point([0.0, 0.0, 0.0], cur);
    let base_r = scale * WIDTH_HEIGHT_RATIO;
    let apex = m::transform_point([0.0, 0.0, 1.0], cur);
    let apex_r = base_r * BR_DIAMETER;
    out.cylcone(base, base_r, apex, apex_r)?;
    out.sphere(apex, apex_r)?;
    if depth > 0 {
        for g in growth {
            branch(
                out,
                growth,
                &m::multiply(g, cur),
                scale * BR_DIAMETER,
                depth - 1,
            )?;
        }
    }
    Ok(())
}
