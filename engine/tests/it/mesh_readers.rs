//! The mesh readers (PLY, OBJ, OFF): the same mesh in every format and
//! encoding reads the same; the external join equals the lookup; the
//! polygon policy; materials and colours; every malformed case is an error
//! naming the file and the line or byte.

use sray_engine::Error;
use sray_engine::input::Wrapping;
use sray_engine::mesh::{MeshOptions, MeshSummary, NEUTRAL, obj, off, ply};
use sray_engine::progress::Progress;
use sray_engine::scene::Material;
use sray_engine::scene::recorder::{Event, Recorder};
use sray_engine::shapes::{Shape, ShapeKind};
use std::path::Path;
use std::sync::Mutex;

/// Progress that keeps the warnings.
#[derive(Default)]
struct Warned(Mutex<Vec<String>>);

impl Progress for Warned {
    fn set_total(&self, _: u64) {}
    fn inc(&self, _: u64) {}
    fn set_message(&self, _: &str) {}
    fn warn(&self, msg: &str) {
        self.0.lock().unwrap().push(msg.to_string());
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Fmt {
    Ply,
    Obj,
    Off,
}

fn read_with(
    f: Fmt,
    data: &[u8],
    memory: u64,
) -> Result<(Recorder, MeshSummary, Vec<String>), Error> {
    let mut r = Recorder::default();
    let w = Warned::default();
    let opts = MeshOptions {
        memory,
        spill_dir: None,
        camera_index: None,
    };
    let s = match f {
        Fmt::Ply => {
            ply::read_ply_from(data, Wrapping::Plain, Path::new("m.ply"), &mut r, &w, &opts)
        }
        Fmt::Obj => obj::read_obj_from(
            data,
            Wrapping::Plain,
            Path::new("m.obj"),
            None,
            &mut r,
            &w,
            &opts,
        ),
        Fmt::Off => {
            off::read_off_from(data, Wrapping::Plain, Path::new("m.off"), &mut r, &w, &opts)
        }
    }?;
    Ok((r, s, w.0.into_inner().unwrap()))
}

fn read(f: Fmt, data: &[u8]) -> (Recorder, MeshSummary, Vec<String>) {
    read_with(f, data, 64 << 20)
        .unwrap_or_else(|e| panic!("{f:?}: {e}\n{}", String::from_utf8_lossy(data)))
}

fn err(f: Fmt, data: &[u8]) -> String {
    match read_with(f, data, 64 << 20) {
        Ok(_) => panic!("{f:?} accepted:\n{}", String::from_utf8_lossy(data)),
        Err(e) => e.to_string(),
    }
}

/// The objects of a recording, as (kind, world vertex coordinates).
fn objects(r: &Recorder) -> Vec<(ShapeKind, Vec<[f64; 3]>)> {
    let origin = r
        .events
        .iter()
        .find_map(|e| match e {
            Event::Origin(o) => Some(*o),
            _ => None,
        })
        .unwrap_or([0.0; 3]);
    r.objects()
        .map(|o| {
            let s = o.shape();
            let v = match s {
                Shape::Polygon(p) => p.vertices.to_vec(),
                Shape::Patch(p) => p.vertices.to_vec(),
                _ => Vec::new(),
            };
            (
                o.kind,
                v.iter()
                    .map(|p| std::array::from_fn(|i| p[i] as f64 + origin[i]))
                    .collect(),
            )
        })
        .collect()
}

fn materials(r: &Recorder) -> Vec<Material> {
    r.events
        .iter()
        .filter_map(|e| match e {
            Event::Material(m) => Some(*m),
            _ => None,
        })
        .collect()
}

// A unit cube: 8 vertices, 6 planar quads, counter-clockwise from outside.
const CUBE_V: [[f64; 3]; 8] = [
    [0.0, 0.0, 0.0],
    [1.0, 0.0, 0.0],
    [1.0, 1.0, 0.0],
    [0.0, 1.0, 0.0],
    [0.0, 0.0, 1.0],
    [1.0, 0.0, 1.0],
    [1.0, 1.0, 1.0],
    [0.0, 1.0, 1.0],
];
const CUBE_F: [[u32; 4]; 6] = [
    [0, 3, 2, 1],
    [4, 5, 6, 7],
    [0, 1, 5, 4],
    [2, 3, 7, 6],
    [1, 2, 6, 5],
    [0, 4, 7, 3],
];

fn cube_ply_ascii() -> Vec<u8> {
    let mut s = String::from(
        "ply\nformat ascii 1.0\ncomment a cube\nelement vertex 8\nproperty float x\nproperty float y\nproperty float z\nelement face 6\nproperty list uchar int vertex_indices\nend_header\n",
    );
    for v in CUBE_V {
        s += &format!("{} {} {}\n", v[0], v[1], v[2]);
    }
    for f in CUBE_F {
        s += &format!("4 {} {} {} {}\n", f[0], f[1], f[2], f[3]);
    }
    s.into_bytes()
}

/// The cube in binary, with extra properties of every type to skip, the
/// coordinates as doubles and the indices as ushort with a uint count.
fn cube_ply_binary(big: bool) -> Vec<u8> {
    let mut s = format!(
        "ply\nformat {} 1.0\nelement vertex 8\nproperty double x\nproperty char junk\nproperty double y\nproperty double z\nproperty list uchar short more\nelement face 6\nproperty uint flags\nproperty list uint ushort vertex_indices\nelement extra 2\nproperty float a\nproperty list uchar double b\nend_header\n",
        if big {
            "binary_big_endian"
        } else {
            "binary_little_endian"
        }
    )
    .into_bytes();
    macro_rules! put {
        ($v:expr) => {
            if big {
                s.extend_from_slice(&$v.to_be_bytes())
            } else {
                s.extend_from_slice(&$v.to_le_bytes())
            }
        };
    }
    for v in CUBE_V {
        put!(v[0]);
        put!(-5i8);
        put!(v[1]);
        put!(v[2]);
        put!(2u8);
        put!(7i16);
        put!(-7i16);
    }
    for f in CUBE_F {
        put!(0xdeadu32);
        put!(4u32);
        for i in f {
            put!(i as u16);
        }
    }
    for _ in 0..2 {
        put!(1.5f32);
        put!(1u8);
        put!(2.5f64);
    }
    s
}

fn cube_obj() -> Vec<u8> {
    let mut s = String::from("# a cube\no cube\n");
    for v in CUBE_V {
        s += &format!("v {} {} {}\n", v[0], v[1], v[2]);
    }
    s += "g sides\ns off\n";
    for f in CUBE_F {
        s += &format!("f {} {} {} {}\n", f[0] + 1, f[1] + 1, f[2] + 1, f[3] + 1);
    }
    s.into_bytes()
}

fn cube_off() -> Vec<u8> {
    let mut s = String::from("OFF\n# a cube\n8 6 12\n");
    for v in CUBE_V {
        s += &format!("{} {} {}\n", v[0], v[1], v[2]);
    }
    for f in CUBE_F {
        s += &format!("4 {} {} {} {}\n", f[0], f[1], f[2], f[3]);
    }
    s.into_bytes()
}

#[test]
fn the_same_mesh_reads_the_same_in_every_format_and_encoding() {
    let (reference, s, w) = read(Fmt::Ply, &cube_ply_ascii());
    assert!(w.is_empty(), "{w:?}");
    assert_eq!((s.vertices, s.faces, s.objects), (8, 6, 6));
    assert_eq!(s.polygons_kept, 6);
    let want = objects(&reference);
    assert_eq!(want.len(), 6);
    assert!(
        want.iter()
            .all(|(k, v)| *k == ShapeKind::Polygon && v.len() == 4)
    );
    for (f, data) in [
        (Fmt::Ply, cube_ply_binary(false)),
        (Fmt::Ply, cube_ply_binary(true)),
        (Fmt::Obj, cube_obj()),
        (Fmt::Off, cube_off()),
    ] {
        let (r, s, w) = read(f, &data);
        assert!(w.is_empty(), "{f:?}: {w:?}");
        assert_eq!(objects(&r), want, "{f:?}");
        assert_eq!(r.events, reference.events, "{f:?}");
        assert_eq!((s.vertices, s.faces), (8, 6));
    }
    // The origin (the world's: the cube is near it), announced before the
    // facts and the first object.
    let e = &reference.events;
    assert_eq!(e[0], Event::Origin([0.0; 3]));
    match &e[1] {
        Event::Mesh(m) => {
            assert_eq!(m.vertices, 8);
            assert_eq!(m.bounds, Some(([0.0; 3], [1.0; 3])));
        }
        other => panic!("{other:?}"),
    }
    assert_eq!(materials(&reference), vec![NEUTRAL]);
}

/// A sphere of quads, smooth in the north (planar quads) and bumpy in the
/// south (quads not planar), with normals, as OBJ with
/// separately indexed normals and as PLY with normals per vertex.
fn sphere(n: usize) -> (Vec<u8>, Vec<u8>) {
    let mut v = Vec::new();
    for i in 0..=n {
        for j in 0..2 * n {
            let th = std::f64::consts::PI * i as f64 / n as f64;
            let ph = std::f64::consts::PI * j as f64 / n as f64;
            // Smooth in the northern half (its quads are planar
            // trapezoids, kept whole), bumpy in the southern (quads that are
            // not planar, triangulated).
            let r = if i <= n / 2 {
                1.0
            } else {
                1.0 + 0.05 * ((7 * i + 3 * j) % 5) as f64
            };
            let d = [th.sin() * ph.cos(), th.cos(), th.sin() * ph.sin()];
            v.push((d.map(|x| x * r), d));
        }
    }
    let idx = |i: usize, j: usize| i * 2 * n + j % (2 * n);
    let mut faces = Vec::new();
    for i in 0..n {
        for j in 0..2 * n {
            faces.push([idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1)]);
        }
    }
    let mut obj = String::new();
    let mut ply = format!(
        "ply\nformat ascii 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\nproperty float nz\nelement face {}\nproperty list uchar uint vertex_indices\nend_header\n",
        v.len(),
        faces.len()
    );
    for (p, d) in &v {
        obj += &format!("v {} {} {}\n", p[0] as f32, p[1] as f32, p[2] as f32);
        ply += &format!(
            "{} {} {} {} {} {}\n",
            p[0] as f32, p[1] as f32, p[2] as f32, d[0] as f32, d[1] as f32, d[2] as f32
        );
    }
    // OBJ normals in reverse order, so their indices differ from the
    // vertices'.
    for (_, d) in v.iter().rev() {
        obj += &format!("vn {} {} {}\n", d[0] as f32, d[1] as f32, d[2] as f32);
    }
    let nv = v.len();
    for f in &faces {
        obj += "f";
        ply += "4";
        for &k in f {
            obj += &format!(" {}//{}", k + 1, nv - k);
            ply += &format!(" {k}");
        }
        obj += "\n";
        ply += "\n";
    }
    (obj.into_bytes(), ply.into_bytes())
}

#[test]
fn the_external_join_equals_the_lookup() {
    let (obj, ply) = sphere(24);
    for (f, data) in [(Fmt::Obj, &obj), (Fmt::Ply, &ply), (Fmt::Off, &cube_off())] {
        let (a, sa, _) = read(f, data);
        // No memory: every table on disk, sorts in runs of 16 records.
        let (b, sb, _) = read_with(f, data, 0).unwrap();
        assert!(!sa.joined_on_disk && sb.joined_on_disk, "{f:?}");
        assert_eq!(a.events, b.events, "{f:?}");
        assert_eq!(sa.objects, sb.objects);
    }
    // Both formats give the same patches (same normals, indexed apart).
    let (a, _, _) = read(Fmt::Obj, &obj);
    let (b, s, _) = read(Fmt::Ply, &ply);
    assert_eq!(a.events, b.events);
    assert!(s.triangulated > 0 && s.polygons_kept > 0, "{s:?}");
    assert!(a.objects().all(|o| o.kind == ShapeKind::Patch));
}

#[test]
fn obj_corners_in_all_four_forms_and_relative_indices() {
    let base = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nvn 0 0 1\nvn 0 0 1\nvn 0 0 1\n";
    let flat = read(Fmt::Obj, format!("{base}f 1 2 3\n").as_bytes()).0;
    for f in [
        "f 1/1 2/2 3/3\n",
        "f -3/-3 -2/-2 -1/-1\n",
        "f 1/3 -2/2 3/1\n",
    ] {
        let r = read(Fmt::Obj, format!("{base}{f}").as_bytes()).0;
        assert_eq!(r.events, flat.events, "{f}");
    }
    let smooth = read(Fmt::Obj, format!("{base}f 1//1 2//2 3//3\n").as_bytes()).0;
    for f in ["f 1/1/1 2/2/2 3/3/3\n", "f -3//-3 -2//-2 -1//-1\n"] {
        let r = read(Fmt::Obj, format!("{base}{f}").as_bytes()).0;
        assert_eq!(r.events, smooth.events, "{f}");
    }
    assert_eq!(objects(&smooth)[0].0, ShapeKind::Patch);
    assert_eq!(objects(&flat)[0].0, ShapeKind::Polygon);
    assert_eq!(objects(&smooth)[0].1, objects(&flat)[0].1);
    // A corner without a normal makes the face flat.
    let mixed = read(Fmt::Obj, format!("{base}f 1//1 2 3//3\n").as_bytes()).0;
    assert_eq!(mixed.events, flat.events);
    // Continued lines, `w`, comments at ends of lines, free-form and
    // unknown statements (warned once each).
    let (r, _, w) = read(
        Fmt::Obj,
        b"v 0 0 0 1\nv 1 0 0 # x\nv 0 1 0\nf 1 \\\n 2 3\ncstype bezier\ncstype bezier\nl 1 2\nfoo bar\n",
    );
    assert_eq!(objects(&r), objects(&flat));
    assert_eq!(w.len(), 3, "{w:?}");
    assert!(w.iter().any(|m| m.contains("2 times")), "{w:?}");
}

#[test]
fn polygons_planar_kept_others_triangulated_degenerate_skipped() {
    let obj = b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 1 1 0.5\nv 2 0 0\n\
f 1 2 3 4\n\
f 1 2 5 4\n\
f 1 2 6\n\
f 1 1 3\n\
f 2 2 2\n\
f 1 2 2 3\n";
    let (r, s, w) = read(Fmt::Obj, obj);
    let o = objects(&r);
    // The planar quad whole, the twisted one as two triangles, the
    // collinear and repeated triangles skipped, the quad that repeats a
    // corner as its triangle.
    assert_eq!(
        o.iter().map(|(_, v)| v.len()).collect::<Vec<_>>(),
        vec![4, 3, 3, 3],
        "{o:?}"
    );
    assert_eq!(
        (s.faces, s.degenerate, s.polygons_kept, s.triangulated),
        (6, 3, 1, 1)
    );
    assert_eq!(w.len(), 1, "{w:?}");
    assert!(w[0].contains("skipped 3 of 6 faces as degenerate"), "{w:?}");
}

/// Found by the `ply` fuzzer: an element without properties takes no
/// bytes, so its count (here 34.5 billion) must not drive a loop.
#[test]
fn a_ply_element_without_properties_costs_nothing_whatever_its_count() {
    let mut ply = cube_ply_ascii();
    let header_end = ply.windows(10).position(|w| w == b"end_header").unwrap();
    let mut with = b"element nothing 34521931780\n".to_vec();
    with.extend_from_slice(&ply[header_end..]);
    ply.truncate(header_end);
    ply.extend_from_slice(&with);
    let start = std::time::Instant::now();
    let (_, s, _) = read(Fmt::Ply, &ply);
    assert_eq!(s.faces, 6);
    // A loop over the count would take minutes; reading takes microseconds.
    assert!(start.elapsed().as_secs() < 10, "{:?}", start.elapsed());
}

#[test]
fn ply_triangle_strips() {
    let ply = b"ply\nformat ascii 1.0\nelement vertex 7\nproperty float x\nproperty float y\nproperty float z\nelement tristrips 1\nproperty list int int vertex_indices\nend_header\n\
0 0 0\n1 0 0\n0 1 0\n1 1 0\n5 5 0\n6 5 0\n5 6 0\n\
8 0 1 2 3 -1 4 5 6\n";
    let (r, s, _) = read(Fmt::Ply, ply);
    let o = objects(&r);
    assert_eq!(s.faces, 3);
    assert_eq!(o.len(), 3);
    // Every triangle turns the same way as the first.
    let z = |v: &[[f64; 3]]| {
        (v[1][0] - v[0][0]) * (v[2][1] - v[0][1]) - (v[1][1] - v[0][1]) * (v[2][0] - v[0][0])
    };
    assert!(o.iter().all(|(_, v)| z(v) > 0.0), "{o:?}");
}

#[test]
fn colours_and_point_clouds() {
    let off = b"COFF\n4 2 0\n0 0 0 255 0 0 255\n1 0 0 255 0 0 255\n0 1 0 0 0 255 255\n1 1 0 0 0 255 255\n\
3 0 1 2\n3 1 3 2 0.0 1.0 0.0\n";
    let (r, _, _) = read(Fmt::Off, off);
    let m = materials(&r);
    assert_eq!(m.len(), 2);
    assert_eq!(m[0].color, [0.6666667, 0.0, 0.33333334]);
    assert_eq!(m[1].color, [0.0, 1.0, 0.0]);
    assert_eq!(m[1].kd, NEUTRAL.kd);
    let ply = b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2 255 128 0\n";
    let (r, _, _) = read(Fmt::Ply, ply);
    assert_eq!(materials(&r)[0].color, [1.0, 128.0 / 255.0, 0.0]);
    // A point cloud: vertices, no faces, nothing to draw.
    let cloud = b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n1 1 1\n";
    let (r, s, _) = read(Fmt::Ply, cloud);
    assert_eq!((s.vertices, s.faces, r.objects().count()), (2, 0, 0));
}

#[test]
fn obj_materials_from_libraries() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("m.mtl"),
        "newmtl shiny\nKd 1 0 0\nKs 0.5 0.5 0.5\nNs 30\nillum 3\nnewmtl glass\nKd 1 1 1\nd 0.2\nNi 1.5\n",
    )
    .unwrap();
    let obj = dir.path().join("m.obj");
    std::fs::write(
        &obj,
        "mtllib m.mtl missing.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nusemtl shiny\nf 1 2 3\nusemtl glass\nf 1 2 3\nusemtl nope\nf 1 2 3\n",
    )
    .unwrap();
    let mut r = Recorder::default();
    let w = Warned::default();
    obj::read_obj(&obj, &mut r, &w, &MeshOptions::default()).unwrap();
    let m = materials(&r);
    assert_eq!(m.len(), 4, "{m:?}");
    assert_eq!(m[0], NEUTRAL);
    assert_eq!(
        (m[1].color, m[1].kd, m[1].ks, m[1].shine),
        ([1.0, 0.0, 0.0], 1.0, 0.5, 30.0)
    );
    assert_eq!((m[2].t, m[2].ior), (0.8, 1.5));
    assert_eq!(m[3], NEUTRAL);
    let w = w.0.into_inner().unwrap();
    assert_eq!(w.len(), 2, "{w:?}");
    assert!(w.iter().any(|m| m.contains("missing.mtl")), "{w:?}");
    assert!(w.iter().any(|m| m.contains("'nope'")), "{w:?}");
}

