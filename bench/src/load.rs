//! The coordinator under load (`sray bench load`): a real `sray
//! coordinator` process, and up to a thousand simulated workers in this
//! process ([`super::sim`]) speaking the real protocol, each on a
//! connection of its own, answering tasks with outputs of the right shape
//! and size (at once, or at a tracer's pace). Clients are real `sray
//! render` processes.
//!
//! Measured on the coordinator's process (`/proc`): its CPU time and
//! resident memory, idle with N workers (memory and CPU per worker) and
//! over jobs (CPU per ray and per task, memory per job); and at the
//! simulated workers: heartbeat and task-request round trips. The CPU per
//! ray and per task come from two runs of the same job in large and small
//! shards (CPU = a·rays + b·tasks); the ceiling is one core over a. The
//! per-worker rate of the breadth-first tracer is measured on a real
//! worker (`--local-workers 1 --threads 2`), and the load of 100 such
//! workers follows from a and b; a run of 100 simulated workers at a
//! pace this machine can feed checks the model against the coordinator's
//! measured CPU.

use super::report::{Report, num};
use super::sim::{self, SimConfig, SimStats};
use super::{Ctx, Plan, exec};
use anyhow::{Context, bail};
use sray_engine::spd::SpdScene;
use std::io::BufRead;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

/// One configuration measured.
#[derive(Clone, Debug)]
struct Scenario {
    label: &'static str,
    workers: usize,
    /// Records stay at the workers (`--records-at-workers`).
    keep: bool,
    /// With `keep`: the colour stays there too (the simulated workers
    /// send none; a bound, see `SimConfig::send_colour`).
    colour_kept: bool,
    /// Rays per shard (0: the coordinator's choice).
    shard_rays: u64,
    side: u32,
    /// Rays per second per simulated worker (0: at once).
    rate: f64,
}

/// What a scenario measured.
#[derive(Clone, Debug, Default)]
struct Outcome {
    rays: f64,
    tasks: f64,
    /// Shards of each round (the job's statistics).
    shards_per_round: serde_json::Value,
    wall: f64,
    cpu: f64,
    /// CPU seconds per worker-second, idle (heartbeats, waiting polls).
    idle_cpu_per_worker: f64,
    rss_empty: f64,
    rss_idle: f64,
    hwm: f64,
    hb_p50: f64,
    hb_p99: f64,
    next_p50: f64,
    next_p99: f64,
    bytes_per_ray: f64,
    errors: u64,
}

/// Seconds the coordinator is watched idle with its workers.
const IDLE_SECONDS: f64 = 5.0;

/// `SRAY_BENCH_LOAD_ONLY=TEXT[|TEXT...]`: whether a setup's label has one
/// of the texts (every setup without the variable).
fn only() -> impl Fn(&str) -> bool {
    let only = std::env::var("SRAY_BENCH_LOAD_ONLY").unwrap_or_default();
    move |label| only.split('|').any(|o| label.contains(o))
}

/// The setups; `real_rate`: a real worker's rays a second, the pace of
/// the simulated workers where the coordinator sizes the shards (which
/// it does from the workers' measured rate: workers that answer at once
/// would make it cut every round into a few large shards).
fn scenarios(ctx: &Ctx, real_rate: f64) -> Vec<Scenario> {
    let (few, many, side) = if ctx.quick {
        (20, 200, 256)
    } else {
        (100, 1000, 1024)
    };
    let sc = |label, workers, keep, shard_rays, rate| Scenario {
        label,
        workers,
        keep,
        colour_kept: false,
        shard_rays,
        side,
        rate,
    };
    let only = only();
    let half = |mut s: Scenario| {
        s.side /= 2;
        s
    };
    let colour_kept = |mut s: Scenario| {
        s.colour_kept = true;
        s
    };
    let all = vec![
        sc("records travel, large shards", few, false, 65_536, 0.0),
        sc("records travel, small shards", few, false, 8_192, 0.0),
        half(sc(
            "records travel, large shards, half side",
            few,
            false,
            65_536,
            0.0,
        )),
        sc("records at workers, large shards", few, true, 65_536, 0.0),
        sc("records at workers, small shards", few, true, 8_192, 0.0),
        half(sc(
            "records at workers, large shards, half side",
            few,
            true,
            65_536,
            0.0,
        )),
        colour_kept(sc(
            "records at workers, colour kept there (a bound), large shards",
            few,
            true,
            65_536,
            0.0,
        )),
        colour_kept(sc(
            "records at workers, colour kept there (a bound), small shards",
            few,
            true,
            8_192,
            0.0,
        )),
        colour_kept(half(sc(
            "records at workers, colour kept there (a bound), large shards, half side",
            few,
            true,
            65_536,
            0.0,
        ))),
        sc("records travel, sized shards", many, false, 0, real_rate),
        sc("records at workers, sized shards", many, true, 0, real_rate),
    ];
    all.into_iter().filter(|s| only(s.label)).collect()
}

