//! Textures and vertex colours reach the image: a quad facing the camera
//! carries a known pattern (or known corner colours), and every pixel is
//! the colour glTF's BRDF gives that pattern where the pixel's corner
//! rays meet the quad, in both tracers.

use crate::common::{self, write_converted};
use serde_json::json;
use sray_engine::bf::StoreNumber;
use sray_engine::progress::NoProgress;
use sray_engine::render::{RenderOptions, brdf};
use sray_engine::scene::Pbr;
use sray_engine::sdb::{Compression, Database};
use sray_engine::source::SceneSource;
use sray_engine::texture::{Encoding, Filter, Sampler, Texture, Wrap};
use std::path::{Path, PathBuf};

const SIZE: u32 = 64;
/// The quad spans [-HALF, HALF]^2 of the plane z = 0; the view spans
/// [-6, 6]^2 from (0, 0, 10).
const HALF: f64 = 4.0;

/// A 4 x 4 PNG of distinct colours (sRGB bytes).
fn pattern_png() -> Vec<u8> {
    let mut img = image::RgbaImage::new(4, 4);
    for j in 0..4u32 {
        for i in 0..4u32 {
            let c = [
                (40 + 70 * i) as u8,
                (250 - 60 * j) as u8,
                ((i * 4 + j) * 15) as u8,
                255,
            ];
            img.put_pixel(i, j, image::Rgba(c));
        }
    }
    let mut png = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .unwrap();
    png
}

/// How the quad gets its colour.
pub(crate) enum Look {
    /// A PNG of the caller's as a file beside the glTF, sampled bilinearly.
    Png(Vec<u8>),
    /// The pattern as a file beside the glTF, sampled by `filter`.
    ImageFile(u32),
    /// The pattern inside the binary buffer, sampled by `filter`.
    ImageInBuffer(u32),
    /// Vertex colours: red from 0 at the left edge to 1 at the right.
    Colors,
}

