//! Databases in spatial order (version 6): the same images as the input's
//! order from both tracers, ties still by input id, smaller files and more
//! blocks skipped for meshes whose faces come in no order, and the same
//! bytes whatever memory the sort had.

use crate::common;

use common::{json, ok, shared_meshes};
use std::path::Path;

fn info(dir: &Path, db: &str) -> serde_json::Value {
    json(&ok(dir, &["info", db, "--json"]))
}

fn stats(dir: &Path, name: &str) -> serde_json::Value {
    json(&std::fs::read_to_string(dir.join(name)).unwrap())
}

/// Renders `db` in `mode` (breadth-first under `memory`) and returns the
/// PNG's bytes.
fn render(dir: &Path, db: &str, mode: &str, memory: &str, extra: &[&str]) -> Vec<u8> {
    let out = format!("{db}.{mode}.{memory}.png");
    let mut args = vec![
        "render", db, "-o", &out, "--mode", mode, "--memory", memory, "--width", "96", "--height",
        "96", "--stats",
    ];
    let st = format!("{out}.json");
    args.push(&st);
    args.extend_from_slice(extra);
    ok(dir, &args);
    std::fs::read(dir.join(&out)).unwrap()
}

/// An OBJ of `spot.obj`'s faces in a scrambled order (a fixed
/// permutation), as an exporter that lists faces by no rule would write.
fn scrambled_spot(meshes: &Path, out: &Path) {
    let text = std::fs::read_to_string(meshes.join("spot.obj")).unwrap();
    let (faces, rest): (Vec<&str>, Vec<&str>) = text.lines().partition(|l| l.starts_with("f "));
    let n = faces.len();
    assert!(n > 1000);
    // Multiplying by a unit modulo n visits every face once.
    let step = (n / 2..n).find(|s| gcd(*s, n) == 1).unwrap();
    let mut s = rest.join("\n");
    for i in 0..n {
        s.push('\n');
        s.push_str(faces[i * step % n]);
    }
    s.push('\n');
    std::fs::write(out, s).unwrap();
}

fn gcd(a: usize, b: usize) -> usize {
    if b == 0 { a } else { gcd(b, a % b) }
}

#[test]
fn a_scrambled_mesh_in_spatial_order_renders_the_same_smaller_and_reads_less() {
    let Some(meshes) = shared_meshes() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    scrambled_spot(&meshes, &d.join("spot.obj"));
    ok(
        d,
        &[
            "convert", "-q", "spot.obj", "-o", "in.sdb", "--order", "input",
        ],
    );
    ok(
        d,
        &[
            "convert", "-q", "spot.obj", "-o", "sp.sdb", "--order", "spatial",
        ],
    );
    // The default for a scene file is the spatial order.
    ok(d, &["convert", "-q", "spot.obj", "-o", "auto.sdb"]);
    assert_eq!(
        std::fs::read(d.join("auto.sdb")).unwrap(),
        std::fs::read(d.join("sp.sdb")).unwrap()
    );
    let (i, s) = (info(d, "in.sdb"), info(d, "sp.sdb"));
    assert_eq!(i["order"], "input");
    assert_eq!(s["order"], "spatial");
    assert_eq!(s["version"], 6);
    assert_eq!(i["objects"], s["objects"]);
    let (ib, sb) = (
        i["file_bytes"].as_u64().unwrap() as f64,
        s["file_bytes"].as_u64().unwrap() as f64,
    );
    // Scrambled, neighbouring faces share no corners: runs save little.
    // In spatial order they do, ids and all.
    assert!(sb < 0.8 * ib, "spatial {sb} bytes, input {ib}");
    let text = ok(d, &["info", "sp.sdb"]);
    assert!(text.contains("objects in spatial order"), "{text}");
    ok(d, &["verify", "sp.sdb"]);

    let want = render(d, "in.sdb", "df", "1GiB", &[]);
    for (mode, memory, extra) in [
        ("df", "1GiB", &[][..]),
        ("bf", "1GiB", &[][..]),
        ("bf", "6MiB", &[][..]),
        ("bf", "6MiB", &["--shading", "join"][..]),
    ] {
        assert!(
            render(d, "sp.sdb", mode, memory, extra) == want,
            "{mode} at {memory} {extra:?}"
        );
    }
    // Depth-first lists each voxel's objects in input id order: every
    // count is the input order's too.
    let tests = |n: &str| stats(d, n)["intersection_tests_by_kind"].clone();
    assert_eq!(
        tests("in.sdb.df.1GiB.png.json"),
        tests("sp.sdb.df.1GiB.png.json")
    );
    // Late passes, with few rays left, pass over more blocks.
    render(d, "in.sdb", "bf", "6MiB", &[]);
    let bytes = |n: &str| stats(d, n)["db_bytes_read"].as_u64();
    let (bi, bs) = (
        bytes("in.sdb.bf.6MiB.png.json"),
        bytes("sp.sdb.bf.6MiB.png.json"),
    );
    assert!(bs < bi, "bytes read: spatial {bs:?}, input {bi:?}");
}

