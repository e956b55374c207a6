//! glTF's lights and materials as glTF means them: `KHR_lights_punctual`
//! intensity with inverse-square falloff, spot cones and range, and the
//! metallic-roughness BRDF, on small files each test writes itself.

use crate::common::{self, write_converted};
use serde_json::json;
use sray_engine::bf::StoreNumber;
use sray_engine::progress::NoProgress;
use sray_engine::render::RenderOptions;
use sray_engine::sdb::{Compression, Database};
use sray_engine::source::SceneSource;
use std::path::{Path, PathBuf};

const SIZE: u32 = 64;

/// Writes a glTF of two unit-half-size quads in the plane z = 0, centred
/// at x = -5 and x = +5, seen by a camera at (0, 0, 10) looking down -z
/// whose view spans x from -6 to 6; `lights` are `KHR_lights_punctual`
/// entries, each placed by a node at its position (pointing down -z).
fn two_quads(
    dir: &Path,
    material: serde_json::Value,
    lights: &[(serde_json::Value, [f64; 3])],
) -> PathBuf {
    let mut bin: Vec<u8> = Vec::new();
    for cx in [-5.0f32, 5.0] {
        for (x, y) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
            for c in [cx + x, y, 0.0f32] {
                bin.extend_from_slice(&c.to_le_bytes());
            }
        }
    }
    for i in [0u16, 1, 2, 0, 2, 3, 4, 5, 6, 4, 6, 7] {
        bin.extend_from_slice(&i.to_le_bytes());
    }
    std::fs::write(dir.join("quads.bin"), &bin).unwrap();
    let mut nodes = vec![
        json!({"mesh": 0}),
        json!({"camera": 0, "translation": [0.0, 0.0, 10.0]}),
    ];
    for (i, (_, at)) in lights.iter().enumerate() {
        nodes.push(json!({"translation": at, "extensions": {"KHR_lights_punctual": {"light": i}}}));
    }
    let doc = json!({
        "asset": {"version": "2.0"},
        "extensionsUsed": ["KHR_lights_punctual"],
        "extensions": {"KHR_lights_punctual": {"lights": lights.iter().map(|l| l.0.clone()).collect::<Vec<_>>()}},
        "scene": 0,
        "scenes": [{"nodes": (0..nodes.len()).collect::<Vec<_>>()}],
        "nodes": nodes,
        "cameras": [{"type": "perspective", "perspective": {
            "yfov": 2.0 * (0.6f64).atan(), "aspectRatio": 1.0, "znear": 0.01}}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "material": 0}]}],
        "materials": [material],
        "buffers": [{"uri": "quads.bin", "byteLength": bin.len()}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 96},
            {"buffer": 0, "byteOffset": 96, "byteLength": 24}
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 8, "type": "VEC3",
             "min": [-6.0, -1.0, 0.0], "max": [6.0, 1.0, 0.0]},
            {"bufferView": 1, "componentType": 5123, "count": 12, "type": "SCALAR"}
        ]
    });
    let path = dir.join("quads.gltf");
    std::fs::write(&path, serde_json::to_string_pretty(&doc).unwrap()).unwrap();
    path
}

fn white_dielectric() -> serde_json::Value {
    json!({"pbrMetallicRoughness": {"baseColorFactor": [1.0, 1.0, 1.0, 1.0],
        "metallicFactor": 0.0, "roughnessFactor": 1.0}})
}

/// A spot light of `intensity` candela pointing down -z, its cone wide
/// enough for the quad beneath it and too narrow for the other.
fn spot(intensity: f64) -> serde_json::Value {
    json!({"type": "spot", "intensity": intensity, "color": [1.0, 1.0, 1.0],
        "spot": {"innerConeAngle": 1.0, "outerConeAngle": 1.2}})
}

fn options() -> RenderOptions {
    RenderOptions {
        width: SIZE,
        height: SIZE,
        threads: 2,
        ..Default::default()
    }
}

/// The database of `gltf`, and its depth-first image in linear `f32`.
fn render(dir: &Path, gltf: &Path) -> (Database, Vec<[f32; 3]>) {
    let db_path = dir.join("scene.sdb");
    let src = SceneSource::parse(gltf.to_str().unwrap()).unwrap();
    write_converted(&src, &db_path, Compression::None, true);
    let db = Database::open(&db_path).unwrap();
    let out = sray_engine::df::render(&db, &options(), &NoProgress).unwrap();
    let img = out.frame.to_rgb_f32();
    (db, img)
}

