//! Local shading and the rays a hit spawns, as `docs/rendering-contract.md`
//! ("Shading a hit") states them: one function for every tracer, so every
//! tracer computes the same colours from the same hits.

use crate::intersect::Surface;
use crate::math::Vec3;
use crate::scene::{Material, SceneHeader};

/// What shading needs to know about the scene.
#[derive(Clone, Debug)]
pub struct ShadeScene {
    pub lights: Vec<(Vec3, [f32; 3])>,
    pub background: [f32; 3],
    pub max_depth: u8,
    /// Secondary and shadow rays ignore hits closer than this.
    pub eps: f64,
}

impl ShadeScene {
    pub fn new(h: &SceneHeader, max_depth: u8, eps: f64) -> ShadeScene {
        let n = h.lights.len();
        ShadeScene {
            lights: h
                .lights
                .iter()
                .map(|l| (Vec3::from_array(l.position), l.resolved_color(n)))
                .collect(),
            background: h.background,
            max_depth,
            eps,
        }
    }

    /// The colour a ray of weight `weight` brings back when it hits nothing.
    #[inline]
    pub fn background(&self, weight: f32) -> [f32; 3] {
        self.background.map(|c| c * weight)
    }
}

/// A ray a hit spawns, in the order they are spawned: one shadow ray per
/// light the surface faces, then reflection, then refraction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Spawn {
    /// Toward light `light`, `dist` away. `color` is what the light adds if
    /// nothing blocks it (already weighted).
    Shadow {
        light: u32,
        dir: Vec3,
        dist: f64,
        color: [f32; 3],
    },
    Reflect {
        dir: Vec3,
        weight: f32,
    },
    Refract {
        dir: Vec3,
        weight: f32,
    },
}

/// Shades a hit of a ray of direction `d` (unit), tree depth `depth` (eye
/// ray = 1) and weight `weight` on surface `s` of material `m`, calling
/// `emit` for each spawned ray. Spawned rays start at `s.p`.
///
/// - The shading normal is turned toward the incoming ray.
/// - A light the surface faces (N.L > 0) gets a shadow ray carrying
///   I * (Kd (N.L) C + Ks max(0, R.L)^Shine), R the mirror direction.
/// - Below the maximum depth: Ks > 0 spawns a reflection ray of weight Ks;
///   T > 0 spawns a refraction ray of weight T (Snell's law, entering when
///   the ray opposes the geometric normal); on total internal reflection
///   the refraction becomes a reflection of weight Ks + T instead.
/// - Colours are `f32`; geometry is `f64`.
#[inline]
pub fn shade(
    sc: &ShadeScene,
    d: Vec3,
    depth: u8,
    weight: f32,
    s: &Surface,
    m: &Material,
    emit: &mut impl FnMut(Spawn),
) {
    let n = if s.ns.dot(d) > 0.0 { -s.ns } else { s.ns };
    let dn = d.dot(n);
    let mirror = (d - n * (2.0 * dn)).try_normalize();
    for (i, (pos, color)) in sc.lights.iter().enumerate() {
        let to = *pos - s.p;
        let dist = to.length();
        if !(dist > 0.0) {
            continue;
        }
        let l = to * (1.0 / dist);
        let ndotl = n.dot(l);
        if !(ndotl > 0.0) {
            continue;
        }
        let spec = match mirror {
            Some(r) if m.ks > 0.0 => {
                let rl = r.dot(l);
                if rl > 0.0 {
                    rl.powf(m.shine as f64) as f32
                } else {
                    0.0
                }
            }
            _ => 0.0,
        };
        let ndotl = ndotl as f32;
        let mut c = [0f32; 3];
        for k in 0..3 {
            c[k] = color[k] * (m.kd * ndotl * m.color[k] + m.ks * spec) * weight;
        }
        emit(Spawn::Shadow {
            light: i as u32,
            dir: l,
            dist,
            color: c,
        });
    }
    if depth >= sc.max_depth {
        return;
    }
    let Some(r) = mirror else { return };
    if m.t > 0.0 {
        let entering = d.dot(s.ng) < 0.0;
        let ior = if m.ior > 0.0 { m.ior as f64 } else { 1.0 };
        let eta = if entering { 1.0 / ior } else { ior };
        let cos_i = -dn;
        let k = 1.0 - eta * eta * (1.0 - cos_i * cos_i);
        if k < 0.0 {
            emit(Spawn::Reflect {
                dir: r,
                weight: weight * (m.ks + m.t),
            });
            return;
        }
        if m.ks > 0.0 {
            emit(Spawn::Reflect {
                dir: r,
                weight: weight * m.ks,
            });
        }
        if let Some(t) = (d * eta + n * (eta * cos_i - k.sqrt())).try_normalize() {
            emit(Spawn::Refract {
                dir: t,
                weight: weight * m.t,
            });
        }
    } else if m.ks > 0.0 {
        emit(Spawn::Reflect {
            dir: r,
            weight: weight * m.ks,
        });
    }
}