pub(super) fn plan(ctx: &Ctx) -> Plan {
    let n = scenarios(ctx, 0.0).len() + 2;
    Plan {
        steps: n,
        seconds: n as f64 * if ctx.quick { 15.0 } else { 60.0 },
    }
}

pub(super) fn run(ctx: &Ctx, r: &mut Report) -> anyhow::Result<()> {
    let scene = ctx.scene_file(SpdScene::Balls, 1, "sdb")?;
    let objects = objects(&scene)?;
    // The per-worker rate of the breadth-first tracer, measured.
    ctx.step("a real worker's rate (balls 4, --local-workers 1, 2 threads)");
    let real = exec::sray_render(
        &[
            "spd:balls:4".into(),
            "-o".into(),
            "rate.png".into(),
            "--local-workers".into(),
            "1".into(),
            "--threads".into(),
            "2".into(),
            "--quiet".into(),
        ],
        ctx.work(),
    )?;
    let real_rays: f64 = rays_of(real.stats.as_ref().unwrap_or(&serde_json::Value::Null));
    let real_busy = real
        .stats
        .as_ref()
        .and_then(|s| s["worker_seconds"].as_f64())
        .unwrap_or(f64::NAN);
    let worker_rate = real_rays / real_busy;

    let mut rows = Vec::new();
    let mut out = Vec::new();
    for sc in scenarios(ctx, worker_rate) {
        ctx.step(&format!("{} simulated workers, {}", sc.workers, sc.label));
        let o = scenario(ctx, &sc, &scene, objects)
            .with_context(|| format!("{} workers, {}", sc.workers, sc.label))?;
        rows.push(row(&sc, &o));
        out.push((sc, o));
    }
    // CPU per ray, per task and per job, by mode: three runs (large and
    // small shards, and large shards on a frame of a quarter the rays),
    // CPU = a·rays + b·tasks + c.
    // Also the first run's (65,536-ray shards, the whole frame) CPU per
    // ray, all of the job's: tasks, pixels and the job itself included.
    let fit = |keep: bool, colour_kept: bool| -> Option<((f64, f64, f64), f64)> {
        let runs: Vec<&Outcome> = out
            .iter()
            .filter(|(s, _)| s.keep == keep && s.colour_kept == colour_kept && s.shard_rays > 0)
            .map(|(_, o)| o)
            .collect();
        let [x, y, z] = runs.as_slice() else {
            return None;
        };
        let f = solve3([
            [x.rays, x.tasks, 1.0, x.cpu],
            [y.rays, y.tasks, 1.0, y.cpu],
            [z.rays, z.tasks, 1.0, z.cpu],
        ])?;
        Some((f, x.cpu / x.rays))
    };
    let (travel, keep, colour_kept) = (fit(false, false), fit(true, false), fit(true, true));
    // A paced run: 100 (20) workers at a rate this machine can feed,
    // records at the workers.
    let (few, paced_rate) = if ctx.quick {
        (20, 5_000.0)
    } else {
        (100, 20_000.0)
    };
    let paced = Scenario {
        label: "records at workers, paced",
        workers: few,
        keep: true,
        colour_kept: false,
        shard_rays: 0,
        side: if ctx.quick { 256 } else { 1024 },
        rate: paced_rate,
    };
    ctx.step(&format!(
        "{few} simulated workers at {paced_rate} rays/s each, records at the workers"
    ));
    let po = if only()(paced.label) {
        let po = scenario(ctx, &paced, &scene, objects)?;
        rows.push(row(&paced, &po));
        out.push((paced.clone(), po.clone()));
        Some(po)
    } else {
        None
    };
    if out.is_empty() {
        return Ok(());
    }

    r.section("The coordinator under load: simulated workers");
    r.para(&format!(
        "A real coordinator process and simulated workers (`bench/src/sim.rs`) in the bench process, \
         each on a connection of its own, speaking the real protocol and answering every task with \
         records of the right kinds, counts and sizes after `rays / rate` seconds (at once with rate \
         0): a ray tree measured on balls 4 (each round's rays spawn 3.03, 0.20, 0.55, 0.62, 0.44 \
         rays), three in five rays adding colour. Clients are real `sray render` processes ({side}x{side}, \
         one job at a time, verification at its default 2 % where records travel; where the coordinator sizes \
         the shards, one unmeasured job first). CPU and memory are the \
         coordinator process's (each thread's `/proc/PID/task/TID/schedstat`, in nanoseconds; `/proc/PID/status`); latencies are round trips seen by \
         the simulated workers. The machine's two cores are shared by the coordinator, the simulated \
         workers and the client, so throughput here is what this machine reaches, not the coordinator's \
         ceiling; the ceiling follows from its CPU per ray.",
        side = out[0].0.side
    ));
    r.table(
        "load",
        &[
            "setup",
            "workers",
            "shard rays",
            "rays",
            "tasks",
            "wall s",
            "Mrays/s",
            "coordinator CPU s",
            "CPU µs/ray",
            "bytes/ray",
            "heartbeat p50/p99 ms",
            "task request p50/p90 ms",
            "RSS idle MiB (empty)",
            "KiB/worker",
            "idle CPU ms per worker-s",
            "peak MiB",
        ],
        &rows,
    )?;
    let mut notes = Vec::new();
    // Tasks per ray when the coordinator sizes the shards for the most
    // workers measured (both stages and verification samples).
    let sized = |keep: bool| {
        out.iter()
            .filter(|(s, _)| s.keep == keep && !s.colour_kept && s.label.contains("sized"))
            .map(|(_, o)| o.tasks / o.rays)
            .next_back()
    };
    notes.push(format!(
        "A real worker (balls 4, 512x512, 2 threads, `--local-workers 1`) traced {} M rays/s of its \
         busy time: 100 such workers make {} M rays/s",
        num(worker_rate / 1e6, 2),
        num(worker_rate * 100.0 / 1e6, 0)
    ));
    let load = 100.0 * worker_rate;
    let mut model = serde_json::Map::new();
    for (name, key, fitted, tpr) in [
        (
            "records travel (the default)",
            "travel",
            travel,
            sized(false),
        ),
        ("records at the workers", "keep", keep, sized(true)),
        (
            "records and colour at the workers (a bound: no colour sent)",
            "keep_colour",
            colour_kept,
            None,
        ),
    ] {
        let Some(((a, b, c), per_ray)) = fitted else {
            continue;
        };
        // Whole jobs in 65,536-ray shards: every task (later rounds cut
        // smaller shards, and each shard is two tasks), pixel and job.
        let ceiling = 1.0 / per_ray;
        let mut n = format!(
            "{name}: {} µs of coordinator CPU per ray, {} µs per task and {} ms per job (fitted to the \
             three runs of fixed shards); one core carries {} M rays/s of such jobs in shards of 65,536 \
             rays (the whole job's CPU per ray)",
            num(a * 1e6, 4),
            num(b * 1e6, 0),
            num(c * 1e3, 0),
            num(ceiling / 1e6, 1)
        );
        let cores = load * per_ray;
        n.push_str(&format!(
            "; 100 such workers cost it {} cores in shards of 65,536 rays",
            num(cores, 2)
        ));
        let mut m = serde_json::json!({
            "cpu_per_ray_s": a, "cpu_per_task_s": b, "cpu_per_job_s": c,
            "ceiling_rays_per_s_65536": ceiling, "cores_for_100_workers_65536": cores,
        });
        if let Some(tpr) = tpr {
            let cores = load * (a + b * tpr);
            n.push_str(&format!(
                ", {} in the shards it sized for the most workers measured ({} rays a task)",
                num(cores, 2),
                num(1.0 / tpr, 0)
            ));
            m["cores_for_100_workers_sized"] = cores.into();
        }
        notes.push(n);
        model.insert(key.into(), m);
    }
    if let (Some(((a, b, _), _)), Some(po)) = (keep, &po) {
        let tpr = po.tasks / po.rays;
        let predicted = paced.workers as f64 * paced.rate * (a + b * tpr);
        notes.push(format!(
            "{} workers paced at {} rays/s each, records at the workers: the model says {} of a core \
             while they trace, measured {} over the whole job ({} s of the coordinator's CPU in {} s)",
            paced.workers,
            paced.rate,
            num(predicted, 3),
            num(po.cpu / po.wall, 3),
            num(po.cpu, 2),
            num(po.wall, 1)
        ));
    }
    for n in &notes {
        r.para(&format!("- {n}"));
    }
    r.json(
        "load",
        &serde_json::json!({
            "worker_rate_rays_per_s": worker_rate,
            "model": model,
            "runs": out.iter().map(|(s, o)| serde_json::json!({
                "setup": s.label,
                "workers": s.workers,
                "records_at_workers": s.keep,
                "colour_kept_at_workers": s.colour_kept,
                "shard_rays": s.shard_rays,
                "side": s.side,
                "rate": s.rate,
                "rays": o.rays,
                "tasks": o.tasks,
                "shards_per_round": o.shards_per_round,
                "wall_s": o.wall,
                "cpu_s": o.cpu,
                "idle_cpu_per_worker": o.idle_cpu_per_worker,
                "rss_empty_bytes": o.rss_empty,
                "rss_idle_bytes": o.rss_idle,
                "peak_bytes": o.hwm,
                "heartbeat_ms": [o.hb_p50, o.hb_p99],
                "next_task_ms": [o.next_p50, o.next_p99],
                "bytes_per_ray": o.bytes_per_ray,
                "errors": o.errors,
            })).collect::<Vec<_>>(),
            "notes": notes,
        }),
    )?;
    Ok(())
}

