//! Models stored once and placed by instances (database version 5), end
//! to end. The fixtures (tests/fixtures/gltf/make.py, by trimesh) place
//! one smooth-shaded mesh four times under rotations and non-uniform
//! scales, once as one mesh the four nodes share and once as four copies.
//! An instance places its model's triangles exactly as a copy is written,
//! so the two must render byte for byte the same, in every tracer,
//! precision and shading mode, embedded and in a cluster.

use crate::common;

use crate::cli_gltf::{fixture, render};
use common::{fails, json, ok};
use std::path::Path;

fn info(d: &Path, db: &str) -> serde_json::Value {
    json(&ok(d, &["info", db, "--json"]))
}

const RAY_COUNTS: [&str; 4] = [
    "eye_hit_rays",
    "shadow_rays",
    "reflect_rays",
    "refract_rays",
];

#[test]
fn instances_render_as_their_copies_in_every_tracer() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(
        d,
        &[
            "convert",
            &fixture("spot4_smooth.glb"),
            "-o",
            "inst.sdb",
            "--quiet",
        ],
    );
    ok(
        d,
        &[
            "convert",
            &fixture("spot4_smooth_copies.glb"),
            "-o",
            "copies.sdb",
            "--quiet",
        ],
    );
    ok(
        d,
        &[
            "convert",
            &fixture("spot4_smooth.glb"),
            "--flatten-instances",
            "-o",
            "flat.sdb",
            "--quiet",
        ],
    );

    // The shared mesh is stored once: one model, four instances.
    let i = info(d, "inst.sdb");
    // A glTF is a scene file: its world's objects in spatial order; the
    // mesh is textured (version 9: its image as tiles).
    assert_eq!(i["version"], 9, "{i}");
    assert_eq!(i["textures"], 1, "{i}");
    assert_eq!(i["counts"]["instance"], 4, "{i}");
    assert_eq!(i["objects"], 4, "{i}");
    let models = i["models"].as_array().unwrap();
    assert_eq!(models.len(), 1, "{i}");
    assert_eq!(models[0]["instances"], 4, "{i}");
    let t = models[0]["triangles"].as_u64().unwrap();
    assert!(t > 5000, "{i}");
    assert_eq!(i["placed_triangles"].as_u64(), Some(4 * t), "{i}");
    assert_eq!(i["triangles"].as_u64(), Some(t), "{i}");
    let c = info(d, "copies.sdb");
    assert_eq!(c["triangles"].as_u64(), Some(4 * t), "{c}");
    assert!(c.get("models").is_none(), "{c}");
    let f = info(d, "flat.sdb");
    assert_eq!(f["triangles"].as_u64(), Some(4 * t), "{f}");
    assert!(f.get("models").is_none(), "{f}");
    // Less than half the copies' size (the copies are in spatial order,
    // which stores them more compactly than the model's input order).
    let (bi, bc) = (
        i["file_bytes"].as_u64().unwrap(),
        c["file_bytes"].as_u64().unwrap(),
    );
    assert!(2 * bi < bc, "{bi} bytes instanced, {bc} copied");

    let configs: [&[&str]; 6] = [
        &["--mode", "df"],
        &["--mode", "df", "--precision", "single"],
        &["--mode", "bf", "--memory", "16MiB"],
        &["--mode", "bf", "--memory", "16MiB", "--precision", "single"],
        &["--mode", "bf", "--memory", "16MiB", "--shading", "join"],
        &["--mode", "df", "--depth", "1", "--threads", "1"],
    ];
    let mut reference = None;
    for cfg in configs {
        let (a, sa) = render(d, &[&["render", "inst.sdb"], cfg].concat());
        let (b, sb) = render(d, &[&["render", "copies.sdb"], cfg].concat());
        let (f, _) = render(d, &[&["render", "flat.sdb"], cfg].concat());
        assert!(
            a == b,
            "{cfg:?}: the instances and the copies render differently"
        );
        assert!(
            f == b,
            "{cfg:?}: --flatten-instances renders differently from the copies"
        );
        for k in RAY_COUNTS {
            assert_eq!(sa[k], sb[k], "{cfg:?}: {k}");
        }
        assert!(sa["eye_hit_rays"].as_u64().unwrap() > 200, "{sa}");
        assert!(
            sa["intersection_tests_by_kind"]["instance"]
                .as_u64()
                .unwrap()
                > 0,
            "{sa}"
        );
        // Breadth-first equals depth-first (the same precision).
        let key = (cfg.contains(&"single"), cfg.contains(&"1"));
        match &reference {
            None => reference = Some((key, a, sa)),
            Some((k, img, st)) if *k == key => {
                assert!(*img == a, "{cfg:?}: breadth-first and depth-first differ");
                for k in RAY_COUNTS {
                    assert_eq!(st[k], sa[k], "{cfg:?}: {k}");
                }
            }
            _ => {}
        }
    }
    // Single precision: breadth-first against depth-first.
    let (x, _) = render(
        d,
        &[
            "render",
            "inst.sdb",
            "--mode",
            "df",
            "--precision",
            "single",
        ],
    );
    let (y, _) = render(
        d,
        &[
            "render",
            "inst.sdb",
            "--mode",
            "bf",
            "--memory",
            "16MiB",
            "--precision",
            "single",
        ],
    );
    assert!(
        x == y,
        "single precision: breadth-first and depth-first differ"
    );
}