/// The pixel whose corners straddle the point (x, y) of the plane z = 0
/// (the view spans -6..6 over the corners 0..SIZE).
fn pixel(img: &[[f32; 3]], x: f64, y: f64) -> [f32; 3] {
    let col = ((x + 6.0) / 12.0 * SIZE as f64).floor() as usize;
    let row = ((6.0 - y) / 12.0 * SIZE as f64).floor() as usize;
    img[row * SIZE as usize + col]
}

#[test]
fn two_equal_lights_at_distances_one_and_two_give_the_inverse_square_ratio() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let gltf = two_quads(
        d,
        white_dielectric(),
        &[(spot(2.0), [-5.0, 0.0, 1.0]), (spot(2.0), [5.0, 0.0, 2.0])],
    );
    let (db, img) = render(d, &gltf);
    let near = pixel(&img, -5.0, 0.0);
    let far = pixel(&img, 5.0, 0.0);
    // A white Lambert surface (plus a little GGX at roughness 1) under
    // 2 cd at 1 m: about 2 / pi.
    assert!(near[0] > 0.5 && near[0] < 0.7, "{near:?}");
    let ratio = near[0] / far[0];
    assert!(
        (ratio - 4.0).abs() < 0.12,
        "near {near:?}, far {far:?}: ratio {ratio}, not 4"
    );
    assert_eq!(near[0], near[2], "white light on a white surface is grey");
    // Outside the quads: a mesh's default background.
    assert_eq!(pixel(&img, 0.0, 0.0), [0.1, 0.11, 0.14]);
    // Breadth-first, under a small budget, renders the same image.
    let df = common::df_render(&db, &options());
    let bf = common::bf_render(&db, &options(), StoreNumber::Adaptive, 8 << 20);
    assert!(df.0 == bf.0, "breadth-first and depth-first images differ");
    assert_eq!(df.1.rays, bf.1.rays);
}

#[test]
fn intensity_scales_the_light_and_range_and_cone_cut_it_off() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let base = {
        let g = two_quads(d, white_dielectric(), &[(spot(1.0), [-5.0, 0.0, 1.0])]);
        render(d, &g).1
    };
    let double = {
        let g = two_quads(d, white_dielectric(), &[(spot(2.0), [-5.0, 0.0, 1.0])]);
        render(d, &g).1
    };
    let (a, b) = (pixel(&base, -5.0, 0.0)[0], pixel(&double, -5.0, 0.0)[0]);
    assert!(a > 0.1 && (b / a - 2.0).abs() < 1e-3, "{a} {b}");
    // The spot's cone leaves the other quad dark.
    assert_eq!(pixel(&double, 5.0, 0.0), [0.0; 3]);
    // A point light of range 1.3 at height 1 reaches the middle of the
    // quad, dimmed by the range window, and not the pixel near its corner
    // (whose pixel corners are all over 1.4 from it).
    let point = json!({"type": "point", "intensity": 2.0, "range": 1.3});
    let g = two_quads(d, white_dielectric(), &[(point, [-5.0, 0.0, 1.0])]);
    let img = render(d, &g).1;
    let mid = pixel(&img, -5.0, 0.0)[0];
    let window = 1.0 - (1.0f32 / 1.3).powi(4);
    assert!((mid / b - window).abs() < 0.03, "{mid} {b} {window}");
    assert_eq!(pixel(&img, -4.2, 0.8), [0.0; 3]);
}

#[test]
fn metal_reflects_the_light_in_its_base_colour_and_dielectric_in_white() {
    // A light straight above the quad's middle and the camera far above.
    // A red metal reflects in red only; a red dielectric gives its red
    // diffuse and a white specular part. (Roughness 1: no mirror rays,
    // so the background does not enter.)
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mat = |metallic: f64| {
        json!({"pbrMetallicRoughness": {"baseColorFactor": [1.0, 0.0, 0.0, 1.0],
            "metallicFactor": metallic, "roughnessFactor": 1.0}})
    };
    let light = [(json!({"type": "point", "intensity": 1.0}), [5.0, 0.0, 1.0])];
    let metal = render(d, &two_quads(d, mat(1.0), &light)).1;
    let plastic = render(d, &two_quads(d, mat(0.0), &light)).1;
    let m = pixel(&metal, 5.0, 0.0);
    let p = pixel(&plastic, 5.0, 0.0);
    assert!(
        m[0] > 0.0 && m[1] < 1e-3 * m[0] && m[1] == m[2],
        "metal {m:?}"
    );
    assert!(
        p[0] > p[1] && p[1] > 0.0 && p[1] == p[2],
        "dielectric {p:?}"
    );
}
