//! Real and generated meshes end to end: counts against each file's own
//! header, bounds, renders that show the whole model, breadth-first equal
//! to depth-first, memory within the budget, models far from the origin,
//! the command line's overrides, and errors.

use crate::common;

use common::{fails, json, ok, run, shared_meshes};
use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};

/// What a mesh file says of itself, read here independently of sray:
/// vertex count, faces, triangles (n - 2 per face of n vertices), and the
/// bounds of the vertices its faces use.
#[derive(Debug)]
struct Expected {
    vertices: u64,
    faces: u64,
    triangles: u64,
    lo: [f64; 3],
    hi: [f64; 3],
}

fn open_text(p: &Path) -> Box<dyn BufRead> {
    let f = std::fs::File::open(p).unwrap();
    if p.extension().is_some_and(|e| e == "gz") {
        Box::new(BufReader::new(flate2::read::MultiGzDecoder::new(f)))
    } else {
        Box::new(BufReader::new(f))
    }
}

fn bounds_of(verts: &[[f64; 3]], used: &[bool]) -> ([f64; 3], [f64; 3]) {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for (v, u) in verts.iter().zip(used) {
        if *u {
            for i in 0..3 {
                lo[i] = lo[i].min(v[i]);
                hi[i] = hi[i].max(v[i]);
            }
        }
    }
    (lo, hi)
}

fn expected(p: &Path) -> Expected {
    let name = p.file_name().unwrap().to_str().unwrap().to_string();
    let mut verts: Vec<[f64; 3]> = Vec::new();
    let mut used: Vec<bool> = Vec::new();
    let (mut faces, mut triangles) = (0u64, 0u64);
    let nums = |l: &str| -> Vec<f64> {
        l.split_whitespace()
            .map(|t| t.parse::<f64>().unwrap())
            .collect()
    };
    if name.contains(".ply") {
        let mut r = open_text(p);
        let mut line = String::new();
        let (mut nv, mut nf, mut binary, mut props) = (0usize, 0u64, false, 0usize);
        loop {
            line.clear();
            r.read_line(&mut line).unwrap();
            let w: Vec<&str> = line.split_whitespace().collect();
            match w.as_slice() {
                ["format", f, _] => binary = *f != "ascii",
                ["element", "vertex", n] => nv = n.parse().unwrap(),
                ["element", "face", n] => nf = n.parse().unwrap(),
                ["property", _, _] if nf == 0 => props += 1,
                ["end_header"] => break,
                _ => {}
            }
        }
        if binary {
            // horse.ply: float x y z nx ny nz, then uchar-counted int lists.
            assert_eq!(props, 6, "{name}");
            let mut b = Vec::new();
            r.read_to_end(&mut b).unwrap();
            let f = |o: usize| f32::from_le_bytes(b[o..o + 4].try_into().unwrap()) as f64;
            for i in 0..nv {
                verts.push([f(24 * i), f(24 * i + 4), f(24 * i + 8)]);
            }
            used = vec![false; nv];
            let mut o = 24 * nv;
            for _ in 0..nf {
                let n = b[o] as usize;
                for k in 0..n {
                    let idx =
                        u32::from_le_bytes(b[o + 1 + 4 * k..o + 5 + 4 * k].try_into().unwrap());
                    used[idx as usize] = true;
                }
                o += 1 + 4 * n;
                faces += 1;
                triangles += n as u64 - 2;
            }
        } else {
            for _ in 0..nv {
                line.clear();
                r.read_line(&mut line).unwrap();
                let v = nums(&line);
                verts.push([v[0], v[1], v[2]]);
            }
            used = vec![false; nv];
            for _ in 0..nf {
                line.clear();
                r.read_line(&mut line).unwrap();
                let v: Vec<usize> = line
                    .split_whitespace()
                    .map(|t| t.parse().unwrap())
                    .collect();
                for &i in &v[1..] {
                    used[i] = true;
                }
                faces += 1;
                triangles += v[0] as u64 - 2;
            }
        }
        assert_eq!(verts.len(), nv, "{name}");
        assert_eq!(faces, nf, "{name}");
    } else if name.ends_with(".obj") {
        for line in open_text(p).lines() {
            let line = line.unwrap();
            let mut w = line.split_whitespace();
            match w.next() {
                Some("v") => {
                    let v: Vec<f64> = w.take(3).map(|t| t.parse().unwrap()).collect();
                    verts.push([v[0], v[1], v[2]]);
                    used.push(false);
                }
                Some("f") => {
                    let mut n = 0;
                    for c in w {
                        let i: i64 = c.split('/').next().unwrap().parse().unwrap();
                        let i = if i < 0 { verts.len() as i64 + i } else { i - 1 };
                        used[i as usize] = true;
                        n += 1;
                    }
                    faces += 1;
                    triangles += n - 2;
                }
                _ => {}
            }
        }
    } else {
        let mut lines = open_text(p)
            .lines()
            .map(|l| l.unwrap())
            .filter(|l| !l.trim().is_empty() && !l.trim_start().starts_with('#'));
        let head = lines.next().unwrap();
        assert!(head.trim().ends_with("OFF"), "{name}");
        let c: Vec<usize> = lines
            .next()
            .unwrap()
            .split_whitespace()
            .map(|t| t.parse().unwrap())
            .collect();
        for _ in 0..c[0] {
            let v = nums(&lines.next().unwrap());
            verts.push([v[0], v[1], v[2]]);
        }
        used = vec![false; c[0]];
        for _ in 0..c[1] {
            let v: Vec<usize> = lines
                .next()
                .unwrap()
                .split_whitespace()
                .map(|t| t.parse().unwrap())
                .collect();
            for &i in &v[1..=v[0]] {
                used[i] = true;
            }
            faces += 1;
            triangles += v[0] as u64 - 2;
        }
    }
    let (lo, hi) = bounds_of(&verts, &used);
    Expected {
        vertices: verts.len() as u64,
        faces,
        triangles,
        lo,
        hi,
    }
}

