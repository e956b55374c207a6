//! `sray bench`: the paper's experiments and the project's comparisons,
//! measured on this machine and written as data, charts and a report.
//!
//! Every timed run is a whole `sray` (or POV-Ray) process, measured with
//! `/usr/bin/time` for peak memory; figures are medians of several runs.

mod accuracy;
mod chart;
mod compressed;
mod exec;
mod fig3;
mod load;
mod povray;
mod report;
mod scaling;
mod sim;
mod table1;
mod table2;

use anyhow::Context;
use clap::{Args, ValueEnum};
use report::Report;
use sray_engine::spd::SpdScene;
use std::cell::Cell;
use std::path::{Path, PathBuf};
use std::time::Instant;

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Experiment {
    /// Depth-first against POV-Ray 3.7 (and RayShade's published times)
    Povray,
    /// The paper's Table 1: depth-first against breadth-first, split
    Table1,
    /// The paper's Table 2 and Figs. 6-8: time against size under a memory cap
    Table2,
    /// The paper's Fig. 3: remaining rays per pass, fixed and adaptive store number
    Fig3,
    /// The paper's Fig. 9 and Table 3: compressed databases, the biggest scenes
    Compressed,
    /// Render time against image error over depth, precision and sampling
    Accuracy,
    /// The cluster: embedded against 1 and 2 local workers, traffic per ray
    Scaling,
    /// The coordinator under 100 and 1,000 simulated workers: CPU and memory
    /// per ray, task and worker, latencies (only when named: not in the default set)
    Load,
}

impl Experiment {
    /// What `sray bench` runs when no experiment is named (the load
    /// harness is left out: it is about the coordinator, not the paper).
    const ALL: [Experiment; 7] = [
        Experiment::Povray,
        Experiment::Table1,
        Experiment::Table2,
        Experiment::Fig3,
        Experiment::Compressed,
        Experiment::Accuracy,
        Experiment::Scaling,
    ];
}

#[derive(Args, Debug)]
pub struct BenchArgs {
    /// Experiments to run (default: all)
    pub experiments: Vec<Experiment>,
    /// Small images and one run each: every experiment in a few minutes
    #[arg(long)]
    pub quick: bool,
    /// Directory for the report, data and charts
    #[arg(long, default_value = "bench-results")]
    pub out: PathBuf,
    /// Runs per measurement; the median is reported (default 5, 1 with --quick)
    #[arg(long)]
    pub runs: Option<usize>,
    /// Directory with the SPD's POV-Ray files (default: ../shared/spd if present)
    #[arg(long)]
    pub spd_dir: Option<PathBuf>,
    /// The sray binary to measure (default: this one)
    #[arg(long)]
    pub sray: Option<PathBuf>,
}

/// What every experiment shares: settings, a scratch directory, progress.
pub struct Ctx {
    pub quick: bool,
    pub runs: usize,
    pub spd_dir: Option<PathBuf>,
    pub work: tempfile::TempDir,
    steps_total: Cell<usize>,
    steps_done: Cell<usize>,
    started: Instant,
}

impl Ctx {
    /// Image side for the experiments that use the paper's 512x512.
    pub fn side(&self) -> u32 {
        if self.quick { 64 } else { 512 }
    }

    /// The seven default scenes (the paper's Table 1).
    pub fn scenes(&self) -> Vec<(SpdScene, u32)> {
        SpdScene::ALL
            .iter()
            .map(|&s| (s, s.default_size()))
            .collect()
    }

    pub fn work(&self) -> &Path {
        self.work.path()
    }

    /// A scene file in the scratch directory, generated on first use by
    /// `sray gen` (`ext` is `sdb` or `nff`).
    pub fn scene_file(&self, scene: SpdScene, size: u32, ext: &str) -> anyhow::Result<PathBuf> {
        let p = self.work().join(format!("{}{size}.{ext}", scene.name()));
        if !p.exists() {
            let args = [
                "gen",
                scene.name(),
                "--size",
                &size.to_string(),
                "-o",
                &p.display().to_string(),
            ];
            exec::measure(&exec::sray_exe()?, &args.map(String::from), self.work())?;
        }
        Ok(p)
    }

    /// Announces a measurement step with the running estimate of what is left.
    pub fn step(&self, what: &str) {
        let done = self.steps_done.get();
        let total = self.steps_total.get().max(done + 1);
        let el = self.started.elapsed().as_secs_f64();
        let eta = if done > 0 {
            format!(
                ", about {} left",
                fmt_duration(el / done as f64 * (total - done) as f64)
            )
        } else {
            String::new()
        };
        eprintln!("[{}/{total}, {}{eta}] {what}", done + 1, fmt_duration(el));
        self.steps_done.set(done + 1);
    }

    /// `runs` measured runs of one step, announced as one.
    pub fn median(
        &self,
        what: &str,
        f: impl FnMut() -> anyhow::Result<exec::Measured>,
    ) -> anyhow::Result<exec::Median> {
        self.step(what);
        exec::median_of(self.runs, f)
    }
}