#[test]
fn a_cluster_renders_instances_as_one_process_does() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(
        d,
        &[
            "convert",
            &fixture("spot4_smooth.glb"),
            "-o",
            "inst.sdb",
            "--quiet",
        ],
    );
    let args = ["render", "inst.sdb", "--mode", "bf", "--memory", "32MiB"];
    let (emb, se) = render(d, &args);
    let (clu, sc) = render(d, &[&args[..], &["--local-workers", "2"]].concat());
    assert!(emb == clu, "the cluster render differs");
    for k in RAY_COUNTS {
        assert_eq!(se[k], sc[k], "{k}");
    }
    // Rendered from the glTF file directly, too.
    let (direct, _) = render(
        d,
        &[
            "render",
            &fixture("spot4_smooth.glb"),
            "--mode",
            "bf",
            "--memory",
            "32MiB",
            "--local-workers",
            "2",
        ],
    );
    assert!(direct == emb, "the cluster render of the glTF file differs");
}

#[test]
fn a_damaged_model_table_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(
        d,
        &[
            "convert",
            &fixture("spot4.glb"),
            "-o",
            "inst.sdb",
            "--quiet",
        ],
    );
    let good = std::fs::read(d.join("inst.sdb")).unwrap();
    // Cut inside the appended model.
    std::fs::write(d.join("cut.sdb"), &good[..good.len() - 100]).unwrap();
    let e = fails(d, &["render", "cut.sdb", "-o", "x.png"]);
    assert!(e.contains("cut.sdb") && e.contains("truncated"), "{e}");
    // A byte of the model's own blocks flipped: its checksum says so.
    let mut b = good.clone();
    let at = b.len() - 2000;
    b[at] ^= 0x40;
    std::fs::write(d.join("flip.sdb"), &b).unwrap();
    let e = fails(d, &["render", "flip.sdb", "--mode", "df", "-o", "x.png"]);
    assert!(e.contains("flip.sdb") && e.contains("model"), "{e}");
    let e = fails(d, &["verify", "flip.sdb"]);
    assert!(e.contains("flip.sdb") && e.contains("model"), "{e}");
}

#[test]
fn a_budget_too_small_for_the_models_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(
        d,
        &[
            "convert",
            &fixture("spot4_smooth.glb"),
            "-o",
            "inst.sdb",
            "--quiet",
        ],
    );
    let e = fails(
        d,
        &[
            "render", "inst.sdb", "--mode", "bf", "--memory", "600KiB", "-o", "x.png",
        ],
    );
    assert!(e.contains("too small") && e.contains("models"), "{e}");
}

/// NFF has no instances: a database of models placed by instances is
/// refused as NFF output, saying why and what to convert instead, and
/// no file is left; the glTF it was made from converts, its placements
/// written as copies.
#[test]
fn an_instanced_database_is_not_written_as_nff() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let glb = fixture("spot4.glb");
    ok(d, &["convert", &glb, "-o", "inst.sdb", "--quiet"]);
    let e = fails(d, &["convert", "inst.sdb", "-o", "inst.nff", "--quiet"]);
    assert!(
        e.contains("inst.sdb")
            && e.contains("1 model(s) placed by instances")
            && e.contains("NFF cannot express")
            && e.contains(".gltf or .glb"),
        "{e}"
    );
    assert!(!e.contains("input-order"), "{e}");
    assert!(!d.join("inst.nff").exists());
    ok(d, &["convert", &glb, "-o", "copies.nff", "--quiet"]);
    let nff = std::fs::read_to_string(d.join("copies.nff")).unwrap();
    assert!(nff.lines().any(|l| l.starts_with("p ")), "no polygons");
}