/// The image's pixels, RGB.
fn pixels(p: &Path) -> (u32, u32, Vec<[u8; 3]>) {
    let img = image::open(p).unwrap().to_rgb8();
    let (w, h) = img.dimensions();
    (w, h, img.pixels().map(|p| p.0).collect())
}

/// Share of pixels that are not the background, after checking that the
/// image's border is all background (the whole model is in view).
fn coverage(p: &Path) -> f64 {
    let (w, h, px) = pixels(p);
    let bg = px[0];
    // The default background, (0.1, 0.11, 0.14).
    for (c, want) in bg.iter().zip([25.5, 28.05, 35.7]) {
        assert!(
            (*c as f64 - want).abs() <= 1.0,
            "{}: corner {bg:?}",
            p.display()
        );
    }
    for y in 0..h {
        for x in 0..w {
            if x == 0 || y == 0 || x == w - 1 || y == h - 1 {
                assert_eq!(
                    px[(y * w + x) as usize],
                    bg,
                    "{}: the model touches the border at ({x}, {y})",
                    p.display()
                );
            }
        }
    }
    px.iter().filter(|c| **c != bg).count() as f64 / px.len() as f64
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn mesh_files(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| {
            let n = p.file_name().unwrap().to_str().unwrap();
            [".ply", ".obj", ".off"].iter().any(|e| n.contains(e))
        })
        .collect();
    v.sort();
    v
}

