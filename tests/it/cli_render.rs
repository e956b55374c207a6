//! `sray render` as a user runs it.

use crate::common;

use common::{fails, json, ok, spd_fixtures};

const COUNTS: [&str; 6] = [
    "eye_rays",
    "eye_hit_rays",
    "reflect_rays",
    "refract_rays",
    "shadow_rays",
    "intersection_tests",
];

/// The seven SPD NFF files (tests/fixtures/spd) and the same scenes
/// generated on the fly render to identical images with identical counts.
#[test]
fn nff_and_spd_routes_render_identically() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for (name, size) in [
        ("balls", 4),
        ("gears", 4),
        ("mount", 6),
        ("rings", 7),
        ("tetra", 6),
        ("tree", 11),
        ("teapot", 12),
    ] {
        let nff = spd_fixtures().join(format!("{name}{size}.nff"));
        let spd = format!("spd:{name}:{size}");
        let small = ["--width", "96", "--height", "96", "--mode", "df"];
        let mut a = vec![
            "render",
            nff.to_str().unwrap(),
            "-o",
            "a.png",
            "--stats",
            "a.json",
        ];
        a.extend(small);
        let mut b = vec!["render", spd.as_str(), "-o", "b.png", "--stats", "b.json"];
        b.extend(small);
        // The generator's order: the same database, so the same counts.
        a.extend(["--order", "input"]);
        ok(d, &a);
        ok(d, &b);
        // In spatial order (the default for a file): the same image.
        let mut c = a.clone();
        c.truncate(c.len() - 2);
        c[3] = "c.png";
        c[5] = "c.json";
        ok(d, &c);
        assert!(
            std::fs::read(d.join("c.png")).unwrap() == std::fs::read(d.join("b.png")).unwrap(),
            "{name}: the spatial order changed the image"
        );
        let (ia, ib) = (
            std::fs::read(d.join("a.png")).unwrap(),
            std::fs::read(d.join("b.png")).unwrap(),
        );
        assert!(ia == ib, "{name}: images differ between {nff:?} and {spd}");
        let sa = json(&std::fs::read_to_string(d.join("a.json")).unwrap());
        let sb = json(&std::fs::read_to_string(d.join("b.json")).unwrap());
        for k in COUNTS {
            assert_eq!(sa[k], sb[k], "{name}: {k}");
        }
        assert_eq!(sa["eye_rays"], 97 * 97);
        assert!(
            sa["eye_hit_rays"].as_u64().unwrap() > 0,
            "{name}: nothing hit"
        );
    }
}

#[test]
fn stats_have_the_promised_keys() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(
        d,
        &[
            "render",
            "spd:tetra:3",
            "-o",
            "t.png",
            "--width",
            "32",
            "--height",
            "32",
            "--stats",
            "s.json",
        ],
    );
    let s = json(&std::fs::read_to_string(d.join("s.json")).unwrap());
    for k in [
        "mode",
        "objects",
        "eye_rays",
        "eye_hit_rays",
        "reflect_rays",
        "refract_rays",
        "shadow_rays",
        "intersection_tests",
        "intersection_tests_by_kind",
        "grid_res",
        "preprocess_seconds",
        "trace_seconds",
        "total_seconds",
        "peak_rss_bytes",
    ] {
        assert!(!s[k].is_null(), "missing {k}: {s}");
    }
    assert_eq!(s["mode"], "df");
    assert_eq!(s["objects"], 64);
    assert_eq!(s["grid_res"].as_array().unwrap().len(), 3);
    let by_kind = &s["intersection_tests_by_kind"];
    let sum: u64 = ["sphere", "polygon", "patch", "cone"]
        .iter()
        .map(|k| by_kind[k].as_u64().unwrap())
        .sum();
    assert_eq!(sum, s["intersection_tests"].as_u64().unwrap());
    assert!(s["peak_rss_bytes"].as_u64().unwrap() > 1 << 20);
    // The PNG is what was asked for.
    let png = std::fs::read(d.join("t.png")).unwrap();
    assert_eq!(&png[1..4], b"PNG");
    assert_eq!(u32::from_be_bytes(png[16..20].try_into().unwrap()), 32);
}