fn row(sc: &Scenario, o: &Outcome) -> Vec<String> {
    let mib = |b: f64| num(b / (1 << 20) as f64, 1);
    vec![
        format!(
            "{}{}",
            sc.label,
            if sc.rate > 0.0 {
                format!(" ({} rays/s each)", num(sc.rate, 0))
            } else {
                String::new()
            }
        ),
        sc.workers.to_string(),
        if sc.shard_rays == 0 {
            "sized".into()
        } else {
            sc.shard_rays.to_string()
        },
        num(o.rays, 0),
        num(o.tasks, 0),
        num(o.wall, 2),
        num(o.rays / o.wall / 1e6, 2),
        num(o.cpu, 3),
        num(o.cpu / o.rays * 1e6, 3),
        num(o.bytes_per_ray, 1),
        format!("{}/{}", num(o.hb_p50, 1), num(o.hb_p99, 1)),
        format!("{}/{}", num(o.next_p50, 1), num(o.next_p99, 1)),
        format!("{} ({})", mib(o.rss_idle), mib(o.rss_empty)),
        num((o.rss_idle - o.rss_empty) / sc.workers as f64 / 1024.0, 1),
        num(o.idle_cpu_per_worker * 1e3, 3),
        mib(o.hwm),
    ]
}

fn rays_of(stats: &serde_json::Value) -> f64 {
    stats["rays_per_round"]
        .as_array()
        .map_or(f64::NAN, |v| v.iter().filter_map(|x| x.as_f64()).sum())
}

