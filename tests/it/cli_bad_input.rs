//! Bad input to `sray render`: each gets a clear error, a non-zero exit, no
//! panic, and no output file (nor a temporary one) left behind.

use crate::common;

use common::{fails, ok, sray};
use std::path::Path;

/// Files in `dir` other than `keep`.
fn leftovers(dir: &Path, keep: &[&str]) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| !keep.contains(&n.as_str()))
        .collect();
    v.sort();
    v
}

fn render_fails(dir: &Path, scene: &str, extra: &[&str], expect: &str) {
    let mut args = vec!["render", scene, "-o", "out.png"];
    args.extend_from_slice(extra);
    let err = fails(dir, &args);
    assert!(
        err.contains(expect),
        "{extra:?}: expected '{expect}' in:\n{err}"
    );
    assert!(!dir.join("out.png").exists(), "{extra:?}: output written");
}

#[test]
fn impossible_options() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for (extra, expect) in [
        (&["--width", "0"][..], "image size"),
        (&["--height", "40000"], "40000"),
        (&["--depth", "-1"], "--depth"),
        (&["--depth", "0"], "depth"),
        (&["--depth", "65"], "depth 65"),
        (&["--grid-res", "0"], "grid resolution"),
        (&["--grid-res", "0x1x1"], "grid resolution"),
        (&["--grid-res", "5x5"], "grid resolution"),
        (&["--grid-density", "0"], "grid density"),
        (&["--threads", "0"], "threads"),
        (&["--samples", "3"], "samples per pixel"),
        (&["--samples", "0"], "samples per pixel"),
        (&["--store-number", "0"], "store"),
        (&["--memory", "lots"], "--memory"),
        (&["--precision", "half"], "--precision"),
        (&["--mode", "fast"], "--mode"),
        (&["--local-workers", "0"], "--local-workers"),
        (
            &["--local-workers", "1", "--shard-rays", "5"],
            "rays per shard",
        ),
        (&["--local-workers", "1", "--mode", "df"], "breadth-first"),
    ] {
        render_fails(d, "spd:balls:1", extra, expect);
    }
    // A budget too small for one batch of rays says the minimum, in both
    // the breadth-first and the automatic mode.
    for mode in ["bf", "auto"] {
        render_fails(
            d,
            "spd:balls:1",
            &["--memory", "1KiB", "--mode", mode],
            "needs at least",
        );
    }
    assert_eq!(leftovers(d, &[]), Vec::<String>::new());
}

#[test]
fn unwritable_outputs_fail_before_the_render() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("file"), "not a directory").unwrap();
    for out in ["file/out.png", "missing-dir/out.png", "/proc/sray-out.png"] {
        let err = fails(
            d,
            &[
                "render",
                "spd:balls:1",
                "-o",
                out,
                "--width",
                "8",
                "--height",
                "8",
            ],
        );
        assert!(err.contains(out), "{out}: {err}");
    }
    // An unwritable statistics path fails the render and leaves no image.
    for stats in ["file/s.json", "/proc/sray-stats.json", "out.png"] {
        let err = fails(
            d,
            &[
                "render",
                "spd:balls:1",
                "-o",
                "out.png",
                "--width",
                "8",
                "--height",
                "8",
                "--stats",
                stats,
            ],
        );
        assert!(err.contains(stats), "{stats}: {err}");
        assert!(!d.join("out.png").exists(), "{stats}: image written");
    }
    assert_eq!(leftovers(d, &["file"]), Vec::<String>::new());
}

