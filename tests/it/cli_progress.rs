//! What `sray render` shows while and after it works: progress bars and
//! the summary line on a terminal, nothing with --quiet.

use crate::common;

use common::{fails, sray};
use std::path::Path;
use std::process::Output;

const SMALL: [&str; 4] = ["--width", "40", "--height", "30"];

/// Runs `sray ARGS` in `dir` with stderr a pipe (not a terminal), with
/// the summary forced on or not.
fn run(dir: &Path, args: &[&str], force_summary: bool) -> Output {
    let mut cmd = sray();
    cmd.current_dir(dir).args(args).env_remove("SRAY_SUMMARY");
    if force_summary {
        cmd.env("SRAY_SUMMARY", "1");
    }
    let o = cmd.output().expect("run sray");
    assert!(
        o.status.success(),
        "sray {args:?} failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    o
}

fn stderr(o: &Output) -> String {
    String::from_utf8(o.stderr.clone()).unwrap()
}

#[test]
fn a_render_ends_with_one_summary_line() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mut args = vec!["render", "spd:balls:1", "-o", "x.png"];
    args.extend_from_slice(&SMALL);
    let err = stderr(&run(d, &args, true));
    let lines: Vec<&str> = err.lines().collect();
    assert_eq!(lines.len(), 1, "{err}");
    let l = lines[0];
    assert!(
        l.starts_with("sray: df (auto: the scene needs about "),
        "{l}"
    );
    for part in [", 40x30, ", " s, ", " rays/s, peak ", " MiB -> x.png"] {
        assert!(l.contains(part), "{part:?} not in {l}");
    }
    // The breadth-first tracer, and the OpenEXR output.
    args[3] = "x.exr";
    args.extend(["--mode", "bf"]);
    let err = stderr(&run(d, &args, true));
    assert!(
        err.starts_with("sray: bf (requested with --mode bf), 40x30, "),
        "{err}"
    );
    assert!(err.ends_with(" -> x.exr\n"), "{err}");
}

#[test]
fn quiet_and_pipes_show_nothing_but_errors() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mut args = vec!["render", "spd:balls:1", "-o", "x.png"];
    args.extend_from_slice(&SMALL);
    // stderr is not a terminal: no summary unless forced.
    assert_eq!(stderr(&run(d, &args, false)), "");
    args.push("--quiet");
    assert_eq!(stderr(&run(d, &args, true)), "");
    *args.last_mut().unwrap() = "-q";
    assert_eq!(stderr(&run(d, &args, true)), "");
    for cmd in [
        &["gen", "balls", "-s", "1", "-o", "b.sdb", "--quiet"][..],
        &["convert", "b.sdb", "-o", "b.nff", "--quiet"],
        &["info", "b.nff", "--quiet"],
        &["verify", "b.sdb", "--quiet"],
    ] {
        assert_eq!(stderr(&run(d, cmd, true)), "", "{cmd:?}");
    }
    // Errors still print.
    let err = fails(d, &["render", "spd:balls:1", "-o", "x.jpg", "--quiet"]);
    assert!(
        err.contains("sray: error:") && err.contains(".exr"),
        "{err}"
    );
}

#[test]
fn the_cluster_path_ends_with_a_summary_too() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mut args = vec![
        "render",
        "spd:balls:1",
        "-o",
        "c.png",
        "--local-workers",
        "1",
    ];
    args.extend_from_slice(&SMALL);
    let err = stderr(&run(d, &args, true));
    let last = err.lines().last().unwrap_or("");
    assert!(
        last.starts_with("sray: cluster (breadth-first on the cluster's workers), 40x30, "),
        "{err}"
    );
    assert!(
        last.contains(" rays/s, peak ") && last.ends_with(" -> c.png"),
        "{err}"
    );
    args.push("--quiet");
    let err = stderr(&run(d, &args, true));
    assert!(!err.contains("sray: cluster"), "{err}");
}