#[test]
fn every_shared_mesh_reads_converts_and_renders_whole() {
    let Some(meshes) = shared_meshes() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let files = mesh_files(&meshes);
    assert!(files.len() >= 9, "{files:?}");
    for f in files {
        let name = f.file_name().unwrap().to_str().unwrap();
        let want = expected(&f);
        let a = json(&ok(d, &["info", s(&f), "--json", "--quiet"]));
        let degenerate = a["degenerate_faces"].as_u64().unwrap();
        assert_eq!(a["vertices"], want.vertices, "{name}");
        // All these files are triangles: each is one, or skipped.
        assert_eq!(want.triangles, want.faces, "{name}");
        assert_eq!(
            a["triangles"].as_u64().unwrap() + degenerate,
            want.triangles,
            "{name}"
        );
        assert_eq!(a["objects"], a["triangles"], "{name}");
        let diag = (0..3)
            .map(|i| (want.hi[i] - want.lo[i]).powi(2))
            .sum::<f64>()
            .sqrt();
        for (key, w) in [("bbox_min", want.lo), ("bbox_max", want.hi)] {
            for i in 0..3 {
                let got = a[key][i].as_f64().unwrap();
                assert!(
                    (got - w[i]).abs() <= 1e-6 * diag + 1e-6 * w[i].abs(),
                    "{name}: {key}[{i}] {got} against {}",
                    w[i]
                );
            }
        }
        // The database says the same.
        ok(d, &["convert", s(&f), "-o", "m.sdb", "--quiet"]);
        let b = json(&ok(d, &["info", "m.sdb", "--json"]));
        for key in [
            "objects",
            "counts",
            "triangles",
            "vertices",
            "bbox_min",
            "bbox_max",
        ] {
            assert_eq!(a[key], b[key], "{name}: {key}");
        }
        assert_eq!(b["lights"], 2, "{name}: the default key and fill lights");
        // Stored as triangle runs, in spatial order (database version 6),
        // which expand to the records' size.
        assert_eq!(b["version"], 6, "{name}");
        assert_eq!(b["order"], "spatial", "{name}");
        assert_eq!(b["layout"], "triangle runs", "{name}");
        let objects = b["objects"].as_u64().unwrap();
        assert!(
            b["run_triangles"].as_u64().unwrap() * 100 >= objects * 95,
            "{name}: {b}"
        );
        assert!(b["runs"].as_u64().unwrap() * 2 <= objects, "{name}: {b}");
        assert!(
            b["raw_bytes"].as_u64().unwrap() * 2 < b["decoded_bytes"].as_u64().unwrap(),
            "{name}: {b}"
        );
        let text = ok(d, &["info", "m.sdb"]);
        assert!(text.contains("layout       triangle runs"), "{text}");
        assert!(text.contains("bytes per triangle"), "{text}");
        // The default view shows the whole model, filling a fair part of
        // the image.
        ok(
            d,
            &[
                "render", "m.sdb", "-o", "m.png", "--width", "96", "--height", "96", "--quiet",
            ],
        );
        let c = coverage(&d.join("m.png"));
        assert!(
            c > 0.08,
            "{name}: the model covers only {:.1} % of the image",
            c * 100.0
        );
        eprintln!(
            "{name}: {} triangles, {degenerate} degenerate, coverage {:.0} %",
            b["triangles"],
            c * 100.0
        );
    }
}

/// Image bytes and the SPD counts of a render.
fn render(d: &Path, args: &[&str]) -> (Vec<u8>, serde_json::Value) {
    let mut a = args.to_vec();
    a.extend(["-o", "r.png", "--stats", "r.json", "--quiet"]);
    ok(d, &a);
    (
        std::fs::read(d.join("r.png")).unwrap(),
        json(&std::fs::read_to_string(d.join("r.json")).unwrap()),
    )
}

const COUNTS: [&str; 5] = [
    "eye_rays",
    "eye_hit_rays",
    "reflect_rays",
    "refract_rays",
    "shadow_rays",
];

#[test]
fn the_dragon_breadth_first_with_a_small_budget_equals_depth_first() {
    let Some(meshes) = shared_meshes() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let dragon = meshes.join("dragon_vrip.ply.gz");
    ok(d, &["convert", s(&dragon), "-o", "dragon.sdb", "--quiet"]);
    let size = ["--width", "128", "--height", "128"];
    let (df, sd) = render(
        d,
        &[&["render", "dragon.sdb", "--mode", "df"][..], &size].concat(),
    );
    let (bf, sb) = render(
        d,
        &[
            &["render", "dragon.sdb", "--mode", "bf", "--memory", "24MiB"][..],
            &size,
        ]
        .concat(),
    );
    assert!(df == bf, "breadth-first and depth-first images differ");
    for k in COUNTS {
        assert_eq!(sd[k], sb[k], "{k}");
    }
    // Straight from the mesh file, converted under the same small budget.
    let (bf2, _) = render(
        d,
        &[
            &["render", s(&dragon), "--mode", "bf", "--memory", "24MiB"][..],
            &size,
        ]
        .concat(),
    );
    assert!(bf2 == df, "rendering the .ply.gz differs from its database");
}

/// Peak RSS of a command, from `/usr/bin/time -v`, in MiB; `None` where
/// that is missing.
fn peak_mib(d: &Path, args: &[&str]) -> Option<f64> {
    if !Path::new("/usr/bin/time").exists() {
        common::cannot_run("the peak check needs /usr/bin/time (Debian: time)");
        return None;
    }
    let o = std::process::Command::new("/usr/bin/time")
        .arg("-v")
        .arg(env!("CARGO_BIN_EXE_sray"))
        .args(args)
        .current_dir(d)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "sray {args:?}: {err}");
    let kb: f64 = err
        .lines()
        .find_map(|l| {
            l.trim()
                .strip_prefix("Maximum resident set size (kbytes): ")
        })
        .expect("no peak in /usr/bin/time's output")
        .parse()
        .unwrap();
    Some(kb / 1024.0)
}

