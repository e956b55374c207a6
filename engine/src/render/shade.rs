//! Local shading and the rays a hit spawns, as `docs/rendering-contract.md`
//! ("Shading a hit") states them: one function for every tracer, so every
//! tracer computes the same colours from the same hits.

use crate::error::Error;
use crate::intersect::Surface;
use crate::math::Vec3;
use crate::scene::{
    ImageData, LightKind, Maps, Material, Pbr, Photometric, SceneHeader, TextureBinding,
};
use crate::sdb::Database;
use crate::texture::mip::TILE_BYTES;
use crate::texture::{Encoding, Texture};
use std::sync::Arc;

/// A light as shading sees it: its position in the geometry's frame, its
/// colour (resolved, see [`crate::scene::Light::resolved_color`]) and,
/// for a glTF light, its photometry.
#[derive(Clone, Copy, Debug)]
pub struct ShadeLight {
    pub position: Vec3,
    pub color: [f32; 3],
    pub photometric: Option<Photometric>,
}

/// What shading needs to know about the scene.
#[derive(Clone, Debug)]
pub struct ShadeScene {
    pub lights: Vec<ShadeLight>,
    pub background: [f32; 3],
    pub max_depth: u8,
    /// Secondary and shadow rays ignore hits closer than this.
    pub eps: f64,
    /// The scene's images (base colour textures: sRGB).
    pub textures: Arc<[Texture]>,
    /// Where the eye is and how wide a pixel is, to pick mip levels;
    /// without it every lookup reads the finest level.
    pub footprint: Option<Footprint>,
}

/// What the camera says of the width of a ray's footprint: `spread`
/// times the distance from `eye`, the width of the eye ray's pixel there
/// (a lower bound for any ray whose path started at the eye, since a path
/// is no shorter than the straight line back to the eye).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Footprint {
    pub eye: Vec3,
    /// A pixel's width at unit distance.
    pub spread: f64,
}

impl Footprint {
    /// The footprint of `camera`'s pixels: the view angle spans the
    /// image's longer side.
    pub fn of(view: &crate::scene::View, width: u32, height: u32) -> Footprint {
        let long = width.max(height).max(1) as f64;
        Footprint {
            eye: Vec3::from_array(view.from),
            spread: 2.0 * (view.angle.to_radians() / 2.0).tan() / long,
        }
    }
}