/// Runs `sray ARGS` on a pseudo-terminal (util-linux `script`); returns
/// what it wrote there, or None without `script`.
fn on_terminal(dir: &Path, args: &[&str]) -> Option<String> {
    let mut line = format!("'{}'", env!("CARGO_BIN_EXE_sray"));
    for a in args {
        line.push_str(&format!(" '{a}'"));
    }
    let o = std::process::Command::new("script")
        .args(["-qfec", &line, "/dev/null"])
        .current_dir(dir)
        .env_remove("SRAY_SUMMARY")
        .env("TERM", "xterm")
        .env("COLUMNS", "200")
        .stdin(std::process::Stdio::null())
        .output();
    let o = match o {
        Ok(o) => o,
        Err(e) => {
            common::cannot_run(&format!(
                "cannot run script(1) for a terminal (Debian: bsdutils): {e}"
            ));
            return None;
        }
    };
    assert!(o.status.success(), "sray {args:?} on a terminal failed");
    Some(String::from_utf8_lossy(&o.stdout).into_owned())
}

/// Every `DONE/TOTAL UNIT` a bar drew.
fn counts(screen: &str) -> Vec<(u64, u64, String)> {
    let words: Vec<&str> = screen
        .split(|c: char| c.is_whitespace() || c.is_control())
        .collect();
    let num = |s: &str| s.replace(',', "").parse::<u64>().ok();
    let mut out = Vec::new();
    for (i, w) in words.iter().enumerate() {
        if let Some((a, b)) = w.split_once('/')
            && let (Some(a), Some(b)) = (num(a), num(b))
        {
            out.push((a, b, words.get(i + 1).unwrap_or(&"").to_string()));
        }
    }
    out
}

/// On a terminal: bars whose count never passes its total, with a
/// percentage, an ETA and whole-number rates; one bar of rays over all
/// the breadth-first rounds, never going back; then the summary. --quiet:
/// nothing at all.
#[test]
fn on_a_terminal_bars_stay_within_their_totals() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let args = [
        "render",
        "spd:balls:3",
        "-o",
        "t.png",
        "--mode",
        "bf",
        "--width",
        "256",
        "--height",
        "256",
        "--threads",
        "1",
    ];
    let Some(screen) = on_terminal(d, &args) else {
        return;
    };
    let counts = counts(&screen);
    let rays: Vec<_> = counts.iter().filter(|c| c.2 == "rays").collect();
    assert!(!rays.is_empty(), "no bar of rays drawn:\n{screen}");
    for (done, total, unit) in &counts {
        assert!(done <= total, "{done}/{total} {unit} drawn:\n{screen}");
    }
    assert!(screen.contains("% "), "no percentage:\n{screen}");
    assert!(screen.contains(", eta "), "no ETA:\n{screen}");
    assert!(screen.contains(" rays/s, eta "), "no rate:\n{screen}");
    // Rates are whole numbers: "(1,234,567 rays/s".
    let words: Vec<&str> = screen.split_whitespace().collect();
    for w in words.windows(2).filter(|w| w[1] == "rays/s") {
        let n = w[0].trim_start_matches('(');
        assert!(
            !n.is_empty() && n.chars().all(|c| c.is_ascii_digit() || c == ','),
            "rate {n:?}:\n{screen}"
        );
    }
    assert!(
        screen.contains("sray: bf (requested with --mode bf), 256x256, "),
        "no summary:\n{screen}"
    );
    // One count of rays for the whole render, not one per round: what is
    // done and the total (the eye rays and an estimate of the later
    // rounds) only go up, and the round and pass are shown beside it.
    let mut last = (0, 0);
    for &&(done, total, _) in &rays {
        assert!(
            done >= last.0 && total >= last.1,
            "{done}/{total} rays drawn after {}/{}:\n{screen}",
            last.0,
            last.1
        );
        last = (done, total);
    }
    assert!(
        rays.iter().any(|r| r.1 > 257 * 257),
        "the total is the eye rays' (257 x 257 corners) only:\n{screen}"
    );
    assert!(screen.contains("round 1: pass "), "no round 1:\n{screen}");
    assert!(screen.contains("round 2: "), "no round 2:\n{screen}");

    let mut quiet = args.to_vec();
    quiet.push("--quiet");
    let screen = on_terminal(d, &quiet).unwrap();
    assert_eq!(screen.trim(), "", "--quiet on a terminal");
}
