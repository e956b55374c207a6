//! Textured OBJ (`vt`, `map_Kd`) and PLY (`u v` or per-face `texcoord`,
//! `comment TextureFile`) meshes: their faces become textured triangles
//! carrying the file's texture coordinates (v flipped to run down the
//! image), the image travels with the scene, the external join equals the
//! lookup, and the texture shows in the image.

use crate::common::{self, write_converted};
use sray_engine::bf::StoreNumber;
use sray_engine::mesh::{MeshOptions, obj, ply};
use sray_engine::progress::NoProgress;
use sray_engine::render::RenderOptions;
use sray_engine::scene::recorder::{Event, Recorder};
use sray_engine::sdb::{Compression, Database};
use sray_engine::shapes::{OwnedShape, Shape};
use sray_engine::source::SceneSource;
use sray_engine::texture::Wrap;
use std::path::Path;

/// A 2 x 2 PNG: red, green / blue, white (upper row first).
fn png() -> Vec<u8> {
    let mut img = image::RgbImage::new(2, 2);
    img.put_pixel(0, 0, image::Rgb([255, 0, 0]));
    img.put_pixel(1, 0, image::Rgb([0, 255, 0]));
    img.put_pixel(0, 1, image::Rgb([0, 0, 255]));
    img.put_pixel(1, 1, image::Rgb([255, 255, 255]));
    let mut out = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut out), image::ImageFormat::Png)
        .unwrap();
    out
}

fn options(memory: u64) -> MeshOptions {
    MeshOptions {
        memory,
        spill_dir: None,
        camera_index: None,
    }
}

/// A textured triangle's corners and texture coordinates.
type Corners = (Vec<[f32; 3]>, Vec<[f32; 2]>);

fn textured(r: &Recorder) -> Vec<Corners> {
    r.objects()
        .filter_map(|o| match o.shape() {
            Shape::Textured(t) => Some((t.vertices.to_vec(), t.uvs.to_vec())),
            _ => None,
        })
        .collect()
}

fn textures(r: &Recorder) -> usize {
    r.events
        .iter()
        .filter(|e| matches!(e, Event::Texture(_)))
        .count()
}

/// A unit quad in z = 0 with OpenGL-style texture coordinates (v up), a
/// library whose material has `map_Kd`, and a second, untextured face.
fn write_obj(dir: &Path, map: &str) {
    std::fs::write(dir.join("pattern.png"), png()).unwrap();
    std::fs::write(
        dir.join("quad.mtl"),
        format!("newmtl tex\nKd 1 1 1\n{map}\nnewmtl plain\nKd 0.5 0.5 0.5\n"),
    )
    .unwrap();
    std::fs::write(
        dir.join("quad.obj"),
        "mtllib quad.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\n\
         vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n\
         usemtl tex\nf 1/1 2/2 3/3 4/4\nusemtl plain\nf 1 2 5\n",
    )
    .unwrap();
}

#[test]
fn obj_vt_and_map_kd_make_textured_triangles() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write_obj(d, "map_Kd -clamp on pattern.png");
    let mut r = Recorder::default();
    obj::read_obj(&d.join("quad.obj"), &mut r, &NoProgress, &options(64 << 20)).unwrap();
    assert_eq!(textures(&r), 1);
    let bound: Vec<_> = r
        .events
        .iter()
        .filter_map(|e| match e {
            Event::Material(m) => m.texture,
            _ => None,
        })
        .collect();
    assert_eq!(bound.len(), 1);
    assert_eq!(bound[0].sampler.wrap_s, Wrap::ClampToEdge);
    // The quad as two textured triangles, v flipped: (0, 0) in the file
    // is the image's lower-left corner, (0, 1) in sray's terms.
    let tris = textured(&r);
    assert_eq!(tris.len(), 2, "{tris:?}");
    for (v, uv) in &tris {
        for (p, t) in v.iter().zip(uv) {
            assert_eq!(*t, [p[0], 1.0 - p[1]], "{v:?} {uv:?}");
        }
    }
    // The face without texture coordinates (and of another material)
    // stays a polygon.
    assert_eq!(r.objects().count(), 3);

    // A map_Kd whose image is missing: a warning, an untextured mesh.
    write_obj(d, "map_Kd missing.png");
    let mut r = Recorder::default();
    obj::read_obj(&d.join("quad.obj"), &mut r, &NoProgress, &options(64 << 20)).unwrap();
    assert_eq!(textures(&r), 0);
    assert!(textured(&r).is_empty());
}

/// A grid of `n` x `n` quads over [0, 1]^2 with texture coordinates,
/// textured: in OBJ (texture coordinates indexed apart from the vertices,
/// in reverse order) and PLY (per vertex).
fn grid(dir: &Path, n: usize) {
    std::fs::write(dir.join("pattern.png"), png()).unwrap();
    std::fs::write(
        dir.join("g.mtl"),
        "newmtl tex\nKd 1 1 1\nmap_Kd pattern.png\n",
    )
    .unwrap();
    let k = n + 1;
    let mut o = String::from("mtllib g.mtl\nusemtl tex\n");
    let mut p = format!(
        "ply\nformat ascii 1.0\ncomment TextureFile pattern.png\nelement vertex {}\n\
         property float x\nproperty float y\nproperty float z\nproperty float u\nproperty float v\n\
         element face {}\nproperty list uchar int vertex_indices\nend_header\n",
        k * k,
        n * n
    );
    let at = |i: usize, j: usize| (i as f32 / n as f32, j as f32 / n as f32);
    for j in 0..k {
        for i in 0..k {
            let (x, y) = at(i, j);
            let z = ((i * 7 + j * 3) % 5) as f32 * 0.01;
            o += &format!("v {x} {y} {z}\n");
            p += &format!("{x} {y} {z} {x} {y}\n");
        }
    }
    for j in (0..k).rev() {
        for i in (0..k).rev() {
            let (x, y) = at(i, j);
            o += &format!("vt {x} {y}\n");
        }
    }
    let vi = |i: usize, j: usize| j * k + i;
    let ti = |i: usize, j: usize| k * k - 1 - (j * k + i);
    for j in 0..n {
        for i in 0..n {
            let c = [(i, j), (i + 1, j), (i + 1, j + 1), (i, j + 1)];
            o += "f";
            p += "4";
            for (a, b) in c {
                o += &format!(" {}/{}", vi(a, b) + 1, ti(a, b) + 1);
                p += &format!(" {}", vi(a, b));
            }
            o += "\n";
            p += "\n";
        }
    }
    std::fs::write(dir.join("g.obj"), o).unwrap();
    std::fs::write(dir.join("g.ply"), p).unwrap();
}