/// Writes the quad's glTF: corners (-H, H), (H, H), (H, -H), (-H, -H)
/// with texture coordinates (0, 0), (1, 0), (1, 1), (0, 1) (the image's
/// upper-left corner at the quad's), a camera at (0, 0, 10) and one
/// directional light of 1 lux shining down -z.
pub(crate) fn quad(dir: &Path, look: Look) -> PathBuf {
    let h = HALF as f32;
    let corners = [[-h, h], [h, h], [h, -h], [-h, -h]];
    let mut bin: Vec<u8> = Vec::new();
    let push = |bin: &mut Vec<u8>, xs: &[f32]| {
        for x in xs {
            bin.extend_from_slice(&x.to_le_bytes());
        }
    };
    for c in corners {
        push(&mut bin, &[c[0], c[1], 0.0]);
    }
    for uv in [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]] {
        push(&mut bin, &uv);
    }
    for c in corners {
        let red = if c[0] > 0.0 { 1.0 } else { 0.0 };
        push(&mut bin, &[red, 0.5, 0.25, 1.0]);
    }
    for i in [0u16, 3, 2, 0, 2, 1] {
        bin.extend_from_slice(&i.to_le_bytes());
    }
    let png = match &look {
        Look::Png(png) => png.clone(),
        _ => pattern_png(),
    };
    let image_at = bin.len();
    if let Look::ImageInBuffer(_) = look {
        bin.extend_from_slice(&png);
    }
    std::fs::write(dir.join("quad.bin"), &bin).unwrap();
    let mut attributes = json!({"POSITION": 0});
    let mut material = json!({"pbrMetallicRoughness": {
        "baseColorFactor": [1.0, 1.0, 1.0, 1.0], "metallicFactor": 0.0, "roughnessFactor": 1.0}});
    let mut doc = json!({
        "asset": {"version": "2.0"},
        "extensionsUsed": ["KHR_lights_punctual"],
        "extensions": {"KHR_lights_punctual": {"lights": [
            {"type": "directional", "intensity": 1.0, "color": [1.0, 1.0, 1.0]}]}},
        "scene": 0,
        "scenes": [{"nodes": [0, 1, 2]}],
        "nodes": [
            {"mesh": 0},
            {"camera": 0, "translation": [0.0, 0.0, 10.0]},
            {"extensions": {"KHR_lights_punctual": {"light": 0}}}
        ],
        "cameras": [{"type": "perspective", "perspective": {
            "yfov": 2.0 * (0.6f64).atan(), "aspectRatio": 1.0, "znear": 0.01}}],
        "buffers": [{"uri": "quad.bin", "byteLength": bin.len()}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 48},
            {"buffer": 0, "byteOffset": 48, "byteLength": 32},
            {"buffer": 0, "byteOffset": 80, "byteLength": 64},
            {"buffer": 0, "byteOffset": 144, "byteLength": 12},
            {"buffer": 0, "byteOffset": image_at, "byteLength": png.len()}
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
             "min": [-h, -h, 0.0], "max": [h, h, 0.0]},
            {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC2"},
            {"bufferView": 2, "componentType": 5126, "count": 4, "type": "VEC4"},
            {"bufferView": 3, "componentType": 5123, "count": 6, "type": "SCALAR"}
        ]
    });
    let mut textured = |filter: u32, image: serde_json::Value| {
        attributes["TEXCOORD_0"] = json!(1);
        material["pbrMetallicRoughness"]["baseColorTexture"] = json!({"index": 0});
        doc["textures"] = json!([{"source": 0, "sampler": 0}]);
        doc["samplers"] = json!([{"magFilter": filter, "wrapS": 33071, "wrapT": 33071}]);
        doc["images"] = json!([image]);
    };
    match look {
        Look::ImageFile(filter) => {
            std::fs::write(dir.join("pattern.png"), &png).unwrap();
            textured(filter, json!({"uri": "pattern.png"}));
        }
        Look::Png(_) => {
            std::fs::write(dir.join("pattern.png"), &png).unwrap();
            textured(9729, json!({"uri": "pattern.png"}));
        }
        Look::ImageInBuffer(filter) => {
            textured(filter, json!({"bufferView": 4, "mimeType": "image/png"}));
        }
        Look::Colors => attributes["COLOR_0"] = json!(2),
    }
    doc["meshes"] = json!([{"primitives": [
        {"attributes": attributes, "indices": 3, "material": 0}]}]);
    doc["materials"] = json!([material]);
    let path = dir.join("quad.gltf");
    std::fs::write(&path, serde_json::to_string_pretty(&doc).unwrap()).unwrap();
    path
}

fn options() -> RenderOptions {
    RenderOptions {
        width: SIZE,
        height: SIZE,
        threads: 2,
        ..Default::default()
    }
}

/// The database of `gltf` and its depth-first image (linear `f32`);
/// checks that breadth-first under a small budget renders the same.
fn render(dir: &Path, gltf: &Path) -> Vec<[f32; 3]> {
    let db_path = dir.join("scene.sdb");
    let src = SceneSource::parse(gltf.to_str().unwrap()).unwrap();
    write_converted(&src, &db_path, Compression::None, true);
    let db = Database::open(&db_path).unwrap();
    let out = sray_engine::df::render(&db, &options(), &NoProgress).unwrap();
    let df = common::df_render(&db, &options());
    let bf = common::bf_render(&db, &options(), StoreNumber::Adaptive, 4 << 20);
    assert!(df.0 == bf.0, "breadth-first and depth-first images differ");
    assert_eq!(df.1.rays, bf.1.rays);
    out.frame.to_rgb_f32()
}

/// Corner `(i, j)` of the pixel grid on the plane z = 0.
fn corner(i: u32, j: u32) -> (f64, f64) {
    let s = 12.0 / SIZE as f64;
    (-6.0 + s * i as f64, 6.0 - s * j as f64)
}