#[test]
fn failures_leave_no_output() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(
        d.join("bad.nff"),
        "v\nfrom 0 0 5\nat 0 0 0\nup 0 1 0\nangle 45\ns 0 0 0\n",
    )
    .unwrap();
    let err = fails(d, &["render", "bad.nff", "-o", "x.png"]);
    assert!(err.contains("bad.nff:6:"), "{err}");
    let err = fails(d, &["render", "spd:balls:1", "-o", "x.png", "--width", "0"]);
    assert!(err.contains("image size"), "{err}");
    let err = fails(d, &["render", "spd:balls:1", "-o", "x.png", "--depth", "0"]);
    assert!(err.contains("depth"), "{err}");
    let err = fails(
        d,
        &["render", "spd:balls:1", "-o", "x.png", "--grid-res", "0"],
    );
    assert!(err.contains("grid resolution"), "{err}");
    let err = fails(
        d,
        &["render", "spd:balls:1", "-o", "x.png", "--threads", "0"],
    );
    assert!(err.contains("threads"), "{err}");
    let err = fails(
        d,
        &[
            "render",
            "spd:balls:1",
            "-o",
            "/nonexistent-dir/x.png",
            "--width",
            "8",
            "--height",
            "8",
        ],
    );
    assert!(err.contains("/nonexistent-dir/x.png"), "{err}");
    let left: Vec<_> = std::fs::read_dir(d)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(
        left,
        vec![std::ffi::OsString::from("bad.nff")],
        "files left behind"
    );
}

/// Every tracer option given on the command line reaches the renderer and
/// shows in the statistics.
#[test]
fn options_reach_the_renderer() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let stats = |extra: &[&str]| {
        let mut a = vec![
            "render",
            "spd:balls:2",
            "-o",
            "o.png",
            "--width",
            "16",
            "--height",
            "16",
            "--stats",
            "s.json",
        ];
        a.extend_from_slice(extra);
        ok(d, &a);
        json(&std::fs::read_to_string(d.join("s.json")).unwrap())
    };
    // balls: the ground polygon goes to a grid of its own unless told not to.
    assert_eq!(stats(&[])["grids"].as_array().unwrap().len(), 2);
    assert_eq!(
        stats(&["--grids", "1"])["grids"].as_array().unwrap().len(),
        1
    );
    let s = stats(&["--grids", "1", "--grid-res", "5"]);
    assert_eq!(s["grid_res"], serde_json::json!([5, 5, 5]));
    let s = stats(&[
        "--mode",
        "bf",
        "--store-number",
        "2",
        "--threads",
        "1",
        "--depth",
        "2",
    ]);
    assert_eq!(s["mode"], "bf");
    assert_eq!(s["store_number"], "2");
    assert_eq!(s["threads"], 1);
    assert_eq!(s["depth"], 2);
    assert!(
        s["store_numbers"][0]
            .as_array()
            .unwrap()
            .iter()
            .all(|v| v.as_f64() == Some(2.0))
    );
    let s = stats(&["--precision", "single"]);
    assert_eq!(s["precision"], "single");
    let err = fails(d, &["render", "spd:balls:2", "-o", "o.png", "--grids", "2"]);
    assert!(err.contains("--grids"), "{err}");
}

/// `--store-number budget`: the image of the paper's adaptive store
/// number, in fewer scans of the objects (a round's last few rays walk on
/// in the pass before instead of costing one each), embedded and on a
/// local worker, which is told the policy with the job.
#[test]
fn the_budget_store_number_gives_the_same_image_in_fewer_scans() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(d, &["convert", "spd:rings:2", "-o", "r.sdb", "-q"]);
    let render = |png: &str, extra: &[&str]| {
        let mut a = vec![
            "render", "r.sdb", "-o", png, "--mode", "bf", "--width", "48", "--height", "48",
            "--stats", "s.json", "-q",
        ];
        a.extend_from_slice(extra);
        ok(d, &a);
        json(&std::fs::read_to_string(d.join("s.json")).unwrap())
    };
    let adaptive = render("a.png", &[]);
    let budget = render("b.png", &["--store-number", "budget"]);
    assert_eq!(adaptive["store_number"], "adaptive");
    assert_eq!(budget["store_number"], "budget");
    let scans = |s: &serde_json::Value| s["db_scans"].as_u64().unwrap();
    assert!(scans(&budget) < scans(&adaptive), "{budget} {adaptive}");
    let png = |f: &str| std::fs::read(d.join(f)).unwrap();
    assert_eq!(png("a.png"), png("b.png"));
    render(
        "w.png",
        &["--store-number", "budget", "--local-workers", "1"],
    );
    assert_eq!(png("a.png"), png("w.png"));
    let err = fails(
        d,
        &[
            "render",
            "r.sdb",
            "-o",
            "x.png",
            "--store-number",
            "budgets",
        ],
    );
    assert!(err.contains("budget, adaptive"), "{err}");
}