pub fn fmt_duration(s: f64) -> String {
    let s = s.max(0.0).round() as u64;
    if s >= 3600 {
        format!("{}h{:02}m", s / 3600, s / 60 % 60)
    } else if s >= 60 {
        format!("{}m{:02}s", s / 60, s % 60)
    } else {
        format!("{s}s")
    }
}

/// An experiment: how many steps and how long it should take, and the run.
struct Plan {
    steps: usize,
    seconds: f64,
}

fn plan(e: Experiment, ctx: &Ctx) -> Plan {
    match e {
        Experiment::Povray => povray::plan(ctx),
        Experiment::Table1 => table1::plan(ctx),
        Experiment::Table2 => table2::plan(ctx),
        Experiment::Fig3 => fig3::plan(ctx),
        Experiment::Compressed => compressed::plan(ctx),
        Experiment::Accuracy => accuracy::plan(ctx),
        Experiment::Scaling => scaling::plan(ctx),
        Experiment::Load => load::plan(ctx),
    }
}

fn run_one(e: Experiment, ctx: &Ctx, r: &mut Report) -> anyhow::Result<()> {
    match e {
        Experiment::Povray => povray::run(ctx, r),
        Experiment::Table1 => table1::run(ctx, r),
        Experiment::Table2 => table2::run(ctx, r),
        Experiment::Fig3 => fig3::run(ctx, r),
        Experiment::Compressed => compressed::run(ctx, r),
        Experiment::Accuracy => accuracy::run(ctx, r),
        Experiment::Scaling => scaling::run(ctx, r),
        Experiment::Load => load::run(ctx, r),
    }
}

/// A description of this machine for the report.
fn machine() -> String {
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split(':').nth(1))
                .map(|m| m.trim().to_string())
        })
        .unwrap_or_else(|| "unknown CPU".into());
    let mem = sray_engine::sys::mem_total_bytes()
        .map(sray_engine::units::fmt_bytes)
        .unwrap_or_default();
    format!(
        "{cpu}, {} logical CPUs, {mem} memory, {} {}",
        sray_engine::sys::cpus(),
        std::env::consts::OS,
        std::env::consts::ARCH
    )
}

pub fn run(a: BenchArgs) -> anyhow::Result<()> {
    exec::set_sray_exe(a.sray.as_deref())?;
    let mut exps = if a.experiments.is_empty() {
        Experiment::ALL.to_vec()
    } else {
        a.experiments.clone()
    };
    exps.dedup();
    // Runs happen in the scratch directory: every path must be absolute.
    let spd_dir = a
        .spd_dir
        .clone()
        .or_else(|| Some(PathBuf::from("../shared/spd")).filter(|d| d.is_dir()))
        .map(|d| d.canonicalize().with_context(|| d.display().to_string()))
        .transpose()?;
    std::fs::create_dir_all(&a.out)
        .with_context(|| format!("cannot create {}", a.out.display()))?;
    let out = a.out.canonicalize()?;
    let mut report = Report::new(&out)?;
    let work = tempfile::Builder::new()
        .prefix(".bench-work-")
        .tempdir_in(&report.dir)
        .with_context(|| {
            format!(
                "cannot create a scratch directory in {}",
                report.dir.display()
            )
        })?;
    let ctx = Ctx {
        quick: a.quick,
        runs: a.runs.unwrap_or(if a.quick { 1 } else { 5 }).max(1),
        spd_dir,
        work,
        steps_total: Cell::new(0),
        steps_done: Cell::new(0),
        started: Instant::now(),
    };
    let plans: Vec<Plan> = exps.iter().map(|&e| plan(e, &ctx)).collect();
    ctx.steps_total.set(plans.iter().map(|p| p.steps).sum());
    let expected: f64 = plans.iter().map(|p| p.seconds).sum();
    eprintln!(
        "sray bench: {} ({} steps, {} run(s) each); expected duration about {}; results in {}",
        exps.iter()
            .map(|e| format!("{e:?}").to_lowercase())
            .collect::<Vec<_>>()
            .join(", "),
        ctx.steps_total.get(),
        ctx.runs,
        fmt_duration(expected),
        report.dir.display()
    );
    for &e in &exps {
        run_one(e, &ctx, &mut report).with_context(|| format!("experiment {e:?}"))?;
    }
    let preamble = format!(
        "Machine: {}.\n\nsray {} ({}), {} run(s) per figure, medians reported{}. Total time {}.\n",
        machine(),
        env!("CARGO_PKG_VERSION"),
        if cfg!(debug_assertions) {
            "debug build: times are not meaningful"
        } else {
            "release build"
        },
        ctx.runs,
        if ctx.quick {
            "; --quick: small images, not comparable with the paper"
        } else {
            ""
        },
        fmt_duration(ctx.started.elapsed().as_secs_f64())
    );
    let p = report.finish("sray benchmarks", &preamble)?;
    eprintln!("sray bench: report written to {}", p.display());
    Ok(())
}