#[test]
fn compressed_files_read_like_plain_ones() {
    use sray_engine::source::SceneSource;
    use std::io::Write;
    let dir = tempfile::tempdir().unwrap();
    let plain = dir.path().join("c.ply");
    std::fs::write(&plain, cube_ply_binary(false)).unwrap();
    let gz = dir.path().join("c.ply.gz");
    let mut e = flate2::write::GzEncoder::new(
        std::fs::File::create(&gz).unwrap(),
        flate2::Compression::default(),
    );
    e.write_all(&cube_ply_binary(false)).unwrap();
    e.finish().unwrap();
    // A zstd-wrapped OBJ under a name that does not say OBJ.
    let zst = dir.path().join("c.data.zst");
    std::fs::write(&zst, zstd::encode_all(&cube_obj()[..], 3).unwrap()).unwrap();
    let events = |p: &Path| {
        let src = SceneSource::parse(p.to_str().unwrap()).unwrap();
        assert!(src.is_mesh());
        let mut r = Recorder::default();
        src.stream_into(&mut r, &Warned::default()).unwrap();
        r.events
    };
    let want = events(&plain);
    assert_eq!(events(&gz), want);
    assert_eq!(events(&zst), want);
}

#[test]
fn far_from_the_origin_keeps_its_precision() {
    let mut s = String::new();
    for v in CUBE_V {
        s += &format!(
            "v {} {} {}\n",
            v[0] * 1e-3 + 1e5,
            v[1] * 1e-3 - 2e5,
            v[2] * 1e-3 + 3e5
        );
    }
    for f in CUBE_F {
        s += &format!("f {} {} {} {}\n", f[0] + 1, f[1] + 1, f[2] + 1, f[3] + 1);
    }
    let (far, _, _) = read(Fmt::Obj, s.as_bytes());
    let (near, _, _) = read(Fmt::Obj, &cube_obj());
    // Relative to the origin, the geometry is the cube's, scaled: f32 at
    // 1e5 would have kept steps of 0.008, a whole side of this cube.
    let local =
        |r: &Recorder| -> Vec<f32> { r.objects().flat_map(|o| o.numbers().to_vec()).collect() };
    let (a, b) = (local(&far), local(&near));
    assert_eq!(a.len(), b.len());
    let shift: Vec<f64> = (0..3).map(|i| a[i] as f64 - b[i] as f64 * 1e-3).collect();
    for (k, (x, y)) in a.iter().zip(&b).enumerate() {
        assert!(
            (*x as f64 - *y as f64 * 1e-3 - shift[k % 3]).abs() < 1e-9,
            "{x} {y}"
        );
    }
    // The origin: the centre, rounded to a multiple of 2^-10 (the largest
    // power of two below the model's size, 0.0017).
    let Event::Origin(o) = far.events[0] else {
        panic!("{:?}", far.events[0])
    };
    for (x, want) in o.iter().zip([1e5 + 5e-4, -2e5 + 5e-4, 3e5 + 5e-4]) {
        assert!((x - want).abs() <= 2f64.powi(-11), "{o:?}");
        assert_eq!((x * 1024.0).fract(), 0.0, "{o:?}");
    }
}