/// What a corner ray brings back from the point (x, y) of a quad whose
/// base colour there is `base`: the BRDF under the light (n = l = +z).
fn lit(x: f64, y: f64, base: [f32; 3]) -> [f32; 3] {
    let pbr = Pbr {
        metallic: 0.0,
        roughness: 1.0,
        emissive: [0.0; 3],
    };
    let n = glam::DVec3::Z;
    let v = (glam::DVec3::new(0.0, 0.0, 10.0) - glam::DVec3::new(x, y, 0.0)).normalize();
    brdf(&pbr, base, n, v, n, 1.0)
}

/// Checks each pixel whose four corners `inside` accepts against the
/// mean of `expect` at its corners; returns how many were checked.
fn check(
    img: &[[f32; 3]],
    inside: impl Fn(f64, f64) -> bool,
    expect: impl Fn(f64, f64) -> [f32; 3],
    tolerance: f32,
) -> usize {
    let mut checked = 0;
    for row in 0..SIZE {
        for col in 0..SIZE {
            let cs = [
                (col, row),
                (col + 1, row),
                (col, row + 1),
                (col + 1, row + 1),
            ]
            .map(|(i, j)| corner(i, j));
            if !cs.iter().all(|&(x, y)| inside(x, y)) {
                continue;
            }
            let mut want = [0f32; 3];
            for &(x, y) in &cs {
                let e = expect(x, y);
                for k in 0..3 {
                    want[k] += e[k] / 4.0;
                }
            }
            let got = img[(row * SIZE + col) as usize];
            for k in 0..3 {
                assert!(
                    (got[k] - want[k]).abs() <= tolerance * want[k].max(0.05),
                    "pixel ({col}, {row}): got {got:?}, want {want:?}"
                );
            }
            checked += 1;
        }
    }
    checked
}

fn on_quad(x: f64, y: f64) -> bool {
    x.abs() < HALF - 1e-3 && y.abs() < HALF - 1e-3
}

/// The texture coordinates of (x, y) on the quad.
fn uv(x: f64, y: f64) -> [f32; 2] {
    [
        ((x + HALF) / (2.0 * HALF)) as f32,
        ((HALF - y) / (2.0 * HALF)) as f32,
    ]
}

fn pattern(filter: Filter) -> impl Fn(f64, f64) -> [f32; 3] {
    let tex = Texture::decode(&pattern_png(), "pattern", Encoding::Srgb).unwrap();
    let s = Sampler {
        wrap_s: Wrap::ClampToEdge,
        wrap_t: Wrap::ClampToEdge,
        filter,
    };
    move |x, y| {
        let t = tex.sample(&s, uv(x, y));
        lit(x, y, [t[0], t[1], t[2]])
    }
}

#[test]
fn a_texture_shows_each_texel_at_its_pixels_with_nearest_filtering() {
    let dir = tempfile::tempdir().unwrap();
    let img = render(dir.path(), &quad(dir.path(), Look::ImageFile(9728)));
    // Pixels all of whose corners lie inside one texel (away from its
    // edges, where the texture coordinates' rounding may pick either).
    let texel = |x: f64, y: f64| {
        let [u, v] = uv(x, y);
        let near_edge = |c: f32| ((c * 4.0) - (c * 4.0).round()).abs() < 0.02;
        on_quad(x, y) && !near_edge(u) && !near_edge(v)
    };
    let n = check(&img, texel, pattern(Filter::Nearest), 1e-3);
    assert!(n > 400, "only {n} pixels checked");
    // The 16 texels are distinct colours: the pattern is not one colour
    // stretched.
    let mut seen: Vec<[u32; 3]> = Vec::new();
    for (x, y) in [(-3.0, 3.0), (-1.0, 3.0), (1.0, -1.0), (3.0, -3.0)] {
        let col = ((x + 6.0) / 12.0 * SIZE as f64) as u32;
        let row = ((6.0 - y) / 12.0 * SIZE as f64) as u32;
        let p = img[(row * SIZE + col) as usize].map(|c| (c * 1000.0) as u32);
        assert!(!seen.contains(&p), "{seen:?} {p:?}");
        seen.push(p);
    }
}