/// Two cylinders on one axis, of one radius: where both are, a ray meets
/// them at the same distance. The taller is listed first, so the input's
/// tie rule draws it (red); its box's centre is higher, so the spatial
/// order stores the shorter (green) first. A tie decided by the position
/// in the file would draw green.
#[test]
fn ties_go_to_the_input_id_whatever_the_order_on_disk() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(
        d.join("ties.nff"),
        "v\nfrom 0 -30 5\nat 0 0 5\nup 0 0 1\nangle 30\nhither 1\nresolution 32 32\n\
         l 0 -30 30\n\
         f 1 0 0 1 0 0 0 1\nc\n0 0 0 1\n0 0 20 1\n\
         f 0 1 0 1 0 0 0 1\nc\n0 0 0 1\n0 0 10 1\n",
    )
    .unwrap();
    ok(
        d,
        &[
            "convert", "-q", "ties.nff", "-o", "in.sdb", "--order", "input",
        ],
    );
    ok(
        d,
        &[
            "convert", "-q", "ties.nff", "-o", "sp.sdb", "--order", "spatial",
        ],
    );
    assert_eq!(info(d, "sp.sdb")["version"], 6);
    let want = render(d, "in.sdb", "df", "1GiB", &[]);
    let img = image::load_from_memory(&want).unwrap().to_rgb8();
    let p = img.get_pixel(48, 48);
    assert!(
        p[0] > 2 * p[1] && p[0] > 20,
        "the taller (red) wins the tie: {p:?}"
    );
    for (mode, memory) in [("df", "1GiB"), ("bf", "1GiB"), ("bf", "4MiB")] {
        assert!(
            render(d, "sp.sdb", mode, memory, &[]) == want,
            "{mode} at {memory}"
        );
    }
    // Written back in input order, as a database or as NFF, the objects
    // go back to their input ids' order: the same ties.
    ok(
        d,
        &[
            "convert", "-q", "sp.sdb", "-o", "back.sdb", "--order", "input",
        ],
    );
    ok(d, &["convert", "-q", "sp.sdb", "-o", "back.nff"]);
    ok(
        d,
        &[
            "convert",
            "-q",
            "back.nff",
            "-o",
            "again.sdb",
            "--order",
            "input",
        ],
    );
    assert_eq!(info(d, "back.sdb")["order"], "input");
    for db in ["back.sdb", "again.sdb"] {
        assert!(render(d, db, "df", "1GiB", &[]) == want, "{db}");
    }
    // Rewritten with the default order (a render with an override does
    // this too), it stays spatial and keeps its ids.
    ok(d, &["convert", "-q", "sp.sdb", "-o", "re.sdb"]);
    assert_eq!(info(d, "re.sdb")["order"], "spatial");
    assert!(render(d, "re.sdb", "bf", "1GiB", &[]) == want);
}

/// The sort spills sorted chunks to files and merges them under a small
/// budget; the database is the same, byte for byte.
#[test]
fn the_sort_writes_the_same_database_whatever_its_memory() {
    let Some(meshes) = shared_meshes() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mesh = meshes.join("dragon_vrip_res2.ply.gz");
    let mesh = mesh.to_str().unwrap();
    ok(d, &["convert", "-q", mesh, "-o", "big.sdb"]);
    ok(
        d,
        &[
            "convert",
            "-q",
            mesh,
            "-o",
            "small.sdb",
            "--memory",
            "4MiB",
            "--tmp-dir",
            ".",
        ],
    );
    assert!(
        std::fs::read(d.join("big.sdb")).unwrap() == std::fs::read(d.join("small.sdb")).unwrap()
    );
    // Nothing left behind in the temporary directory.
    let left: Vec<_> = std::fs::read_dir(d)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(left.len(), 2, "{left:?}");
}