/// Asserts that `e` names the file and a line (text) or byte (binary).
fn names(e: &str, file: &str, at: &str, what: &str) {
    assert!(
        e.starts_with(&format!("{file}:{at}")),
        "expected '{file}:{at}...' in: {e}"
    );
    assert!(e.contains(what), "expected '{what}' in: {e}");
}

const PLY_HEAD: &str = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";

#[test]
fn bad_ply_names_file_and_line_or_byte() {
    let cases: &[(&[u8], &str, &str)] = &[
        (b"plx\n", "1:", "not a PLY file"),
        (b"ply\nformat ascii 1.0\n", "2:", "no 'end_header'"),
        (b"ply\nformat binary_middle_endian 1.0\nend_header\n", "2:", "unknown PLY format"),
        (b"ply\nformat ascii 2.0\nend_header\n", "2:", "version '2.0'"),
        (b"ply\nelement vertex 1\nend_header\n", "3:", "no 'format' line"),
        (b"ply\nformat ascii 1.0\nfoo bar\nend_header\n", "3:", "unknown PLY header keyword 'foo'"),
        (b"ply\nformat ascii 1.0\nproperty float x\nend_header\n", "3:", "before any 'element'"),
        (b"ply\nformat ascii 1.0\nelement vertex -1\nend_header\n", "3:", "not a whole number"),
        (b"ply\nformat ascii 1.0\nelement vertex 1\nproperty quad x\nend_header\n", "4:", "unknown property type 'quad'"),
        (
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty list uchar float x\nproperty float y\nproperty float z\nend_header\n",
            "3:",
            "coordinate must be a scalar",
        ),
        (
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float z\nend_header\n",
            "3:",
            "no 'y' property",
        ),
        (
            b"ply\nformat ascii 1.0\nelement face 1\nproperty int vertex_indices\nend_header\n",
            "3:",
            "it must be a list",
        ),
        (
            b"ply\nformat ascii 1.0\nelement face 1\nproperty list uchar float vertex_indices\nend_header\n",
            "3:",
            "must be of an integer type",
        ),
        (
            b"ply\nformat ascii 1.0\nelement face 1\nproperty list float int vertex_indices\nend_header\n",
            "4:",
            "count must be of an integer type",
        ),
    ];
    for (data, at, what) in cases {
        names(&err(Fmt::Ply, data), "m.ply", at, what);
    }
    let body = |b: &str| [PLY_HEAD.as_bytes(), b.as_bytes()].concat();
    for (b, at, what) in [
        (
            "0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n",
            "13:",
            "vertex index 3 is out of range",
        ),
        (
            "0 0 0\n1 0 0\n0 1 0\n3 0 -1 2\n",
            "13:",
            "vertex index -1 is out of range",
        ),
        (
            "0 0 0\n1 0 0\n0 1 0\n2 0 1\n",
            "13:",
            "at least 3 are needed",
        ),
        ("0 0 0\n1 nan 0\n0 1 0\n3 0 1 2\n", "11:", "not finite"),
        ("0 0 0\n1 0 0\n0 1 inf\n3 0 1 2\n", "12:", "not finite"),
        (
            "0 0 0\n1 0 0\n0 1 1e39\n3 0 1 2\n",
            "12:",
            "beyond the range",
        ),
        (
            "0 0 0\n1 0 0\n0 1 x\n3 0 1 2\n",
            "12:",
            "'x' is not a number",
        ),
        (
            "0 0 0\n1 0 0\n0 1 0\n3 0 1 2.5\n",
            "13:",
            "'2.5' is not a whole number",
        ),
        (
            "0 0 0\n1 0 0\n0 1 0\n300 0 1 2\n",
            "13:",
            "300 is out of range for uchar",
        ),
        (
            "0 0 0\n1 0 0\n",
            "11:",
            "after 2 of the 3 'vertex' elements its header declares (line 3): truncated",
        ),
        (
            "0 0 0\n1 0 0\n0 1 0\n3 0 1\n",
            "13:",
            "after 0 of the 1 'face' elements",
        ),
    ] {
        names(&err(Fmt::Ply, &body(b)), "m.ply", at, what);
    }
    // Binary: byte offsets. The header is 150 bytes.
    let head = |n: u64, c: &str| {
        format!(
            "ply\nformat binary_little_endian 1.0\nelement vertex {n}\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list {c} int vertex_indices\nend_header\n"
        )
        .into_bytes()
    };
    let h = head(3, "uchar");
    let hl = h.len();
    let verts: Vec<u8> = [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0]
        .iter()
        .flat_map(|f| f.to_le_bytes())
        .collect();
    let face = |n: u8, idx: &[i32]| -> Vec<u8> {
        let mut f = vec![n];
        for i in idx {
            f.extend_from_slice(&i.to_le_bytes());
        }
        f
    };
    let at = |b: usize| format!(" byte {b}:");
    let e = err(Fmt::Ply, &[&h[..], &verts, &face(3, &[0, 1, 7])].concat());
    names(&e, "m.ply", &at(hl + 36), "vertex index 7 is out of range");
    let e = err(Fmt::Ply, &[&h[..], &verts, &face(3, &[0, 1])].concat());
    names(
        &e,
        "m.ply",
        &at(hl + 45),
        "after 0 of the 1 'face' elements",
    );
    let mut nan = verts.clone();
    nan[16..20].copy_from_slice(&f32::NAN.to_le_bytes());
    let e = err(Fmt::Ply, &[&h[..], &nan, &face(3, &[0, 1, 2])].concat());
    names(
        &e,
        "m.ply",
        &at(hl + 12),
        "vertex 1: a coordinate is not finite",
    );
    let e = err(Fmt::Ply, &[&h[..], &verts[..20]].concat());
    names(
        &e,
        "m.ply",
        &at(hl + 20),
        "after 1 of the 3 'vertex' elements",
    );
    // Absurd counts cost nothing: no allocation by a count.
    let e = err(
        Fmt::Ply,
        &[&head(u64::MAX / 2, "uchar")[..], &verts].concat(),
    );
    assert!(e.contains("after 3 of the"), "{e}");
    let e = err(
        Fmt::Ply,
        &[&head(3, "uint")[..], &verts, &u32::MAX.to_le_bytes()].concat(),
    );
    assert!(e.contains("more than the limit"), "{e}");
}