#[test]
fn a_texture_in_the_binary_buffer_is_sampled_bilinearly() {
    let dir = tempfile::tempdir().unwrap();
    let img = render(dir.path(), &quad(dir.path(), Look::ImageInBuffer(9729)));
    let n = check(&img, on_quad, pattern(Filter::Linear), 2e-3);
    assert!(n > 1500, "only {n} pixels checked");
}

#[test]
fn vertex_colours_multiply_the_base_colour_and_interpolate() {
    let dir = tempfile::tempdir().unwrap();
    let img = render(dir.path(), &quad(dir.path(), Look::Colors));
    let expect = |x: f64, y: f64| {
        let red = ((x + HALF) / (2.0 * HALF)) as f32;
        lit(x, y, [red, 0.5, 0.25])
    };
    let n = check(&img, on_quad, expect, 2e-3);
    assert!(n > 1500, "only {n} pixels checked");
}

/// A `w` x `h` PNG whose texels are all `c`.
fn flat_png(c: [u8; 4]) -> Vec<u8> {
    let img = image::RgbaImage::from_pixel(4, 4, image::Rgba(c));
    let mut png = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .unwrap();
    png
}

/// The quad of [`quad`] (the pattern as its base colour texture, image
/// 0) with its material changed by `f`, which may bind the further
/// images `extra` (images 1, 2, ... as files beside it).
fn quad_with(dir: &Path, extra: &[Vec<u8>], f: impl Fn(&mut serde_json::Value)) -> PathBuf {
    let path = quad(dir, Look::ImageFile(9729));
    let mut doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    for (k, png) in extra.iter().enumerate() {
        let name = format!("map{}.png", k + 1);
        std::fs::write(dir.join(&name), png).unwrap();
        doc["images"]
            .as_array_mut()
            .unwrap()
            .push(json!({"uri": name}));
        doc["textures"]
            .as_array_mut()
            .unwrap()
            .push(json!({"source": k + 1, "sampler": 0}));
    }
    f(&mut doc["materials"][0]);
    std::fs::write(&path, serde_json::to_string_pretty(&doc).unwrap()).unwrap();
    path
}

#[test]
fn a_metallic_roughness_texture_scales_the_factors() {
    // Green 128 (roughness 128/255), blue 0 (metallic 0) under factors 1:
    // the image of the factors 0 and 128/255 without the texture, bit for
    // bit (so the image, bound only as data, holds linear values).
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mapped = render(
        d,
        &quad_with(d, &[flat_png([0, 128, 0, 255])], |m| {
            m["pbrMetallicRoughness"]["metallicFactor"] = json!(1.0);
            m["pbrMetallicRoughness"]["metallicRoughnessTexture"] = json!({"index": 1});
        }),
    );
    let plain = render(
        d,
        &quad_with(d, &[], |m| {
            m["pbrMetallicRoughness"]["metallicFactor"] = json!(0.0);
            m["pbrMetallicRoughness"]["roughnessFactor"] = json!(128.0f32 / 255.0);
        }),
    );
    assert!(mapped == plain, "the texture did not scale the factors");
    // And it matters: a rough surface differs.
    let rough = render(d, &quad_with(d, &[], |_| {}));
    assert!(rough != plain);
}

#[test]
fn an_emissive_texture_adds_its_texels_times_the_factor() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let lit_only = render(d, &quad_with(d, &[], |_| {}));
    let glowing = render(
        d,
        &quad_with(d, &[pattern_png()], |m| {
            m["emissiveFactor"] = json!([1.0, 0.5, 1.0]);
            m["emissiveTexture"] = json!({"index": 1});
        }),
    );
    // The difference is the emission: the pattern (sRGB decoded, bilinear)
    // times the factor, averaged over each pixel's corners.
    let glow: Vec<[f32; 3]> = glowing
        .iter()
        .zip(&lit_only)
        .map(|(g, l)| std::array::from_fn(|k| g[k] - l[k]))
        .collect();
    let tex = Texture::decode(&pattern_png(), "pattern", Encoding::Srgb).unwrap();
    let s = Sampler {
        wrap_s: Wrap::ClampToEdge,
        wrap_t: Wrap::ClampToEdge,
        filter: Filter::Linear,
    };
    let n = check(
        &glow,
        on_quad,
        |x, y| {
            let t = tex.sample(&s, uv(x, y));
            [t[0], 0.5 * t[1], t[2]]
        },
        2e-3,
    );
    assert!(n > 1500, "only {n} pixels checked");
}