/// The breadth-first render stays within its memory budget over the
/// process's fixed footprint, in a scene with two grids, reflections and
/// spilling (before the phases gave their buffers back, 48 MiB peaked at
/// 98 MiB here). The footprint (program, libraries, thread stacks, and at
/// most 1 MiB of budget) is measured, not assumed: it grows with the
/// binary (the cluster's HTTP and gRPC stacks took it from 9.1 to 9.8 MiB).
#[test]
fn breadth_first_peak_memory_stays_within_the_budget() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // The largest of three runs: thread start-up makes it vary by a few
    // hundred KiB from run to run.
    let fixed = (0..3)
        .map(|_| {
            ok(
                d,
                &[
                    "render",
                    "spd:balls:1",
                    "-o",
                    "f.png",
                    "--mode",
                    "bf",
                    "--memory",
                    "1MiB",
                    "--width",
                    "16",
                    "--height",
                    "16",
                    "--stats",
                    "f.json",
                ],
            );
            let f = json(&std::fs::read_to_string(d.join("f.json")).unwrap());
            f["peak_rss_bytes"].as_f64().unwrap() / (1 << 20) as f64
        })
        .fold(0.0, f64::max);
    assert!(fixed < 16.0, "the fixed footprint alone is {fixed:.1} MiB");
    for (budget, mib) in [("8MiB", 8.0), ("48MiB", 48.0)] {
        ok(
            d,
            &[
                "render",
                "spd:rings:4",
                "-o",
                "r.png",
                "--mode",
                "bf",
                "--memory",
                budget,
                "--width",
                "256",
                "--height",
                "256",
                "--stats",
                "r.json",
            ],
        );
        let s = json(&std::fs::read_to_string(d.join("r.json")).unwrap());
        let peak = s["peak_rss_bytes"].as_f64().unwrap() / (1 << 20) as f64;
        assert!(s["spill_bytes_written"].as_u64().unwrap() > 0, "{s}");
        assert!(
            peak <= fixed + mib,
            "--memory {budget}: peak RSS {peak:.1} MiB is over the budget plus the \
             fixed footprint of {fixed:.1} MiB"
        );
    }
}

/// `--full-scans` (the paper's passes, for `sray bench`): every pass reads
/// every block, and the image is the same; a cluster refuses it.
#[test]
fn full_scans_read_every_block_and_change_nothing_else() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(d, &["convert", "spd:tetra:6", "-o", "t.sdb", "-q"]);
    let render = |png: &str, extra: &[&str]| {
        let mut a = vec![
            "render",
            "t.sdb",
            "-o",
            png,
            "--mode",
            "bf",
            "--width",
            "48",
            "--height",
            "48",
            "--store-number",
            "1",
            "--memory",
            "2MiB",
            "--stats",
            "s.json",
            "-q",
        ];
        a.extend_from_slice(extra);
        ok(d, &a);
        json(&std::fs::read_to_string(d.join("s.json")).unwrap())
    };
    let fast = render("fast.png", &[]);
    let full = render("full.png", &["--full-scans"]);
    assert!(fast["db_blocks_skipped"].as_u64().unwrap() > 0, "{fast}");
    assert_eq!(full["db_blocks_skipped"].as_u64(), Some(0), "{full}");
    assert_eq!(fast["db_scans"], full["db_scans"]);
    assert!(full["db_bytes_read"].as_u64() > fast["db_bytes_read"].as_u64());
    assert_eq!(
        std::fs::read(d.join("fast.png")).unwrap(),
        std::fs::read(d.join("full.png")).unwrap()
    );
    let err = fails(
        d,
        &[
            "render",
            "t.sdb",
            "-o",
            "c.png",
            "--full-scans",
            "--local-workers",
            "1",
        ],
    );
    assert!(err.contains("--full-scans"), "{err}");
    assert!(!d.join("c.png").exists());
}