#[test]
fn bad_obj_names_file_and_line() {
    for (data, at, what) in [
        (
            "v 0 0 0\nv 1 0 0\nf 1 2 3\n",
            "3:",
            "vertex index 3 is out of range: 2 are defined before this line",
        ),
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n",
            "4:",
            "OBJ indices start at 1",
        ),
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -4 1 2\n",
            "4:",
            "vertex index -4 is out of range",
        ),
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n",
            "4:",
            "a face of 2 vertices; at least 3 are needed",
        ),
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/1 2 3\n",
            "4:",
            "texture coordinate index 1 is out of range",
        ),
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1//2 2 3\n",
            "4:",
            "normal index 2 is out of range",
        ),
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/2/3/4 2 3\n",
            "4:",
            "not a face corner",
        ),
        ("v 0 0 0\nv NaN 0 0\n", "2:", "not a finite number"),
        ("v 0 0\n", "1:", "'v' needs 3 coordinates"),
        ("vn 0 0 1 1\n", "1:", "'vn' takes 3 numbers"),
        ("v 0 0 0\n\0\n", "2:", "binary data"),
        ("v 0 0 0\nf 1 1 \\\n", "2:", "ends inside a continued line"),
    ] {
        names(&err(Fmt::Obj, data.as_bytes()), "m.obj", at, what);
    }
}