#[test]
fn a_normal_map_tilts_the_shading_normal_in_the_texture_frame() {
    // Every texel (204, 128, 230): the normal tilted toward +u (+x here),
    // y of the frame (+v up the image, +y here) nearly zero.
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let img = render(
        d,
        &quad_with(d, &[flat_png([204, 128, 230, 255])], |m| {
            m["pbrMetallicRoughness"]
                .as_object_mut()
                .unwrap()
                .remove("baseColorTexture");
            m["normalTexture"] = json!({"index": 1, "scale": 0.8});
        }),
    );
    let c = |v: u8| 2.0 * (v as f64 / 255.0) - 1.0;
    let n = glam::DVec3::new(0.8 * c(204), 0.8 * c(128), c(230)).normalize();
    let pbr = Pbr {
        metallic: 0.0,
        roughness: 1.0,
        emissive: [0.0; 3],
    };
    let expect = |x: f64, y: f64| {
        let v = (glam::DVec3::new(0.0, 0.0, 10.0) - glam::DVec3::new(x, y, 0.0)).normalize();
        brdf(&pbr, [1.0; 3], n, v, glam::DVec3::Z, n.z).map(|c| c * n.z as f32)
    };
    let k = check(&img, on_quad, expect, 2e-3);
    assert!(k > 1500, "only {k} pixels checked");
    // The tilt is visible: the flat quad's shading differs.
    let lambert = lit(0.0, 0.0, [1.0; 3])[0];
    assert!((img[(32 * SIZE + 32) as usize][0] - lambert).abs() > 0.02);
}

#[test]
fn a_masked_material_without_a_texture_cuts_by_its_alpha() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let path = leaf(d, "MASK");
    let doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    let with_alpha = |alpha: f64| {
        let mut doc = doc.clone();
        doc["materials"][0] = json!({"alphaMode": "MASK", "alphaCutoff": 0.5,
            "pbrMetallicRoughness": {"baseColorFactor": [1.0, 0.0, 0.0, alpha],
                "metallicFactor": 0.0, "roughnessFactor": 1.0}});
        std::fs::write(&path, serde_json::to_string(&doc).unwrap()).unwrap();
        render(d, &path)
    };
    // Below the cut-off the leaf is not there at all: the image of the
    // scene without its node; above, it is.
    let cut = with_alpha(0.3);
    let kept = with_alpha(0.8);
    let mut without = doc.clone();
    without["scenes"][0]["nodes"] = json!([1, 2, 3]);
    std::fs::write(&path, serde_json::to_string(&without).unwrap()).unwrap();
    let bare = render(d, &path);
    assert!(cut == bare, "a leaf below its cut-off still shows");
    assert!(kept != bare, "a leaf above its cut-off is gone");
}

/// A 2 x 1 PNG: a transparent red texel beside an opaque green one.
fn half_transparent_png() -> Vec<u8> {
    let mut img = image::RgbaImage::new(2, 1);
    img.put_pixel(0, 0, image::Rgba([255, 0, 0, 0]));
    img.put_pixel(1, 0, image::Rgba([0, 255, 0, 255]));
    let mut png = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .unwrap();
    png
}

