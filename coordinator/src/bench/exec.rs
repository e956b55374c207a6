//! Running commands for measurement: the `sray` binary itself (so a run is
//! a whole process, as the comparisons with other renderers need), and
//! other programs, with wall time and peak memory.

use anyhow::{Context, bail};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

/// One measured run.
#[derive(Clone, Debug)]
pub struct Measured {
    pub seconds: f64,
    /// Peak resident set size in KiB (0 when unknown).
    pub peak_kib: u64,
    /// `--stats` of an sray run.
    pub stats: Option<Value>,
}

/// `/usr/bin/time`, if present, measures a child's peak memory.
fn time_program() -> Option<&'static Path> {
    let p = Path::new("/usr/bin/time");
    p.exists().then_some(p)
}

/// Runs `program args` and measures it; fails if it fails.
pub fn measure(program: &Path, args: &[String], cwd: &Path) -> anyhow::Result<Measured> {
    let report = cwd.join(".bench-time");
    let mut cmd = match time_program() {
        Some(t) => {
            let mut c = Command::new(t);
            c.arg("-f").arg("%e %M").arg("-o").arg(&report).arg(program);
            c
        }
        None => Command::new(program),
    };
    cmd.args(args).current_dir(cwd);
    let start = Instant::now();
    let out = cmd
        .output()
        .with_context(|| format!("cannot run {}", program.display()))?;
    let wall = start.elapsed().as_secs_f64();
    if !out.status.success() {
        bail!(
            "{} {} failed: {}\n{}",
            program.display(),
            args.join(" "),
            out.status,
            String::from_utf8_lossy(&out.stderr)
                .lines()
                .rev()
                .take(5)
                .collect::<Vec<_>>()
                .join("\n")
        );
    }
    let mut m = Measured {
        seconds: wall,
        peak_kib: 0,
        stats: None,
    };
    // Time from our own clock (`/usr/bin/time` rounds to 10 ms); peak
    // memory from `/usr/bin/time`: the largest resident set of the process
    // or of any child it waited for.
    if let Ok(s) = std::fs::read_to_string(&report) {
        if let Some(k) = s.split_whitespace().nth(1) {
            m.peak_kib = k.parse().unwrap_or(0);
        }
        let _ = std::fs::remove_file(&report);
    }
    Ok(m)
}

/// This `sray` executable.
pub fn sray_exe() -> anyhow::Result<PathBuf> {
    std::env::current_exe().context("cannot find the sray executable")
}

/// Runs `sray render ARGS --stats FILE` and reads the statistics.
pub fn sray_render(args: &[String], cwd: &Path) -> anyhow::Result<Measured> {
    let stats = cwd.join(".bench-stats.json");
    let mut a: Vec<String> = vec!["render".into()];
    a.extend(args.iter().cloned());
    a.push("--stats".into());
    a.push(stats.display().to_string());
    let mut m = measure(&sray_exe()?, &a, cwd)?;
    let text = std::fs::read_to_string(&stats).with_context(|| stats.display().to_string())?;
    m.stats = Some(serde_json::from_str(&text)?);
    let _ = std::fs::remove_file(&stats);
    Ok(m)
}

/// The median of `runs` runs of `f`, by time; every run's record is kept
/// in the result for the report.
pub fn median_of(
    runs: usize,
    mut f: impl FnMut() -> anyhow::Result<Measured>,
) -> anyhow::Result<Median> {
    let mut all = Vec::with_capacity(runs);
    for _ in 0..runs.max(1) {
        all.push(f()?);
    }
    all.sort_by(|a, b| a.seconds.total_cmp(&b.seconds));
    let mid = all[all.len() / 2].clone();
    Ok(Median { median: mid, all })
}

#[derive(Clone, Debug)]
pub struct Median {
    pub median: Measured,
    pub all: Vec<Measured>,
}

impl Median {
    pub fn seconds(&self) -> f64 {
        self.median.seconds
    }
    pub fn peak_kib(&self) -> u64 {
        self.all.iter().map(|m| m.peak_kib).max().unwrap_or(0)
    }
    pub fn stats(&self) -> &Value {
        self.median.stats.as_ref().unwrap_or(&Value::Null)
    }
    /// A stats field as a number, from the median run.
    pub fn stat(&self, key: &str) -> f64 {
        self.stats()[key].as_f64().unwrap_or(f64::NAN)
    }
}