#[test]
fn malformed_scenes_and_damaged_databases() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let view = "v\nfrom 0 0 5\nat 0 0 0\nup 0 1 0\nangle 45\nhither 1\nresolution 8 8\n";
    for (text, expect) in [
        (format!("{view}q 1 2 3\n"), "bad.nff:8:"),
        (format!("{view}s 0 0 nan 1\n"), "bad.nff:8:"),
        (format!("{view}s 0 0 inf 1\n"), "bad.nff:8:"),
        (format!("{view}p 3\n0 0 0\n1 0 0\n"), "bad.nff"),
        (format!("{view}p 99999999\n0 0 0\n"), "bad.nff:8:"),
        ("s 0 0 0 1\n".to_string(), "bad.nff:1:"),
        (format!("{view}s 0 0 0\n"), "bad.nff:8:"),
        ("\u{0}\u{1}binary".to_string(), "bad.nff:1:"),
    ] {
        std::fs::write(d.join("bad.nff"), text).unwrap();
        render_fails(d, "bad.nff", &[], expect);
    }
    // A real database, then damaged: a flipped byte in the objects and a
    // truncation. Both tracers refuse it, naming the block.
    ok(d, &["gen", "balls", "--size", "2", "-o", "good.sdb"]);
    let good = std::fs::read(d.join("good.sdb")).unwrap();
    let mut flipped = good.clone();
    let at = good.len() / 2;
    flipped[at] ^= 0x40;
    std::fs::write(d.join("flipped.sdb"), &flipped).unwrap();
    std::fs::write(d.join("short.sdb"), &good[..good.len() * 2 / 3]).unwrap();
    for db in ["flipped.sdb", "short.sdb"] {
        for mode in ["df", "bf"] {
            render_fails(d, db, &["--mode", mode], db);
        }
    }
    let err = fails(d, &["render", "flipped.sdb", "-o", "out.png"]);
    assert!(err.contains("block") || err.contains("tables"), "{err}");
    assert_eq!(
        leftovers(d, &["bad.nff", "good.sdb", "flipped.sdb", "short.sdb"]),
        Vec::<String>::new()
    );
}

/// Runs `sray ARGS` under `sh -c PREFIX`, so that the prefix can set a
/// limit or a mount first.
fn sray_under(dir: &Path, wrapper: &[&str], script: &str, args: &[&str]) -> std::process::Output {
    let bin = sray().get_program().to_owned();
    let mut cmd = std::process::Command::new(wrapper[0]);
    cmd.args(&wrapper[1..])
        .arg("sh")
        .arg("-c")
        .arg(format!(
            "{script}; \"$0\" \"$@\"; rc=$?; ls -A spill >&2; exit $rc"
        ))
        .arg(bin)
        .args(args)
        .current_dir(dir);
    cmd.output().unwrap()
}

/// A spill directory that fills up mid-render: a clear error naming the
/// spill, no image, and the spill files removed. Two ways to make it full:
/// a file-size limit (works everywhere) and a 64 KiB tmpfs mounted in a
/// user namespace (where the kernel allows one).
#[test]
fn a_full_spill_directory() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(d, &["gen", "balls", "--size", "3", "-o", "balls.sdb"]);
    std::fs::create_dir(d.join("spill")).unwrap();
    let args = [
        "render",
        "balls.sdb",
        "-o",
        "out.png",
        "--mode",
        "bf",
        "--width",
        "128",
        "--height",
        "128",
        "--memory",
        "1MiB",
        "--tmp-dir",
        "spill",
    ];
    // Unlimited, the render works and spills.
    let o = sray_under(
        d,
        &["env"],
        "true",
        &[&args[..], &["--stats", "s.json"]].concat(),
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s = common::json(&std::fs::read_to_string(d.join("s.json")).unwrap());
    assert!(s["spill_bytes_written"].as_u64().unwrap() > 64 << 10, "{s}");
    std::fs::remove_file(d.join("out.png")).unwrap();

    let mut ways = vec![("file-size limit", vec!["env"], "ulimit -f 64")];
    let userns = std::process::Command::new("unshare")
        .args(["--user", "--map-root-user", "--mount", "true"])
        .status()
        .is_ok_and(|s| s.success());
    if userns {
        ways.push((
            "64 KiB tmpfs",
            vec!["unshare", "--user", "--map-root-user", "--mount"],
            "mount -t tmpfs -o size=64k tmpfs spill",
        ));
    } else {
        common::cannot_run(
            "no user namespaces here (unshare --user --map-root-user failed): the tmpfs case \
             is left out",
        );
    }
    for (what, wrapper, script) in ways {
        let o = sray_under(d, &wrapper, script, &args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{what}: the render succeeded");
        assert!(!err.contains("panicked"), "{what}: {err}");
        assert!(
            err.contains("spill") && err.contains("--tmp-dir"),
            "{what}: {err}"
        );
        // `ls -A spill` printed nothing after the error line: no spill
        // files were left.
        let last = err.lines().last().unwrap_or("");
        assert!(
            last.starts_with("sray: error:"),
            "{what}: files left in spill: {err}"
        );
        assert!(!d.join("out.png").exists(), "{what}: image written");
    }
    assert_eq!(leftovers(&d.join("spill"), &[]), Vec::<String>::new());
}
