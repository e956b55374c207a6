//! `sray gen`, `convert`, `info` and `verify` as a user runs them.

use crate::common;

use common::{fails, json, ok, spd_fixtures};

#[test]
fn gen_writes_the_spd_text_exactly() {
    let dir = tempfile::tempdir().unwrap();
    for (name, size) in [("balls", 4), ("gears", 4), ("teapot", 12)] {
        let out = format!("{name}.nff");
        ok(
            dir.path(),
            &["gen", name, "--size", &size.to_string(), "-o", &out],
        );
        let ours = std::fs::read(dir.path().join(&out)).unwrap();
        let spd = std::fs::read(spd_fixtures().join(format!("{name}{size}.nff"))).unwrap();
        assert!(
            ours == spd,
            "{name}{size}: sray gen output differs from the SPD's"
        );
    }
}

#[test]
fn gen_database_and_info_json() {
    let dir = tempfile::tempdir().unwrap();
    ok(dir.path(), &["gen", "tetra", "--size", "5", "-o", "t.sdb"]);
    ok(
        dir.path(),
        &[
            "gen",
            "tetra",
            "--size",
            "5",
            "-o",
            "tz.sdb",
            "--compress",
            "zstd:9",
        ],
    );
    let a = json(&ok(dir.path(), &["info", "t.sdb", "--json"]));
    let b = json(&ok(dir.path(), &["info", "tz.sdb", "--json"]));
    assert_eq!(a["objects"], 1024);
    assert_eq!(a["counts"]["polygon"], 1024);
    assert_eq!(a["counts"]["sphere"], 0);
    assert_eq!(a["counts"]["patch"], 0);
    assert_eq!(a["counts"]["cone"], 0);
    assert_eq!(a["lights"], 1);
    assert_eq!(a["materials"], 1);
    assert_eq!(a["compression"], "none");
    assert_eq!(b["compression"], "zstd");
    assert_eq!(a["bbox_min"], b["bbox_min"]);
    assert_eq!(a["bbox_max"], serde_json::json!([1.0, 1.0, 1.0]));
    assert!(b["file_bytes"].as_u64().unwrap() < a["file_bytes"].as_u64().unwrap());
    assert_eq!(
        a["file_bytes"].as_u64().unwrap(),
        std::fs::metadata(dir.path().join("t.sdb")).unwrap().len()
    );
    let v = json(&ok(dir.path(), &["verify", "tz.sdb", "--json"]));
    assert_eq!(v["objects"], 1024);
}

#[test]
fn info_is_the_same_for_nff_and_converted_database() {
    let dir = tempfile::tempdir().unwrap();
    for (name, size) in [("rings", 7), ("tree", 11), ("mount", 6)] {
        let nff = spd_fixtures().join(format!("{name}{size}.nff"));
        let nff = nff.to_str().unwrap();
        ok(
            dir.path(),
            &["convert", nff, "-o", "x.sdb", "--compress", "zstd"],
        );
        let a = json(&ok(dir.path(), &["info", nff, "--json"]));
        let b = json(&ok(dir.path(), &["info", "x.sdb", "--json"]));
        for key in [
            "objects",
            "counts",
            "lights",
            "materials",
            "bbox_min",
            "bbox_max",
        ] {
            assert_eq!(a[key], b[key], "{name}: {key}");
        }
        assert_eq!(
            a["file_bytes"].as_u64().unwrap(),
            std::fs::metadata(nff).unwrap().len()
        );
        assert_eq!(a["compression"], "none");
    }
}

#[test]
fn bad_nff_gives_file_and_line_and_no_output() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("bad.nff"),
        "v\nfrom 0 0 5\nat 0 0 0\nup 0 1 0\nangle 45\nhither 1\nresolution 8 8\ns 0 0 oops 1\n",
    )
    .unwrap();
    let err = fails(dir.path(), &["convert", "bad.nff", "-o", "bad.sdb"]);
    assert!(
        err.contains("bad.nff:8:") && err.contains("'oops' is not a number"),
        "{err}"
    );
    assert!(!dir.path().join("bad.sdb").exists());
    let leftovers: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
    assert_eq!(leftovers.len(), 1, "temporary files left behind");
    let err = fails(dir.path(), &["info", "bad.nff"]);
    assert!(err.contains("bad.nff:8:"), "{err}");
}

#[test]
fn impossible_requests_fail_clearly() {
    let dir = tempfile::tempdir().unwrap();
    let err = fails(dir.path(), &["gen", "tetra", "--size", "99", "-o", "t.sdb"]);
    assert!(err.contains("out of range"), "{err}");
    let err = fails(dir.path(), &["gen", "sponge", "-o", "t.sdb"]);
    assert!(err.contains("unknown SPD scene"), "{err}");
    let err = fails(dir.path(), &["gen", "tetra", "-o", "t.png"]);
    assert!(err.contains(".sdb") && err.contains(".nff"), "{err}");
    let err = fails(
        dir.path(),
        &["gen", "tetra", "-o", "t.sdb", "--compress", "zstd:99"],
    );
    assert!(err.contains("zstd level"), "{err}");
    let err = fails(
        dir.path(),
        &["gen", "tetra", "-o", "/nonexistent-dir/t.sdb"],
    );
    assert!(err.contains("/nonexistent-dir/t.sdb"), "{err}");
    let err = fails(dir.path(), &["info", "missing.sdb"]);
    assert!(err.contains("missing.sdb"), "{err}");
    std::fs::write(
        dir.path().join("junk.sdb"),
        b"SRAYSDB\0 this is not a database",
    )
    .unwrap();
    let err = fails(dir.path(), &["info", "junk.sdb"]);
    assert!(err.contains("junk.sdb: header:"), "{err}");
}

/// `sray info X | head`: a reader that closes the pipe early ends the
/// output quietly (exit 0, nothing on stderr), as `sray status` and
/// `sray verify` do; no panic about a broken pipe.
#[test]
fn info_into_a_closed_pipe_ends_quietly() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(d, &["gen", "tetra", "--size", "3", "-o", "t.sdb"]);
    for args in [
        &["info", "t.sdb"][..],
        &["info", "t.sdb", "--json"],
        &["verify", "t.sdb"],
    ] {
        // The pipe's reader is gone before sray writes: its first write
        // fails with EPIPE, every time.
        let (reader, writer) = std::io::pipe().unwrap();
        drop(reader);
        let o = common::sray()
            .current_dir(d)
            .args(args)
            .stdout(writer)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(o.status.success(), "{args:?}: {:?}\n{err}", o.status);
        assert!(err.trim().is_empty(), "{args:?}: {err}");
    }
}
