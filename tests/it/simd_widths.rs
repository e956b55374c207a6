//! Every SIMD width computes the same bits: the image and every count of
//! a render are the same whichever instruction set the intersection
//! kernels run on (`--simd`, `SRAY_SIMD`), in both precisions, and on a
//! cluster whose workers run different widths.

use crate::common;

use common::{Proc, cluster, json, ok, run, shared_meshes};
use std::path::Path;

const COUNTS: [&str; 7] = [
    "eye_rays",
    "eye_hit_rays",
    "reflect_rays",
    "refract_rays",
    "shadow_rays",
    "intersection_tests",
    "intersection_tests_by_kind",
];

const WIDTHS: [&str; 5] = ["portable", "sse", "avx2", "avx512", "neon"];

/// The widths this CPU can run: `--simd` refuses the others with a clear
/// message (checked here too, so that a refusal for another reason fails).
fn widths_here(dir: &Path) -> Vec<&'static str> {
    let mut here = Vec::new();
    for w in WIDTHS {
        let o = run(
            dir,
            &[
                "render",
                "spd:balls:1",
                "-o",
                "probe.png",
                "--width",
                "8",
                "--height",
                "8",
                "--mode",
                "df",
                "--simd",
                w,
            ],
        );
        if o.status.success() {
            here.push(w);
        } else {
            let err = String::from_utf8_lossy(&o.stderr);
            assert!(err.contains("this CPU cannot run"), "--simd {w}: {err}");
        }
    }
    // Every CPU has the portable path and one native width.
    assert!(here.len() >= 2, "only {here:?}");
    assert_eq!(here[0], "portable");
    here
}

/// A render's image and statistics in `mode` (`df` or `bf`) with the
/// kernels of `simd` (forced by flag, or by environment variable when
/// `by_env`).
fn render(
    dir: &Path,
    scene: &str,
    mode: &str,
    precision: &str,
    simd: &str,
    by_env: bool,
) -> (Vec<u8>, serde_json::Value) {
    let mut args = vec![
        "render",
        scene,
        "-o",
        "w.png",
        "--width",
        "48",
        "--height",
        "40",
        "--depth",
        "3",
        "--mode",
        mode,
        "--precision",
        precision,
        "--stats",
        "w.json",
        "-q",
    ];
    if !by_env {
        args.extend_from_slice(&["--simd", simd]);
    }
    let o = common::sray()
        .current_dir(dir)
        .args(&args)
        .env(
            if by_env {
                "SRAY_SIMD"
            } else {
                "SRAY_SIMD_UNUSED"
            },
            simd,
        )
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "{scene} {simd}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let stats = json(&std::fs::read_to_string(dir.join("w.json")).unwrap());
    assert_eq!(stats["simd"], simd, "{scene}: the kernels that ran");
    (std::fs::read(dir.join("w.png")).unwrap(), stats)
}