/// The scene's object count (results must name objects below it).
fn objects(scene: &Path) -> anyhow::Result<u64> {
    let out = Command::new(exec::sray_exe()?)
        .args(["info", &scene.display().to_string(), "--json"])
        .output()?;
    let v: serde_json::Value = serde_json::from_slice(&out.stdout)?;
    v["objects"]
        .as_u64()
        .context("sray info gave no object count")
}

/// A process's CPU time so far, by thread: nanoseconds on a CPU from
/// `/proc/PID/task/TID/schedstat`, exact where `/proc/PID/stat` counts
/// 10 ms ticks (a job whose coordinator runs 40 ms would read 0.03 to
/// 0.05 s). Empty where the kernel keeps no such counts.
#[derive(Default)]
struct CpuClock {
    by_thread: std::collections::HashMap<u64, u64>,
    /// `/proc/PID/stat`'s user and system seconds (whole ticks).
    ticks: f64,
}

impl CpuClock {
    fn read(pid: u32) -> CpuClock {
        let mut by_thread = std::collections::HashMap::new();
        if let Ok(dir) = std::fs::read_dir(format!("/proc/{pid}/task")) {
            for e in dir.flatten() {
                let Some(tid) = e.file_name().to_str().and_then(|t| t.parse().ok()) else {
                    continue;
                };
                let ns = std::fs::read_to_string(e.path().join("schedstat"))
                    .ok()
                    .and_then(|s| s.split_whitespace().next()?.parse().ok());
                if let Some(ns) = ns {
                    by_thread.insert(tid, ns);
                }
            }
        }
        CpuClock {
            by_thread,
            ticks: cpu_seconds(pid),
        }
    }

