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

/// The `sray` executable the experiments run, set once by [`set_sray_exe`].
static SRAY: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();

/// Names the `sray` binary to measure: `--sray PATH`, else the running
/// executable when it is `sray` itself (`sray bench`), else an error.
pub fn set_sray_exe(explicit: Option<&Path>) -> anyhow::Result<()> {
    let p = match explicit {
        Some(p) => p.to_path_buf(),
        None => {
            let me = std::env::current_exe().context("cannot find the running executable")?;
            if me.file_stem().and_then(|s| s.to_str()) != Some("sray") {
                bail!(
                    "{} is not the sray binary: give the binary to measure with --sray PATH",
                    me.display()
                );
            }
            me
        }
    };
    let p = p
        .canonicalize()
        .with_context(|| format!("cannot find the sray binary {}", p.display()))?;
    let _ = SRAY.set(p);
    Ok(())
}

/// The `sray` binary under measurement.
pub fn sray_exe() -> anyhow::Result<PathBuf> {
    SRAY.get()
        .cloned()
        .context("internal: the sray binary to measure was not set")
}

/// `sray-paged` beside the `sray` under measurement: the same program with
/// the file-backed allocator, through which the depth-first tracer pages
/// past its budget (table2's depth-first runs).
pub fn sray_paged_exe() -> anyhow::Result<PathBuf> {
    let sray = sray_exe()?;
    let p = sray.with_file_name(format!("sray-paged{}", std::env::consts::EXE_SUFFIX));
    if !p.is_file() {
        bail!(
            "{} not found beside {}: the depth-first runs page through sray-paged \
             (cargo build --release builds it)",
            p.display(),
            sray.display()
        );
    }
    Ok(p)
}

/// Runs `sray render ARGS --stats FILE` and reads the statistics.
pub fn sray_render(args: &[String], cwd: &Path) -> anyhow::Result<Measured> {
    sray_render_with(&sray_exe()?, args, cwd)
}

/// [`sray_render`] with the binary `exe` (`sray` or `sray-paged`).
pub fn sray_render_with(exe: &Path, args: &[String], cwd: &Path) -> anyhow::Result<Measured> {
    let stats = cwd.join(".bench-stats.json");
    let mut a: Vec<String> = vec!["render".into()];
    a.extend(args.iter().cloned());
    a.push("--stats".into());
    a.push(stats.display().to_string());
    let mut m = measure(exe, &a, cwd)?;
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
    Ok(Median::of(all))
}

/// The median of a list of numbers (NaN for none).
pub fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
}

#[derive(Clone, Debug)]
pub struct Median {
    pub median: Measured,
    pub all: Vec<Measured>,
}

impl Median {
    /// The median of runs already made (at least one).
    pub fn of(mut all: Vec<Measured>) -> Median {
        all.sort_by(|a, b| a.seconds.total_cmp(&b.seconds));
        let median = all[all.len() / 2].clone();
        Median { median, all }
    }

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

/// A memory limit for child processes: a Linux cgroup (v2 `memory.max`,
/// or v1 `memory.limit_in_bytes`), which needs root.
pub struct MemoryCap {
    dir: PathBuf,
    v2: bool,
}

/// The outcome of a run under a cap.
#[derive(Clone, Debug)]
pub struct Capped {
    pub measured: Option<Measured>,
    /// Killed for exceeding the cap (out of memory).
    pub oom_killed: bool,
    /// Stopped at the time limit.
    pub timed_out: bool,
    /// Most memory the cgroup held (process and page cache), bytes.
    pub peak_bytes: u64,
    pub error: Option<String>,
}

impl MemoryCap {
    /// A new cgroup limited to `bytes`, or why there cannot be one.
    pub fn new(bytes: u64) -> Result<MemoryCap, String> {
        let name = format!("sray-bench-{}-{}", std::process::id(), bytes);
        let v2_root = Path::new("/sys/fs/cgroup");
        let v2 = std::fs::read_to_string(v2_root.join("cgroup.controllers"))
            .map(|c| c.split_whitespace().any(|x| x == "memory"))
            .unwrap_or(false);
        let (dir, limit_file) = if v2 {
            (v2_root.join(&name), "memory.max")
        } else if Path::new("/sys/fs/cgroup/memory/memory.limit_in_bytes").exists() {
            (
                PathBuf::from("/sys/fs/cgroup/memory").join(&name),
                "memory.limit_in_bytes",
            )
        } else {
            return Err(
                "no cgroup memory controller found (v2 memory.max or v1 memory.limit_in_bytes)"
                    .into(),
            );
        };
        std::fs::create_dir_all(&dir).map_err(|e| {
            format!(
                "cannot create the cgroup {} ({e}); a memory cap needs root",
                dir.display()
            )
        })?;
        let cap = MemoryCap { dir, v2 };
        std::fs::write(cap.dir.join(limit_file), bytes.to_string())
            .map_err(|e| format!("cannot set {limit_file}: {e}"))?;
        if v2 {
            // No swap either: the cap is a cap.
            let _ = std::fs::write(cap.dir.join("memory.swap.max"), "0");
        } else {
            let _ = std::fs::write(cap.dir.join("memory.swappiness"), "0");
        }
        Ok(cap)
    }