/// A leaf: the quad [-3, 3]^2 of z = 0 whose left half is cut out by its
/// texture's alpha (`alphaMode: MASK`), in front of a white floor, the
/// quad [-5.5, 5.5]^2 of z = -2, under a directional light down -z, seen
/// from (0, 0, 10).
fn leaf(dir: &Path, mode: &str) -> PathBuf {
    let mut bin: Vec<u8> = Vec::new();
    let push = |bin: &mut Vec<u8>, xs: &[f32]| {
        for x in xs {
            bin.extend_from_slice(&x.to_le_bytes());
        }
    };
    for (h, z) in [(3.0f32, 0.0f32), (5.5, -2.0)] {
        for c in [[-h, h], [h, h], [h, -h], [-h, -h]] {
            push(&mut bin, &[c[0], c[1], z]);
        }
    }
    for uv in [[0.0f32, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]] {
        push(&mut bin, &uv);
    }
    for i in [0u16, 3, 2, 0, 2, 1] {
        bin.extend_from_slice(&i.to_le_bytes());
    }
    let png = half_transparent_png();
    let image_at = bin.len();
    bin.extend_from_slice(&png);
    std::fs::write(dir.join("leaf.bin"), &bin).unwrap();
    let doc = json!({
        "asset": {"version": "2.0"},
        "extensionsUsed": ["KHR_lights_punctual"],
        "extensions": {"KHR_lights_punctual": {"lights": [
            {"type": "directional", "intensity": 1.0, "color": [1.0, 1.0, 1.0]}]}},
        "scene": 0,
        "scenes": [{"nodes": [0, 1, 2, 3]}],
        "nodes": [
            {"mesh": 0},
            {"mesh": 1},
            {"camera": 0, "translation": [0.0, 0.0, 10.0]},
            {"extensions": {"KHR_lights_punctual": {"light": 0}}}
        ],
        "cameras": [{"type": "perspective", "perspective": {
            "yfov": 2.0 * (0.6f64).atan(), "aspectRatio": 1.0, "znear": 0.01}}],
        "buffers": [{"uri": "leaf.bin", "byteLength": bin.len()}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 48},
            {"buffer": 0, "byteOffset": 48, "byteLength": 48},
            {"buffer": 0, "byteOffset": 96, "byteLength": 32},
            {"buffer": 0, "byteOffset": 128, "byteLength": 12},
            {"buffer": 0, "byteOffset": image_at, "byteLength": png.len()}
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
             "min": [-3.0, -3.0, 0.0], "max": [3.0, 3.0, 0.0]},
            {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC3",
             "min": [-5.5, -5.5, -2.0], "max": [5.5, 5.5, -2.0]},
            {"bufferView": 2, "componentType": 5126, "count": 4, "type": "VEC2"},
            {"bufferView": 3, "componentType": 5123, "count": 6, "type": "SCALAR"}
        ],
        "meshes": [
            {"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 2}, "indices": 3, "material": 0}]},
            {"primitives": [{"attributes": {"POSITION": 1}, "indices": 3, "material": 1}]}
        ],
        "materials": [
            {"alphaMode": mode, "alphaCutoff": 0.5, "pbrMetallicRoughness": {
                "baseColorTexture": {"index": 0}, "metallicFactor": 0.0, "roughnessFactor": 1.0}},
            {"pbrMetallicRoughness": {"baseColorFactor": [1.0, 1.0, 1.0, 1.0],
                "metallicFactor": 0.0, "roughnessFactor": 1.0}}
        ],
        "textures": [{"source": 0, "sampler": 0}],
        "samplers": [{"magFilter": 9728, "wrapS": 33071, "wrapT": 33071}],
        "images": [{"bufferView": 4, "mimeType": "image/png"}]
    });
    let path = dir.join("leaf.gltf");
    std::fs::write(&path, serde_json::to_string_pretty(&doc).unwrap()).unwrap();
    path
}

/// The pixel whose corners straddle (x, y) of the plane z = 0.
fn at(img: &[[f32; 3]], x: f64, y: f64) -> [f32; 3] {
    let col = ((x + 6.0) / 12.0 * SIZE as f64).floor() as usize;
    let row = ((6.0 - y) / 12.0 * SIZE as f64).floor() as usize;
    img[row * SIZE as usize + col]
}