    /// CPU seconds from `self` to `later`: each thread's time since
    /// `self` (all of it for threads started since). A thread that ended
    /// in between loses what it ran after `self`: the coordinator's
    /// threads that end are the blocking pool's idle ones.
    fn seconds_to(&self, later: &CpuClock) -> f64 {
        if later.by_thread.is_empty() {
            return later.ticks - self.ticks;
        }
        later
            .by_thread
            .iter()
            .map(|(t, ns)| ns.saturating_sub(self.by_thread.get(t).copied().unwrap_or(0)))
            .sum::<u64>() as f64
            / 1e9
    }
}

/// A process's CPU seconds (user and system), in whole 10 ms ticks.
fn cpu_seconds(pid: u32) -> f64 {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default();
    // Fields after the command's closing parenthesis; utime and stime are
    // the 14th and 15th of the line, in USER_HZ (100 a second on Linux).
    let rest = stat.rsplit_once(')').map_or("", |r| r.1);
    let f: Vec<f64> = rest
        .split_whitespace()
        .map(|x| x.parse().unwrap_or(0.0))
        .collect();
    (f.get(11).unwrap_or(&0.0) + f.get(12).unwrap_or(&0.0)) / 100.0
}

fn memory(pid: u32, key: &str) -> f64 {
    std::fs::read_to_string(format!("/proc/{pid}/status"))
        .unwrap_or_default()
        .lines()
        .find_map(|l| {
            l.strip_prefix(key)?
                .trim()
                .strip_suffix(" kB")?
                .parse::<f64>()
                .ok()
        })
        .unwrap_or(f64::NAN)
        * 1024.0
}

/// A coordinator process, killed when dropped.
struct Coordinator {
    child: Child,
    url: String,
}