    fn read(&self, file: &str) -> Option<String> {
        std::fs::read_to_string(self.dir.join(file)).ok()
    }

    fn peak(&self) -> u64 {
        let f = if self.v2 {
            "memory.peak"
        } else {
            "memory.max_usage_in_bytes"
        };
        self.read(f)
            .and_then(|s| s.trim().parse().ok())
            .unwrap_or(0)
    }

    fn reset_peak(&self) {
        if !self.v2 {
            let _ = std::fs::write(self.dir.join("memory.max_usage_in_bytes"), "0");
        }
    }

    fn oom_kills(&self) -> u64 {
        let (file, key) = if self.v2 {
            ("memory.events", "oom_kill")
        } else {
            ("memory.oom_control", "oom_kill")
        };
        self.read(file)
            .and_then(|s| {
                s.lines()
                    .find_map(|l| l.strip_prefix(key).and_then(|v| v.trim().parse().ok()))
            })
            .unwrap_or(0)
    }

    /// Runs `program args` inside the cgroup, stopping it after
    /// `limit_secs`; never fails for the run's own failure (that is
    /// reported in the result).
    pub fn run(&self, program: &Path, args: &[String], cwd: &Path, limit_secs: f64) -> Capped {
        self.reset_peak();
        let ooms = self.oom_kills();
        let procs = self.dir.join("cgroup.procs");
        let report = cwd.join(".bench-time");
        // The shell joins the cgroup, then becomes the measured program.
        let mut cmd = Command::new("/bin/sh");
        cmd.arg("-c")
            .arg("echo $$ > \"$0\" && exec \"$@\"")
            .arg(&procs);
        if let Some(t) = time_program() {
            cmd.arg(t).arg("-f").arg("%e %M").arg("-o").arg(&report);
        }
        cmd.arg(program).args(args).current_dir(cwd);
        cmd.stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::piped());
        let start = Instant::now();
        let mut child = match cmd.spawn() {
            Ok(c) => c,
            Err(e) => {
                return Capped {
                    measured: None,
                    oom_killed: false,
                    timed_out: false,
                    peak_bytes: 0,
                    error: Some(format!("cannot run {}: {e}", program.display())),
                };
            }
        };
        let mut timed_out = false;
        let status = loop {
            if let Ok(Some(s)) = child.try_wait() {
                break Some(s);
            }
            if start.elapsed().as_secs_f64() > limit_secs {
                let _ = child.kill();
                timed_out = true;
                break child.wait().ok();
            }
            std::thread::sleep(std::time::Duration::from_millis(50));
        };
        let wall = start.elapsed().as_secs_f64();
        let mut stderr = String::new();
        if let Some(mut e) = child.stderr.take() {
            use std::io::Read;
            let _ = e.read_to_string(&mut stderr);
        }
        let oom_killed = self.oom_kills() > ooms;
        let ok = status.is_some_and(|s| s.success());
        let mut peak_kib = 0;
        if let Ok(s) = std::fs::read_to_string(&report) {
            peak_kib = s
                .split_whitespace()
                .nth(1)
                .and_then(|k| k.parse().ok())
                .unwrap_or(0);
            let _ = std::fs::remove_file(&report);
        }
        Capped {
            measured: ok.then_some(Measured {
                seconds: wall,
                peak_kib,
                stats: None,
            }),
            oom_killed,
            timed_out,
            peak_bytes: self.peak(),
            error: (!ok && !timed_out && !oom_killed)
                .then(|| stderr.lines().rev().take(3).collect::<Vec<_>>().join(" / ")),
        }
    }
}

impl Drop for MemoryCap {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir(&self.dir);
    }
}

/// `exe render ARGS` (`exe` is `sray` or `sray-paged`) under a memory
/// cap, with its statistics.
pub fn sray_render_capped(
    exe: &Path,
    cap: &MemoryCap,
    args: &[String],
    cwd: &Path,
    limit_secs: f64,
) -> anyhow::Result<Capped> {
    let stats = cwd.join(".bench-stats.json");
    let _ = std::fs::remove_file(&stats);
    let mut a: Vec<String> = vec!["render".into()];
    a.extend(args.iter().cloned());
    a.push("--stats".into());
    a.push(stats.display().to_string());
    let mut c = cap.run(exe, &a, cwd, limit_secs);
    if let Some(m) = c.measured.as_mut() {
        let text = std::fs::read_to_string(&stats)?;
        m.stats = Some(serde_json::from_str(&text)?);
        let _ = std::fs::remove_file(&stats);
    }
    Ok(c)
}

/// `sray render ARGS` under `cap` when there is one (stopped after
/// `limit_secs`), else as a plain measured run.
pub fn sray_render_maybe_capped(
    exe: &Path,
    cap: Option<&MemoryCap>,
    args: &[String],
    cwd: &Path,
    limit_secs: f64,
) -> anyhow::Result<Capped> {
    match cap {
        Some(c) => sray_render_capped(exe, c, args, cwd, limit_secs),
        None => Ok(Capped {
            measured: Some(sray_render_with(exe, args, cwd)?),
            oom_killed: false,
            timed_out: false,
            peak_bytes: 0,
            error: None,
        }),
    }
}