impl ShadeScene {
    /// What shading needs of `h`; its images are decoded here (an image
    /// that does not decode is an error naming it). A database's tiled
    /// images are read from it: see [`ShadeScene::with_textures`].
    pub fn new(h: &SceneHeader, max_depth: u8, eps: f64) -> Result<ShadeScene, Error> {
        let textures = h
            .textures
            .iter()
            .map(|t| match &t.data {
                ImageData::Encoded(bytes) => Texture::decode(bytes, &t.name, Encoding::Srgb),
                ImageData::Tiled(_) => Err(Error::Scene(format!(
                    "{}: a tiled image is read from its database",
                    t.name
                ))),
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self::with_textures(h, max_depth, eps, textures.into()))
    }

    /// What shading needs of database `db` for a render within `memory`
    /// bytes, and the bytes its textures may hold: images stored whole
    /// (version 8) decoded, tiled ones (version 9) read through a cache
    /// of an eighth of the memory (no more than they take), so that
    /// textures larger than the memory are read a tile at a time.
    pub fn open(
        db: &Database,
        max_depth: u8,
        eps: f64,
        memory: u64,
    ) -> Result<(ShadeScene, u64), Error> {
        let tiled: u64 = db
            .scene()
            .textures
            .iter()
            .map(|t| match &t.data {
                ImageData::Tiled(t) => t.tiles.len() as u64 * TILE_BYTES as u64,
                ImageData::Encoded(_) => 0,
            })
            .sum();
        let cache = tiled.min((memory / 8).max(16 * TILE_BYTES as u64));
        let textures = db.textures(cache)?;
        let held: u64 = textures.iter().map(|t| t.bytes() as u64).sum();
        let sc = Self::with_textures(db.scene(), max_depth, eps, textures);
        Ok((
            sc,
            held + if tiled > 0 {
                cache.max(16 * TILE_BYTES as u64)
            } else {
                0
            },
        ))
    }

    /// The first texture tile a render could not read, if any: shading
    /// went on with zero texels, so the render must fail with it.
    pub fn texture_error(&self) -> Option<Error> {
        self.textures.iter().find_map(|t| t.store_error())
    }

    /// Tiles read so far by every texture (they share one store); `None`
    /// when no texture is read from a database.
    pub fn tile_reads(&self) -> Option<crate::texture::TileReads> {
        self.textures.iter().find_map(|t| t.store_reads())
    }

    /// What shading needs of `h`, whose images are `textures`.
    pub fn with_textures(
        h: &SceneHeader,
        max_depth: u8,
        eps: f64,
        textures: Arc<[Texture]>,
    ) -> ShadeScene {
        let n = h.lights.len();
        ShadeScene {
            lights: h
                .lights
                .iter()
                .map(|l| ShadeLight {
                    position: Vec3::from_array(l.position),
                    color: l.resolved_color(n),
                    photometric: l.photometric,
                })
                .collect(),
            background: h.background,
            max_depth,
            eps,
            textures,
            footprint: None,
        }
    }

    /// The mip level of `tex` a lookup at surface `s` through binding `b`
    /// reads: the level whose texels match the pixel's footprint there.
    #[inline]
    pub fn level(&self, tex: &Texture, b: &TextureBinding, s: &Surface) -> usize {
        let Some(f) = self.footprint else {
            return 0;
        };
        let scale = b.transform.scale[0].abs().max(b.transform.scale[1].abs()) as f64;
        let texels = f.spread
            * (s.p - f.eye).length()
            * s.attrs.uv_per_length as f64
            * scale
            * tex.width.max(tex.height) as f64;
        tex.level_for(texels)
    }

    /// The texture a lookup at `s` with material `m` reads, and the tile
    /// it starts in (`None` when it reads none): hits are shaded in this
    /// order so that textures larger than memory are read tile by tile.
    pub fn tile_key(&self, m: &Material, s: &Surface) -> Option<(u32, u32)> {
        let (b, uv) = (m.texture?, s.attrs.uv?);
        let tex = self.textures.get(b.image as usize)?;
        let level = self.level(tex, &b, s);
        Some((
            b.image,
            tex.tile_of(&b.sampler, b.transform.apply(uv), level),
        ))
    }

    /// Material `m` as it looks at surface `s`: its colour times the base
    /// colour texture at the surface's texture coordinates and times the
    /// surface's vertex colour, its metallic, roughness and emission times
    /// their textures, and its shading normal from its normal map; `None`
    /// where nothing applies (the material and normal as they are).
    #[inline]
    pub fn look(&self, m: &Material, s: &Surface) -> Option<Look> {
        let uv = s.attrs.uv;
        let maps = uv.is_some() && (m.texture.is_some() || m.maps != Maps::NONE);
        if !maps && s.attrs.color.is_none() {
            return None;
        }
        let sample = |b: Option<TextureBinding>| -> Option<[f32; 4]> {
            let (b, uv) = (b?, uv?);
            let t = self.textures.get(b.image as usize)?;
            Some(t.sample_level(&b.sampler, b.transform.apply(uv), self.level(t, &b, s)))
        };
        let mut out = *m;
        let tex = sample(m.texture);
        for k in 0..3 {
            out.color[k] *= tex.map_or(1.0, |t| t[k]) * s.attrs.color.map_or(1.0, |c| c[k]);
        }
        let mut normal = None;
        if maps {
            if let Some(p) = out.pbr.as_mut() {
                if let Some(t) = sample(m.maps.metallic_roughness) {
                    p.roughness *= t[1];
                    p.metallic *= t[2];
                }
                if let Some(t) = sample(m.maps.emissive) {
                    for k in 0..3 {
                        p.emissive[k] *= t[k];
                    }
                }
            }
            if let (Some(b), Some(t)) = (m.maps.normal, sample(m.maps.normal)) {
                normal = mapped_normal(s, t, b.alpha);
            }
        }
        Some(Look {
            material: out,
            normal,
        })
    }

    /// The colour a ray of weight `weight` brings back when it hits nothing.
    #[inline]
    pub fn background(&self, weight: f32) -> [f32; 3] {
        self.background.map(|c| c * weight)
    }
}

/// A material as it looks at one point ([`ShadeScene::look`]).
#[derive(Clone, Copy, Debug)]
pub struct Look {
    pub material: Material,
    /// The shading normal a normal map gives, if one does.
    pub normal: Option<Vec3>,
}

/// The shading normal that normal-map texel `t` (RGB in [0, 1], glTF's
/// +X right, +Y up the image, +Z out of the surface) gives at `s`, its
/// X and Y scaled by `scale`: in the frame of the shading normal, the
/// tangent (dp/du made perpendicular to it) and their cross product.
/// `None` where the surface has no tangent.
fn mapped_normal(s: &Surface, t: [f32; 4], scale: f32) -> Option<Vec3> {
    let n = s.ns;
    let du = Vec3::from_array(s.attrs.tangent.map(|x| x as f64));
    let tangent = (du - n * n.dot(du)).try_normalize()?;
    let bitangent = n.cross(tangent);
    let x = (2.0 * t[0] as f64 - 1.0) * scale as f64;
    let y = (2.0 * t[1] as f64 - 1.0) * scale as f64;
    let z = 2.0 * t[2] as f64 - 1.0;
    (tangent * x + bitangent * y + n * z).try_normalize()
}

/// What a hit gives, in this order: its own emission, one shadow ray per
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
    /// Light the surface gives off itself (a glTF material's emissive
    /// colour, already weighted): added to the ray's pixel as it is.
    Emit {
        color: [f32; 3],
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
    let looked = sc.look(m, s);
    let m = looked.as_ref().map_or(m, |l| &l.material);
    let ns = looked.and_then(|l| l.normal).unwrap_or(s.ns);
    if let Some(p) = &m.pbr
        && p.emissive != [0.0; 3]
    {
        emit(Spawn::Emit {
            color: p.emissive.map(|e| e * weight),
        });
    }
    let n = if ns.dot(d) > 0.0 { -ns } else { ns };
    let dn = d.dot(n);
    let mirror = (d - n * (2.0 * dn)).try_normalize();
    for (i, light) in sc.lights.iter().enumerate() {
        if light.photometric.is_some() || m.pbr.is_some() {
            if let Some(spawn) = gltf_light(light, i as u32, d, n, s.p, weight, m) {
                emit(spawn);
            }
            continue;
        }
        let color = &light.color;
        let to = light.position - s.p;
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

/// What a light brings to a hit at `p` when glTF's model applies (the
/// light or the material is glTF's; NFF scenes never get here): the
/// shadow ray toward the light, or `None` where the surface faces away
/// from it or the light gives nothing there (beyond its range, outside
/// its cone), so that no shadow ray is spent on it.
///
/// - A `KHR_lights_punctual` light gives illuminance `intensity * colour`
///   (candela over the squared distance for point and spot lights, lux
///   for directional ones) times the range window `clamp(1 - (d/range)^4,
///   0, 1)` and, for a spot light, the cone's smooth falloff (both as the
///   extension's specification writes them). An NFF light (no
///   photometry) gives `pi * colour`, so that a white Lambert surface
///   looks as it does under NFF's model.
/// - A glTF material reflects it by the metallic-roughness BRDF of the
///   glTF specification's Appendix B (Lambert diffuse plus GGX specular,
///   Smith height-correlated visibility, Schlick Fresnel); an NFF
///   material under a glTF light keeps NFF's terms.
fn gltf_light(
    light: &ShadeLight,
    index: u32,
    d: Vec3,
    n: Vec3,
    p: Vec3,
    weight: f32,
    m: &Material,
) -> Option<Spawn> {
    let (l, dist, scale) = match light.photometric {
        None => {
            let to = light.position - p;
            let dist = to.length();
            (to * (1.0 / dist), dist, std::f64::consts::PI)
        }
        Some(ph) => match ph.kind {
            LightKind::Directional => {
                let l = -Vec3::from_array(ph.direction);
                (l, f64::INFINITY, ph.intensity as f64)
            }
            LightKind::Point | LightKind::Spot => {
                let to = light.position - p;
                let dist = to.length();
                let l = to * (1.0 / dist);
                let mut e = ph.intensity as f64 / (dist * dist);
                if let Some(range) = ph.range {
                    let r = dist / range as f64;
                    e *= (1.0 - r * r * r * r).clamp(0.0, 1.0);
                }
                if ph.kind == LightKind::Spot {
                    e *= spot_falloff(&ph, l);
                }
                (l, dist, e)
            }
        },
    };
    if !(dist > 0.0) || !(scale > 0.0) || !scale.is_finite() {
        return None;
    }
    let ndotl = n.dot(l);
    if !(ndotl > 0.0) {
        return None;
    }
    let f = match &m.pbr {
        Some(pbr) => brdf(pbr, m.color, n, -d, l, ndotl),
        None => {
            // NFF's terms, with the light's illuminance as its colour.
            let r = d - n * (2.0 * d.dot(n));
            let rl = r.try_normalize().map_or(0.0, |r| r.dot(l));
            let spec = if m.ks > 0.0 && rl > 0.0 {
                rl.powf(m.shine as f64)
            } else {
                0.0
            };
            let s = 1.0 / ndotl;
            m.color
                .map(|c| (m.kd as f64 * c as f64 + m.ks as f64 * spec * s) as f32)
        }
    };
    let k = (scale * ndotl) as f32;
    let mut color = [0f32; 3];
    for c in 0..3 {
        color[c] = light.color[c] * k * f[c] * weight;
    }
    Some(Spawn::Shadow {
        light: index,
        dir: l,
        dist,
        color,
    })
}

/// The spot cone's falloff toward unit direction `l` (from the hit to the
/// light), as `KHR_lights_punctual` defines it: 1 inside the inner cone,
/// 0 outside the outer, a squared linear ramp in the cosine between.
fn spot_falloff(ph: &Photometric, l: Vec3) -> f64 {
    let cd = Vec3::from_array(ph.direction).dot(-l);
    let (ci, co) = ((ph.inner_cone as f64).cos(), (ph.outer_cone as f64).cos());
    let scale = 1.0 / (ci - co).max(1e-3);
    let a = ((cd - co) * scale).clamp(0.0, 1.0);
    a * a
}

/// glTF's metallic-roughness BRDF (specification, Appendix B) for base
/// colour `base`, unit normal `n` facing the viewer, unit directions `v`
/// toward the viewer and `l` toward the light, `ndotl = n.l > 0`.
pub fn brdf(pbr: &Pbr, base: [f32; 3], n: Vec3, v: Vec3, l: Vec3, ndotl: f64) -> [f32; 3] {
    use std::f64::consts::PI;
    let metallic = pbr.metallic.clamp(0.0, 1.0) as f64;
    let alpha = (pbr.roughness.clamp(0.0, 1.0) as f64).powi(2).max(1e-3);
    let a2 = alpha * alpha;
    let ndotv = n.dot(v).max(1e-6);
    let h = (l + v).try_normalize().unwrap_or(n);
    let ndoth = n.dot(h).max(0.0);
    let vdoth = v.dot(h).clamp(0.0, 1.0);
    let dd = ndoth * ndoth * (a2 - 1.0) + 1.0;
    let distribution = a2 / (PI * dd * dd);
    let vis = 1.0
        / ((ndotl + (a2 + (1.0 - a2) * ndotl * ndotl).sqrt())
            * (ndotv + (a2 + (1.0 - a2) * ndotv * ndotv).sqrt()));
    let schlick = (1.0 - vdoth).powi(5);
    base.map(|c| {
        let c = c as f64;
        let f0 = 0.04 * (1.0 - metallic) + c * metallic;
        let fresnel = f0 + (1.0 - f0) * schlick;
        let diffuse = (1.0 - fresnel) * c * (1.0 - metallic) / PI;
        (diffuse + fresnel * distribution * vis) as f32
    })
}