impl Drop for Coordinator {
    fn drop(&mut self) {
        // SIGTERM first (a profiler wrapping it writes its file), then
        // SIGKILL.
        let _ = Command::new("kill")
            .arg(self.child.id().to_string())
            .status();
        for _ in 0..100 {
            if self.child.try_wait().ok().flatten().is_some() {
                return;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn start_coordinator(dir: &Path, token: &Path, keep: bool) -> anyhow::Result<Coordinator> {
    let data = dir.join("data");
    // SRAY_BENCH_COORDINATOR_PREFIX (e.g. "perf record -g -o FILE --")
    // runs the coordinator under a profiler (its CPU figures are then
    // the profiler's).
    let prefix: Vec<String> = std::env::var("SRAY_BENCH_COORDINATOR_PREFIX")
        .map(|p| p.split_whitespace().map(String::from).collect())
        .unwrap_or_default();
    let mut cmd = match prefix.split_first() {
        Some((p, rest)) => {
            let mut c = Command::new(p);
            c.args(rest).arg(exec::sray_exe()?);
            c
        }
        None => Command::new(exec::sray_exe()?),
    };
    cmd.args(["coordinator", "--listen", "127.0.0.1:0", "--data-dir"])
        .arg(&data)
        .arg("--token-file")
        .arg(token)
        .args([
            "--heartbeat-ms",
            "1000",
            "--worker-timeout",
            "60",
            "--worker-wait",
            "600",
        ])
        .env("RUST_LOG", "warn")
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped());
    if keep {
        cmd.arg("--records-at-workers");
    }
    let mut child = cmd.spawn().context("cannot start a coordinator")?;
    let err = child.stderr.take().context("no stderr")?;
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in std::io::BufReader::new(err).lines() {
            let Ok(line) = line else { break };
            if let Some(u) = line.strip_prefix("sray coordinator listening on ") {
                let _ = tx.send(u.to_string());
            }
        }
    });
    let url = rx
        .recv_timeout(Duration::from_secs(30))
        .context("the coordinator did not start")?;
    Ok(Coordinator { child, url })
}

fn scenario(ctx: &Ctx, sc: &Scenario, scene: &Path, objects: u64) -> anyhow::Result<Outcome> {
    let dir = tempfile::tempdir_in(ctx.work())?;
    let token = dir.path().join("token");
    std::fs::write(&token, "load-harness-token-0123456789")?;
    let coord = start_coordinator(dir.path(), &token, sc.keep)?;
    let pid = coord.child.id();
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?;
    let mut o = Outcome {
        rss_empty: memory(pid, "VmRSS:"),
        ..Default::default()
    };
    let cfg = Arc::new(SimConfig {
        url: coord.url.clone(),
        token: Some(sray_proto::auth::Token::from_file(&token).map_err(anyhow::Error::msg)?),
        rate: sc.rate,
        objects,
        send_colour: !sc.colour_kept,
    });
    let stats = Arc::new(SimStats::default());
    for i in 0..sc.workers {
        rt.spawn(sim::run(i, cfg.clone(), stats.clone()));
    }
    let t = Instant::now();
    while (stats.registered.load(Ordering::Relaxed) as usize) < sc.workers {
        if t.elapsed() > Duration::from_secs(120) || stats.errors.load(Ordering::Relaxed) > 0 {
            bail!(
                "{} of {} simulated workers registered ({} registrations tried again)",
                stats.registered.load(Ordering::Relaxed),
                sc.workers,
                stats.register_retries.load(Ordering::Relaxed)
            );
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    std::thread::sleep(Duration::from_secs(2));
    stats.reset_latencies();
    let c0 = CpuClock::read(pid);
    std::thread::sleep(Duration::from_secs_f64(IDLE_SECONDS));
    o.idle_cpu_per_worker = c0.seconds_to(&CpuClock::read(pid)) / IDLE_SECONDS / sc.workers as f64;
    o.rss_idle = memory(pid, "VmRSS:");

    let stats_file = dir.path().join("job.json");
    let side = sc.side.to_string();
    let shard = sc.shard_rays.to_string();
    let mut args: Vec<String> = vec![
        "render".into(),
        scene.display().to_string(),
        "-o".into(),
        dir.path().join("out.png").display().to_string(),
        "--coordinator".into(),
        coord.url.clone(),
        "--token-file".into(),
        token.display().to_string(),
        "--width".into(),
        side.clone(),
        "--height".into(),
        side,
        "--stats".into(),
        stats_file.display().to_string(),
        "--quiet".into(),
    ];
    if sc.shard_rays > 0 {
        args.extend(["--shard-rays".into(), shard]);
    }
    let job = || {
        Command::new(exec::sray_exe()?)
            .args(&args)
            .env("SRAY_JOBS_DIR", dir.path().join("tickets"))
            .output()
            .context("cannot run the client")
    };
    if sc.shard_rays == 0 {
        // Shards sized by the coordinator: a job first, unmeasured, as a
        // coordinator in service has run one (it sizes shards from the
        // workers' rate, measured from the tasks they complete).
        let warm = job()?;
        if !warm.status.success() {
            bail!(
                "the first job failed: {}",
                String::from_utf8_lossy(&warm.stderr)
            );
        }
        stats.reset_latencies();
    }
    let c0 = CpuClock::read(pid);
    let t0 = Instant::now();
    let client = job()?;
    o.wall = t0.elapsed().as_secs_f64();
    o.cpu = c0.seconds_to(&CpuClock::read(pid));
    o.hwm = memory(pid, "VmHWM:");
    stats.stop.store(true, Ordering::Relaxed);
    if !client.status.success() {
        bail!(
            "the job failed: {}",
            String::from_utf8_lossy(&client.stderr)
        );
    }
    let js: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&stats_file)?)?;
    o.rays = rays_of(&js);
    o.tasks =
        js["tasks"].as_f64().unwrap_or(0.0) + js["verification"]["samples"].as_f64().unwrap_or(0.0);
    o.bytes_per_ray = js["bytes_per_ray"].as_f64().unwrap_or(f64::NAN);
    o.shards_per_round = js["shards_per_round"].clone();
    {
        let hb = stats.heartbeat_ms.lock().unwrap();
        o.hb_p50 = sim::quantile(&hb, 0.5);
        o.hb_p99 = sim::quantile(&hb, 0.99);
        let nt = stats.next_task_ms.lock().unwrap();
        o.next_p50 = sim::quantile(&nt, 0.5);
        o.next_p99 = sim::quantile(&nt, 0.9);
    }
    o.errors = stats.errors.load(Ordering::Relaxed);
    drop(coord);
    rt.shutdown_timeout(Duration::from_secs(1));
    Ok(o)
}

/// Solves three linear equations (rows `[x, y, z, rhs]`) by Cramer's
/// rule; `None` when they do not determine the unknowns.
fn solve3(m: [[f64; 4]; 3]) -> Option<(f64, f64, f64)> {
    let det = |c: [usize; 3]| {
        let e = |r: usize, k: usize| m[r][c[k]];
        e(0, 0) * (e(1, 1) * e(2, 2) - e(1, 2) * e(2, 1))
            - e(0, 1) * (e(1, 0) * e(2, 2) - e(1, 2) * e(2, 0))
            + e(0, 2) * (e(1, 0) * e(2, 1) - e(1, 1) * e(2, 0))
    };
    let d = det([0, 1, 2]);
    if d.abs() < 1e-12 {
        return None;
    }
    Some((det([3, 1, 2]) / d, det([0, 3, 2]) / d, det([0, 1, 3]) / d))
}

#[cfg(test)]
mod tests {
    #[test]
    fn three_equations_solved() {
        // 2x + y + z = 8, x + 3y + 2z = 11, x + y + 4z = 15: x = 2, y = 1, z = 3.
        let (x, y, z) = super::solve3([
            [2.0, 1.0, 1.0, 8.0],
            [1.0, 3.0, 2.0, 11.0],
            [1.0, 1.0, 4.0, 15.0],
        ])
        .unwrap();
        assert!((x - 2.0).abs() < 1e-9 && (y - 1.0).abs() < 1e-9 && (z - 3.0).abs() < 1e-9);
        // Equal rows determine nothing.
        assert!(super::solve3([[1.0, 1.0, 1.0, 1.0]; 3]).is_none());
    }
}