/// Converting the full dragon with a budget smaller than its vertex array
/// (437,645 vertices: 5.0 MiB as f32 x y z, 10 MiB as the f64 the reader
/// keeps) stays within the budget plus the documented fixed overhead, and
/// gives the same database as a large budget.
#[test]
fn converting_the_dragon_stays_within_a_budget_smaller_than_its_vertices() {
    let Some(meshes) = shared_meshes() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let dragon = meshes.join("dragon_vrip.ply.gz");
    let small = peak_mib(
        d,
        &[
            "convert",
            s(&dragon),
            "-o",
            "small.sdb",
            "--memory",
            "4MiB",
            "--tmp-dir",
            ".",
            "--quiet",
        ],
    );
    ok(
        d,
        &[
            "convert",
            s(&dragon),
            "-o",
            "large.sdb",
            "--memory",
            "1GiB",
            "--quiet",
        ],
    );
    assert!(
        std::fs::read(d.join("small.sdb")).unwrap() == std::fs::read(d.join("large.sdb")).unwrap(),
        "the databases differ"
    );
    if let Some(p) = small {
        eprintln!("convert --memory 4MiB: peak {p:.1} MiB");
        assert!(p <= 4.0 + 8.0, "peak {p:.1} MiB");
    }
    // Spill files are gone.
    let left: Vec<_> = std::fs::read_dir(d)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .filter(|n| n.to_string_lossy().starts_with("sray-"))
        .collect();
    assert!(left.is_empty(), "{left:?}");
    // A render straight from the mesh under a small budget too.
    if let Some(p) = peak_mib(
        d,
        &[
            "render",
            s(&dragon),
            "-o",
            "d.png",
            "--mode",
            "bf",
            "--memory",
            "16MiB",
            "--width",
            "64",
            "--height",
            "64",
            "--quiet",
        ],
    ) {
        eprintln!("render --memory 16MiB: peak {p:.1} MiB");
        assert!(p <= 16.0 + 8.0, "peak {p:.1} MiB");
    }
}

/// A closed bumpy torus of quads, as OBJ, moved by `offset`.
fn torus_obj(offset: [f64; 3]) -> String {
    let (n, m) = (48, 24);
    let mut s = String::from("# a torus\n");
    for i in 0..n {
        for j in 0..m {
            let a = i as f64 / n as f64 * std::f64::consts::TAU;
            let b = j as f64 / m as f64 * std::f64::consts::TAU;
            let r = 0.3 + 0.02 * ((3 * i + 5 * j) % 4) as f64;
            let p = [
                (1.0 + r * b.cos()) * a.cos(),
                r * b.sin(),
                (1.0 + r * b.cos()) * a.sin(),
            ];
            s += &format!(
                "v {} {} {}\n",
                p[0] + offset[0],
                p[1] + offset[1],
                p[2] + offset[2]
            );
        }
    }
    for i in 0..n {
        for j in 0..m {
            let k = |i: usize, j: usize| (i % n) * m + (j % m) + 1;
            s += &format!(
                "f {} {} {} {}\n",
                k(i, j),
                k(i, j + 1),
                k(i + 1, j + 1),
                k(i + 1, j)
            );
        }
    }
    s
}