#[test]
fn light_and_sight_pass_through_an_alpha_mask_cut_out() {
    let dir = tempfile::tempdir().unwrap();
    let img = render(dir.path(), &leaf(dir.path(), "MASK"));
    let opaque = at(&img, 1.5, 0.0);
    let hole = at(&img, -1.5, 0.0);
    let floor = at(&img, 4.3, 0.0);
    // The opaque half is the green texel.
    // (A grey glint of GGX on top.)
    assert!(opaque[1] > 0.2 && opaque[0] < 0.02, "{opaque:?}");
    // Through the hole: the white floor (not the red texel), lit, so its
    // shadow rays passed the hole too, about as bright as the floor seen
    // beside the leaf.
    assert!(
        (hole[0] - hole[1]).abs() < 1e-3 && (hole[0] - hole[2]).abs() < 1e-3,
        "{hole:?}"
    );
    assert!(
        (hole[0] / floor[0] - 1.0).abs() < 0.05,
        "{hole:?} {floor:?}"
    );
    // Without the mask, the left half is the red texel and the floor
    // behind it unseen.
    let dir = tempfile::tempdir().unwrap();
    let img = render(dir.path(), &leaf(dir.path(), "OPAQUE"));
    let red = at(&img, -1.5, 0.0);
    assert!(red[0] > 0.2 && red[1] < 0.02, "{red:?}");
}

#[test]
fn a_cut_out_renders_the_same_in_both_tracers_precisions_and_budgets() {
    use sray_engine::render::Precision;
    let dir = tempfile::tempdir().unwrap();
    let gltf = leaf(dir.path(), "MASK");
    let db_path = dir.path().join("leaf.sdb");
    let src = SceneSource::parse(gltf.to_str().unwrap()).unwrap();
    write_converted(&src, &db_path, Compression::Zstd(3), true);
    let db = Database::open(&db_path).unwrap();
    for precision in [Precision::Double, Precision::Single] {
        let o = RenderOptions {
            precision,
            ..options()
        };
        let df = common::df_render(&db, &o);
        for memory in [1 << 20, 64 << 20] {
            let bf = common::bf_render(&db, &o, StoreNumber::Adaptive, memory);
            if df.0 != bf.0 {
                let px = |img: &[u8], x: f64, y: f64| {
                    let col = ((x + 6.0) / 12.0 * SIZE as f64).floor() as usize;
                    let row = ((6.0 - y) / 12.0 * SIZE as f64).floor() as usize;
                    let i = 3 * (row * SIZE as usize + col);
                    [img[i], img[i + 1], img[i + 2]]
                };
                for (x, y) in [(-1.5, 0.0), (1.5, 0.0), (4.8, 0.0), (-4.5, 0.0)] {
                    eprintln!(
                        "({x},{y}) df {:?} bf {:?}",
                        px(&df.0, x, y),
                        px(&bf.0, x, y)
                    );
                }
                eprintln!("df {:?}\nbf {:?}", df.1.rays, bf.1.rays);
            }
            assert!(df.0 == bf.0, "{precision:?}, {memory}: the tracers differ");
            assert_eq!(df.1.rays, bf.1.rays);
        }
    }
}

#[test]
fn an_emissive_surface_adds_its_light_in_both_tracers() {
    let dir = tempfile::tempdir().unwrap();
    let path = quad(dir.path(), Look::Colors);
    let mut doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    doc["materials"][0]["emissiveFactor"] = json!([0.5, 0.25, 0.0]);
    doc["materials"][0]["extensions"] =
        json!({"KHR_materials_emissive_strength": {"emissiveStrength": 2.0}});
    doc["extensionsUsed"] = json!(["KHR_lights_punctual", "KHR_materials_emissive_strength"]);
    std::fs::write(&path, serde_json::to_string(&doc).unwrap()).unwrap();
    let img = render(dir.path(), &path);
    // What the light gives the vertex colours, plus (1, 0.5, 0).
    let expect = |x: f64, y: f64| {
        let red = ((x + HALF) / (2.0 * HALF)) as f32;
        let l = lit(x, y, [red, 0.5, 0.25]);
        [l[0] + 1.0, l[1] + 0.5, l[2]]
    };
    let n = check(&img, on_quad, expect, 2e-3);
    assert!(n > 1500, "only {n} pixels checked");
}