/// A ball of 7,200 small triangles on a floor a hundred times wider, in one
/// grid (`--grids 1`): the ball crowds a few voxels. By default the
/// breadth-first tracer holds its groups of 64 as aggregates; `--aggregates
/// off` tests them one by one and `on` gives the depth-first tracer
/// aggregates too; on a cluster of local workers too. Every image is the
/// same.
#[test]
fn aggregates_change_no_image_in_either_tracer_or_on_a_cluster() {
    use std::fmt::Write;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mut nff = String::from(
        "v\nfrom 1.5 1.2 2\nat 0 0.5 0\nup 0 1 0\nangle 40\nhither 0.001\nresolution 96 96\n\
         b 0.1 0.1 0.2\nl 3 8 4\nf 0.6 0.6 0.6 1 0 0 0 1\n\
         p 4\n-50 0 -50\n-50 0 50\n50 0 50\n50 0 -50\nf 0.9 0.5 0.2 0.7 0.3 20 0 1\n",
    );
    // A UV sphere of radius 0.5 standing on the floor, in latitude bands.
    let (bands, sectors) = (60, 60);
    let at = |i: usize, j: usize| {
        let (t, p) = (
            std::f64::consts::PI * i as f64 / bands as f64,
            std::f64::consts::TAU * j as f64 / sectors as f64,
        );
        [
            0.5 * t.sin() * p.cos(),
            0.5 + 0.5 * t.cos(),
            0.5 * t.sin() * p.sin(),
        ]
    };
    for i in 0..bands {
        for j in 0..sectors {
            for tri in [
                [at(i, j), at(i + 1, j), at(i + 1, j + 1)],
                [at(i, j), at(i + 1, j + 1), at(i, j + 1)],
            ] {
                nff.push_str("p 3\n");
                for v in tri {
                    writeln!(nff, "{} {} {}", v[0], v[1], v[2]).unwrap();
                }
            }
        }
    }
    std::fs::write(d.join("ball.nff"), nff).unwrap();
    ok(d, &["convert", "ball.nff", "-o", "ball.sdb", "-q"]);
    let want = render(d, "ball.sdb", "df", "1GiB", &["--grids", "1"]);
    let df = stats(d, "ball.sdb.df.1GiB.png.json");
    assert!(df["grids"][0].get("aggregates").is_none(), "{df}");
    assert!(df["grids"][0]["nested_voxels"].as_u64() > Some(0), "{df}");
    let walks = |name: &str| stats(d, name)["aggregate_walks"].as_u64().unwrap();
    for (mode, memory, how) in [
        ("bf", "64MiB", "auto"),
        ("bf", "2MiB", "auto"),
        ("bf", "3MiB", "off"),
        ("df", "1GiB", "on"),
        ("df", "2GiB", "off"),
    ] {
        let got = render(
            d,
            "ball.sdb",
            mode,
            memory,
            &["--grids", "1", "--aggregates", how],
        );
        assert!(got == want, "{mode} under {memory}, aggregates {how}");
        let st = stats(d, &format!("ball.sdb.{mode}.{memory}.png.json"));
        match (mode, how) {
            ("bf", "auto") => {
                assert!(walks(&format!("ball.sdb.bf.{memory}.png.json")) > 0);
                assert!(st["grids"][0]["aggregates"].as_u64() > Some(10), "{st}");
            }
            ("bf", _) => {
                assert_eq!(walks("ball.sdb.bf.3MiB.png.json"), 0);
                assert!(st["grids"][0].get("aggregates").is_none(), "{st}");
            }
            (_, "on") => assert!(st["grids"][0]["aggregates"].as_u64() > Some(10), "{st}"),
            _ => assert!(st["grids"][0].get("aggregates").is_none(), "{st}"),
        }
    }
    // `sray info --aggregates` counts the groups a breadth-first render
    // with the default grids holds as aggregates; a scene file is refused.
    render(d, "ball.sdb", "bf", "32MiB", &[]);
    let st = stats(d, "ball.sdb.bf.32MiB.png.json");
    let held: u64 = st["grids"]
        .as_array()
        .unwrap()
        .iter()
        .map(|g| g["aggregates"].as_u64().unwrap_or(0))
        .sum();
    let info = json(&ok(
        d,
        &["info", "ball.sdb", "--aggregates", "--json", "-q"],
    ));
    assert_eq!(info["aggregates"].as_u64(), Some(held), "{info} {st}");
    assert_eq!(
        info["aggregate_objects"].as_u64(),
        Some(64 * held),
        "{info}"
    );
    let err = common::fails(d, &["info", "ball.nff", "--aggregates", "-q"]);
    assert!(
        err.contains("--aggregates") && err.contains("convert"),
        "{err}"
    );
    // The workers get the setting with the job.
    for how in ["auto", "off"] {
        let png = format!("cluster-{how}.png");
        ok(
            d,
            &[
                "render",
                "ball.sdb",
                "-o",
                &png,
                "--local-workers",
                "2",
                "--width",
                "96",
                "--height",
                "96",
                "--grids",
                "1",
                "--aggregates",
                how,
                "-q",
            ],
        );
        assert!(
            std::fs::read(d.join(&png)).unwrap() == want,
            "cluster, aggregates {how}"
        );
    }
}