#[test]
fn bad_off_names_file_and_line() {
    for (data, at, what) in [
        ("", "0:", "empty"),
        ("PLY\n", "1:", "not an OFF file"),
        ("STOFF\n", "1:", "texture coordinates"),
        ("OFF BINARY\n", "1:", "binary OFF"),
        ("OFF\n3\n", "2:", "the counts line"),
        ("OFF\n3 x 0\n", "2:", "the number of faces 'x'"),
        (
            "OFF\n3 1 0\n0 0 0\n1 0 0\n",
            "4:",
            "after 2 of the 3 vertices its header (line 2) declares: truncated",
        ),
        (
            "OFF\n3 2 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
            "6:",
            "after 1 of the 2 faces",
        ),
        (
            "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n",
            "6:",
            "face 0: vertex index 3 is out of range",
        ),
        (
            "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n2 0 1\n",
            "6:",
            "at least 3 are needed",
        ),
        (
            "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n4 0 1 2\n",
            "6:",
            "it lists 3 vertex indices, its count says 4",
        ),
        (
            "OFF\n3 1 0\n0 0 0\n1 inf 0\n0 1 0\n3 0 1 2\n",
            "4:",
            "not a finite number",
        ),
        (
            "OFF\n3 1 0\n0 0 0\n1 0\n0 1 0\n3 0 1 2\n",
            "4:",
            "vertex 1 has 2 values",
        ),
        (
            "COFF\n3 1 0\n0 0 0 1 1\n",
            "3:",
            "COFF takes x y z r g b [a]",
        ),
        (
            "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2 1 2\n",
            "6:",
            "2 values after the vertex indices",
        ),
    ] {
        names(&err(Fmt::Off, data.as_bytes()), "m.off", at, what);
    }
    // A missing keyword is allowed (the counts come first).
    let (r, _, _) = read(Fmt::Off, b"3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
    assert_eq!(r.objects().count(), 1);
}