/// A model 1e5 from the origin (as CAD and survey data are) renders like
/// the same model at the origin: its geometry is kept relative to its
/// centre. Measured: identical images.
#[test]
fn a_model_far_from_the_origin_renders_like_at_the_origin() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("near.obj"), torus_obj([0.0; 3])).unwrap();
    std::fs::write(d.join("far.obj"), torus_obj([1e5, -1e5, 1e5])).unwrap();
    let a = json(&ok(d, &["info", "near.obj", "--json"]));
    let b = json(&ok(d, &["info", "far.obj", "--json"]));
    assert_eq!(a["triangles"], b["triangles"]);
    for (i, o) in [1e5, -1e5, 1e5].into_iter().enumerate() {
        for k in ["bbox_min", "bbox_max"] {
            let (near, far) = (a[k][i].as_f64().unwrap(), b[k][i].as_f64().unwrap());
            assert!((far - (near + o)).abs() < 0.01, "{k}[{i}]: {a} against {b}");
        }
    }
    let size = ["--width", "128", "--height", "128"];
    let mut images = Vec::new();
    for m in ["near.obj", "far.obj"] {
        for mode in ["df", "bf"] {
            let (img, _) = render(d, &[&["render", m, "--mode", mode][..], &size].concat());
            images.push(img);
        }
    }
    assert!(images[0] == images[1] && images[2] == images[3]);
    std::fs::write(d.join("near.png"), &images[0]).unwrap();
    std::fs::write(d.join("far.png"), &images[2]).unwrap();
    let (_, _, p) = pixels(&d.join("near.png"));
    let (_, _, q) = pixels(&d.join("far.png"));
    let differ: Vec<u8> = p
        .iter()
        .zip(&q)
        .filter(|(a, b)| a != b)
        .map(|(a, b)| (0..3).map(|i| a[i].abs_diff(b[i])).max().unwrap())
        .collect();
    // Documented tolerance: at most 0.1 % of pixels, by at most 2 levels.
    assert!(
        differ.len() as f64 <= 0.001 * p.len() as f64 && differ.iter().all(|&x| x <= 2),
        "{} pixels differ, by up to {:?}",
        differ.len(),
        differ.iter().max()
    );
    eprintln!(
        "far from the origin: {} of {} pixels differ",
        differ.len(),
        p.len()
    );
    assert!(coverage(&d.join("far.png")) > 0.1);
}

#[test]
fn overrides_replace_camera_lights_and_material() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("t.obj"), torus_obj([0.0; 3])).unwrap();
    let size = ["--width", "48", "--height", "48"];
    let base = render(d, &[&["render", "t.obj"][..], &size].concat()).0;
    // Each override changes the image; the default view given explicitly
    // changes nothing.
    let v = json(&ok(d, &["info", "t.obj", "--json"]));
    assert_eq!(v["lights"], 0, "a mesh file has no lights of its own");
    for extra in [
        &["--camera", "fov=60"][..],
        &["--camera", "from=0,5,0", "at=0,0,0", "up=0,0,-1"],
        &["--camera", "from=0,5,0 at=0,0,0 up=0,0,-1 fov=50"],
        &["--light", "3,3,3"],
        &["--light", "3,3,3,1,0,0", "--light", "-3,3,3,0,0,1"],
        &["--material", "1,0.5,0,1,0,0,0,1"],
    ] {
        let img = render(d, &[&["render", "t.obj"][..], &size, extra].concat()).0;
        assert!(img != base, "{extra:?} changed nothing");
    }
    // The same overrides on an NFF scene, converted and rendered.
    let nff = common::spd_fixtures().join("balls4.nff");
    let plain = render(d, &[&["render", s(&nff)][..], &size].concat()).0;
    let over = [
        "--camera",
        "fov=30",
        "--light",
        "5,5,5",
        "--material",
        "0.2,0.8,0.2,0.9,0.1,10,0,1",
    ];
    let a = render(d, &[&["render", s(&nff)][..], &size, &over].concat()).0;
    assert!(a != plain);
    ok(
        d,
        &[&["convert", s(&nff), "-o", "b.sdb"][..], &over].concat(),
    );
    let b = render(d, &[&["render", "b.sdb"][..], &size].concat()).0;
    assert!(a == b, "baked overrides render differently");
    // Overriding a database re-streams it; the file is untouched.
    let before = std::fs::read(d.join("b.sdb")).unwrap();
    let c = render(
        d,
        &[&["render", "b.sdb", "--camera", "fov=20"][..], &size].concat(),
    )
    .0;
    assert!(c != b);
    assert!(std::fs::read(d.join("b.sdb")).unwrap() == before);
    // Bad overrides are refused before any work.
    for (bad, what) in [
        (&["--camera", "eye=1,2,3"][..], "from=, at=, up= and fov="),
        (&["--camera", "fov=0"], "between 0 and 180"),
        (&["--light", "1,2"], "X,Y,Z or X,Y,Z,R,G,B"),
        (&["--material", "1,1,1"], "8 comma-separated"),
    ] {
        let e = fails(d, &[&["render", "t.obj", "-o", "x.png"][..], bad].concat());
        assert!(e.contains(what), "{bad:?}: {e}");
    }
}