#[test]
fn every_width_renders_the_same_image_and_counts() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let widths = widths_here(d);
    // Spheres, polygons, cylinders and cones, patches and triangles, and
    // a scanned mesh (the batched triangle path).
    let mut scenes: Vec<String> = ["balls", "gears", "rings", "tree", "teapot", "mount"]
        .iter()
        .map(|s| format!("spd:{s}:1"))
        .collect();
    let bunny = shared_meshes().map(|m| m.join("stanford-bunny.obj"));
    if let Some(b) = bunny.filter(|b| b.exists()) {
        scenes.push(b.to_string_lossy().into_owned());
    } else {
        assert!(std::env::var_os("CI").is_none(), "no shared meshes on CI");
    }
    for scene in &scenes {
        for precision in ["single", "double"] {
            // Depth-first packets and breadth-first voxels' rays both
            // test with the kernels; both tracers find the same image.
            let want = render(d, scene, "df", precision, widths[0], false);
            assert!(want.1["intersection_tests"].as_u64().unwrap() > 0);
            let bf = render(d, scene, "bf", precision, widths[0], false);
            assert!(
                bf.0 == want.0,
                "{scene} {precision}: breadth-first differs from depth-first"
            );
            for (k, w) in widths.iter().enumerate().skip(1) {
                // Every other width by flag, the last by environment.
                let by_env = k + 1 == widths.len();
                let got = render(d, scene, "df", precision, w, by_env);
                assert!(
                    got.0 == want.0,
                    "{scene} {precision}: {w} image differs from portable"
                );
                for c in COUNTS {
                    assert_eq!(got.1[c], want.1[c], "{scene} {precision}: {w} {c}");
                }
                let got = render(d, scene, "bf", precision, w, by_env);
                assert!(
                    got.0 == bf.0,
                    "{scene} {precision}: breadth-first {w} image differs from portable"
                );
                for c in COUNTS.iter().chain(&BF_COUNTS) {
                    assert_eq!(
                        got.1[c], bf.1[c],
                        "{scene} {precision}: breadth-first {w} {c}"
                    );
                }
            }
        }
    }
}

/// Counts of the breadth-first passes that the width must not change
/// either.
const BF_COUNTS: [&str; 4] = [
    "tests_skipped_mailbox",
    "tests_skipped_last_voxel",
    "ray_voxel_registrations",
    "passes",
];

#[test]
fn an_unknown_or_missing_width_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let err = common::fails(
        d,
        &["render", "spd:balls:1", "-o", "x.png", "--simd", "avx9"],
    );
    assert!(err.contains("avx9"), "{err}");
    let o = common::sray()
        .current_dir(d)
        .args([
            "render",
            "spd:balls:1",
            "-o",
            "x.png",
            "--width",
            "8",
            "--height",
            "8",
            "--mode",
            "df",
        ])
        .env("SRAY_SIMD", "mmx")
        .output()
        .unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("SRAY_SIMD") && err.contains("mmx"), "{err}");
    assert!(!err.contains("panicked"), "{err}");
}

/// Workers on different widths (as on machines with different CPUs) make
/// the embedded render's image and counts.
#[test]
fn workers_on_different_widths_agree_with_the_embedded_render() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let widths = widths_here(d);
    let scene = "spd:gears:1";
    ok(
        d,
        &[
            "render", scene, "-o", "emb.png", "--width", "40", "--height", "40", "--stats",
            "emb.json", "--mode", "bf",
        ],
    );
    let emb = std::fs::read(d.join("emb.png")).unwrap();
    // (The breadth-first counts: the cluster's workers trace breadth-first.)
    let emb_stats = json(&std::fs::read_to_string(d.join("emb.json")).unwrap());
    std::fs::write(d.join("token"), "simd-secret\n").unwrap();
    let (coord, url) = cluster::coordinator(d, &["--token-file", "token"]);
    let names = ["narrow", "wide"];
    let _workers: Vec<Proc> = names
        .iter()
        .zip([widths[0], widths[widths.len() - 1]])
        .map(|(name, w)| {
            let cache = format!("cache-{name}");
            let args = [
                "worker",
                "--coordinator",
                &url,
                "--cache-dir",
                &cache,
                "--threads",
                "1",
                "--name",
                name,
                "--token-file",
                "token",
                "--memory",
                "64MiB",
            ];
            Proc::start(d, &args, &[("SRAY_SIMD", w)])
        })
        .collect();
    for n in names {
        cluster::registered(&coord, n);
    }
    ok(
        d,
        &cluster::render_args(scene, &url, "token", "c.png", "40", "256"),
    );
    let img = std::fs::read(d.join("c.png")).unwrap();
    let stats = json(&std::fs::read_to_string(d.join("cluster.json")).unwrap());
    assert!(img == emb, "cluster image differs from the embedded render");
    for c in COUNTS {
        assert_eq!(stats[c], emb_stats[c], "{c}");
    }
}