/// The recorded mesh, and whether its corners were joined on disk.
fn read(path: &Path, memory: u64) -> (Recorder, bool) {
    let mut r = Recorder::default();
    let o = options(memory);
    let s = match path.extension().and_then(|e| e.to_str()) {
        Some("obj") => obj::read_obj(path, &mut r, &NoProgress, &o),
        _ => ply::read_ply(path, &mut r, &NoProgress, &o),
    }
    .unwrap();
    (r, s.joined_on_disk)
}

#[test]
fn texture_coordinates_join_on_disk_as_in_memory_in_obj_and_ply() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    grid(d, 24);
    for name in ["g.obj", "g.ply"] {
        let (big, on_disk) = read(&d.join(name), 64 << 20);
        assert!(!on_disk);
        // No memory: every table on disk, sorts in runs of 16 records.
        let (small, on_disk) = read(&d.join(name), 0);
        assert!(on_disk, "{name}: the small budget did not join on disk");
        let (b, s) = (textured(&big), textured(&small));
        assert_eq!(b.len(), 2 * 24 * 24, "{name}");
        assert!(b == s, "{name}: the external join differs from the lookup");
        // Every corner's coordinates are its position's (v flipped).
        for (v, uv) in &b {
            for (p, t) in v.iter().zip(uv) {
                assert!(
                    (t[0] - p[0]).abs() < 1e-6 && (t[1] - (1.0 - p[1])).abs() < 1e-6,
                    "{name}: {v:?} {uv:?}"
                );
            }
        }
        let o: Vec<&OwnedShape> = big.objects().collect();
        assert_eq!(o.len(), b.len(), "{name}: every face textured");
        assert_eq!(textures(&big), 1, "{name}");
    }
}

#[test]
fn ply_per_face_texcoord_lists_are_read() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("t.png"), png()).unwrap();
    std::fs::write(
        d.join("f.ply"),
        "ply\nformat ascii 1.0\ncomment TextureFile t.png\nelement vertex 3\n\
         property float x\nproperty float y\nproperty float z\nelement face 1\n\
         property list uchar int vertex_indices\nproperty list uchar float texcoord\nend_header\n\
         0 0 0\n1 0 0\n0 1 0\n3 0 1 2 6 0.25 0.25 0.75 0.25 0.25 0.75\n",
    )
    .unwrap();
    let (r, _) = read(&d.join("f.ply"), 64 << 20);
    let t = textured(&r);
    assert_eq!(t.len(), 1);
    assert_eq!(t[0].1, vec![[0.25, 0.75], [0.75, 0.75], [0.25, 0.25]]);
}

/// Renders the OBJ quad of `write_obj` (seen by the default view of a
/// mesh) from its database, depth-first and breadth-first (equal).
fn render(dir: &Path) -> Vec<[f32; 3]> {
    let src = SceneSource::parse(dir.join("quad.obj").to_str().unwrap()).unwrap();
    let db_path = dir.join("quad.sdb");
    write_converted(&src, &db_path, Compression::Zstd(3), true);
    let db = Database::open(&db_path).unwrap();
    let o = RenderOptions {
        width: 48,
        height: 48,
        threads: 2,
        ..Default::default()
    };
    let df = common::df_render(&db, &o);
    let bf = common::bf_render(&db, &o, StoreNumber::Adaptive, 4 << 20);
    assert!(df.0 == bf.0, "breadth-first and depth-first images differ");
    sray_engine::df::render(&db, &o, &NoProgress)
        .unwrap()
        .frame
        .to_rgb_f32()
}

#[test]
fn an_obj_texture_shows_in_the_image() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write_obj(d, "map_Kd -clamp on pattern.png");
    let tex = render(d);
    write_obj(d, "");
    let plain = render(d);
    // Where the quad is seen, the textured image is the plain one times
    // the texture (Kd 1; NFF's shading is linear in the colour): each of
    // the four colours appears, as the channel ratios show.
    let mut seen = [false; 4];
    for (t, p) in tex.iter().zip(&plain) {
        if p[0] <= 0.05 || (p[0] - p[1]).abs() > 1e-6 {
            continue; // background or the other face
        }
        let r = t.map(|c| c / p[0]);
        for (k, want) in [
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
            [1.0, 1.0, 1.0],
        ]
        .iter()
        .enumerate()
        {
            if (0..3).all(|c| (r[c] - want[c]).abs() < 0.02) {
                seen[k] = true;
            }
        }
    }
    assert_eq!(seen, [true; 4], "the four texels are not all in the image");
}