/// The overrides reach the cluster: they are baked into the database the
/// client prepares.
#[test]
fn overrides_reach_local_workers() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("t.obj"), torus_obj([0.0; 3])).unwrap();
    let args = [
        "render",
        "t.obj",
        "--width",
        "40",
        "--height",
        "40",
        "--mode",
        "bf",
        "--camera",
        "fov=55",
        "--light",
        "2,4,3,1,0.8,0.6",
        "--material",
        "0.5,0.7,1,0.9,0.2,20,0,1",
    ];
    let (emb, se) = render(d, &args);
    let (clu, sc) = render(d, &[&args[..], &["--local-workers", "2"]].concat());
    assert!(emb == clu, "the cluster render differs");
    for k in COUNTS {
        assert_eq!(se[k], sc[k], "{k}");
    }
}

#[test]
fn point_clouds_and_bad_meshes_fail_clearly() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(
        d.join("cloud.ply"),
        "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n1 1 1\n",
    )
    .unwrap();
    let i = json(&ok(d, &["info", "cloud.ply", "--json"]));
    assert_eq!(
        (
            i["objects"].as_u64(),
            i["triangles"].as_u64(),
            i["vertices"].as_u64()
        ),
        (Some(0), Some(0), Some(2))
    );
    for args in [
        &["render", "cloud.ply", "-o", "c.png"][..],
        &["convert", "cloud.ply", "-o", "c.sdb"],
    ] {
        let e = fails(d, args);
        assert!(
            e.contains("nothing to render") && e.contains("point cloud of 2 vertices"),
            "{e}"
        );
    }
    std::fs::write(d.join("bad.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n").unwrap();
    let e = fails(d, &["convert", "bad.obj", "-o", "bad.sdb"]);
    assert!(
        e.contains("bad.obj:4: vertex index 4 is out of range"),
        "{e}"
    );
    std::fs::write(d.join("bad.ply"), "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n").unwrap();
    let e = fails(d, &["render", "bad.ply", "-o", "bad.png"]);
    assert!(e.contains("bad.ply:8:") && e.contains("truncated"), "{e}");
    // Nothing left behind.
    let mut left: Vec<String> = std::fs::read_dir(d)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    left.sort();
    assert_eq!(left, ["bad.obj", "bad.ply", "cloud.ply"]);
    // Degenerate faces: one summary warning, the rest renders.
    std::fs::write(
        d.join("deg.obj"),
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 2 0 0\nf 1 2 3\nf 1 2 4\nf 1 1 2\n",
    )
    .unwrap();
    let o = run(d, &["convert", "deg.obj", "-o", "deg.sdb"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert_eq!(err.matches("warning").count(), 1, "{err}");
    assert!(err.contains("skipped 2 of 3 faces as degenerate"), "{err}");
    // A budget too small for a mesh names the least.
    let e = fails(
        d,
        &["convert", "deg.obj", "-o", "x.sdb", "--memory", "1MiB"],
    );
    assert!(e.contains("at least 2.0 MiB"), "{e}");
}

#[test]
fn nff_and_databases_report_triangles_and_vertices() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let tetra = common::spd_fixtures().join("tetra6.nff");
    let a = json(&ok(d, &["info", s(&tetra), "--json"]));
    assert_eq!(
        (a["triangles"].as_u64(), a["vertices"].as_u64()),
        (Some(4096), Some(3 * 4096))
    );
    ok(d, &["convert", s(&tetra), "-o", "t.sdb"]);
    let b = json(&ok(d, &["info", "t.sdb", "--json"]));
    assert_eq!(
        (&a["triangles"], &a["vertices"]),
        (&b["triangles"], &b["vertices"])
    );
    // Gears: polygons of many vertices make n - 2 triangles each.
    let g = json(&ok(
        d,
        &[
            "info",
            s(&common::spd_fixtures().join("gears4.nff")),
            "--json",
        ],
    ));
    assert!(g["triangles"].as_u64().unwrap() > g["counts"]["polygon"].as_u64().unwrap());
    // A gzip-wrapped NFF reads like the plain file.
    let mut e = flate2::write::GzEncoder::new(
        std::fs::File::create(d.join("tetra.nff.gz")).unwrap(),
        flate2::Compression::fast(),
    );
    std::io::Write::write_all(&mut e, &std::fs::read(&tetra).unwrap()).unwrap();
    e.finish().unwrap();
    let z = json(&ok(d, &["info", "tetra.nff.gz", "--json"]));
    assert_eq!(z["compression"], "gzip");
    for k in ["objects", "triangles", "vertices", "bbox_min", "bbox_max"] {
        assert_eq!(a[k], z[k], "{k}");
    }
}
