//! `sray coordinator` and `sray worker`: the two long-running services of
//! a cluster. Both log to stderr (`RUST_LOG` filters, default `info`) and
//! stop on Ctrl-C or SIGTERM.

use anyhow::Context;
use clap::Args;
use sray_coordinator::server::{Security, serve_with};
use sray_coordinator::state::{Config, Limits, MIN_WORKER_MEMORY, Shared};
use sray_proto::auth::Token;
use std::path::PathBuf;
use std::time::Duration;

#[derive(Args, Debug)]
pub struct CoordinatorArgs {
    /// Address to listen on
    #[arg(long, default_value = "127.0.0.1:7878")]
    pub listen: String,
    /// Also serve HTTP here for operators: /healthz, /metrics (Prometheus),
    /// /api/status and a dashboard at /. No authentication: bind it to
    /// loopback or a private network (off by default)
    #[arg(long, value_name = "ADDR")]
    pub http_listen: Option<String>,
    /// Where uploaded scenes and the jobs' journals are kept (one coordinator per directory)
    #[arg(long, default_value = "sray-data")]
    pub data_dir: PathBuf,
    /// Where rays and results in flight are kept (default: the data directory)
    #[arg(long)]
    pub tmp_dir: Option<PathBuf>,
    /// Require this token (a file holding it) of workers and clients alike; prefer the next two
    #[arg(long)]
    pub token_file: Option<PathBuf>,
    /// Require this token (a file holding it) of workers; it grants nothing a client may do
    #[arg(long)]
    pub worker_token_file: Option<PathBuf>,
    /// Require this token (a file holding it) of clients; it grants nothing a worker may do
    #[arg(long)]
    pub client_token_file: Option<PathBuf>,
    /// With TLS, require every caller to present a certificate signed by this CA (PEM)
    #[arg(long)]
    pub tls_client_ca: Option<PathBuf>,
    /// Serve TLS with this certificate chain (PEM); needs --tls-key
    #[arg(long, requires = "tls_key")]
    pub tls_cert: Option<PathBuf>,
    /// The certificate's private key (PEM)
    #[arg(long, requires = "tls_cert")]
    pub tls_key: Option<PathBuf>,
    /// Rays per shard for jobs that do not say (0: sized for the cluster,
    /// from the round's rays, the workers connected and the database's size)
    #[arg(long, default_value_t = 0)]
    pub shard_rays: u64,
    /// Heartbeat interval asked of workers, milliseconds
    #[arg(long, default_value_t = 1000)]
    pub heartbeat_ms: u64,
    /// A worker silent this long (seconds) is declared dead and its task requeued
    #[arg(long, default_value_t = 5.0)]
    pub worker_timeout: f64,
    /// A job with no worker that may do its work for this long (seconds) fails
    #[arg(long, default_value_t = 60.0)]
    pub worker_wait: f64,
    /// Share of every shard's rays re-traced on another worker to verify it (0 turns verification off)
    #[arg(long, default_value_t = 0.02)]
    pub verify_fraction: f64,
    /// A task running this many times longer than the median of its finished siblings gets a backup attempt
    #[arg(long, default_value_t = 4.0)]
    pub deadline_factor: f64,
    /// ... but not before this many seconds
    #[arg(long, default_value_t = 30.0)]
    pub deadline_min: f64,
    /// ... and after this many seconds while no sibling has finished
    #[arg(long, default_value_t = 900.0)]
    pub task_timeout: f64,
    /// Seconds a worker is quarantined (no tasks) after 3 failures, or a wrong output
    #[arg(long, default_value_t = 600.0)]
    pub quarantine: f64,
    /// Seconds a finished job's image stays fetchable (`sray fetch`)
    #[arg(long, default_value_t = 3600.0)]
    pub job_retention: f64,
    /// Bytes of uploaded scenes kept; least recently used are removed past it
    #[arg(long, default_value = "50GiB", value_parser = |s: &str| sray_engine::units::parse_bytes(s))]
    pub scene_store_max: u64,
    /// Memory for the records in flight (rounds' rays, tasks' outputs);
    /// beyond it they go to spill files under --tmp-dir
    #[arg(long, default_value = "256MiB", value_parser = |s: &str| sray_engine::units::parse_bytes(s))]
    pub records_memory: u64,
    /// Leave the tasks' results and spawned rays at the workers that made
    /// them: only counts, digests and colour come here, so the wire
    /// carries a few bytes per ray. Tasks then run only where their input
    /// is, there are no checkpoints, verification checks whole shards
    /// (--verify-fraction of them, and each worker's first) by running
    /// them and the rounds before them again on another worker, and a job
    /// that loses a worker recomputes the records it held (its shards'
    /// earlier rounds, on another worker); one that finds a liar starts
    /// again without it. For a cluster whose workers are rarely lost
    #[arg(long)]
    pub records_at_workers: bool,
    /// Workers with less --memory are refused at registration
    #[arg(long, default_value_t = MIN_WORKER_MEMORY, value_parser = |s: &str| sray_engine::units::parse_bytes(s))]
    pub min_worker_memory: u64,
    /// Largest image a job may ask for, width x height
    #[arg(long, default_value_t = Limits::default().max_pixels)]
    pub max_pixels: u64,
    /// Most eye rays per pixel a job may ask for
    #[arg(long, default_value_t = Limits::default().max_samples)]
    pub max_samples: u32,
    /// Deepest ray tree a job may ask for
    #[arg(long, default_value_t = Limits::default().max_depth)]
    pub max_depth: u32,
    /// Largest object database a client may upload
    #[arg(long, default_value = "64GiB", value_parser = |s: &str| sray_engine::units::parse_bytes(s))]
    pub max_scene_bytes: u64,
    /// Jobs running at once; more are refused until one ends
    #[arg(long, default_value_t = Limits::default().max_jobs)]
    pub max_jobs: usize,
}

#[derive(Args, Debug)]
pub struct WorkerArgs {
    /// The coordinator's URL (http://HOST:PORT, or https:// with --tls-ca)
    #[arg(long)]
    pub coordinator: String,
    /// Tracer threads (default: all cores)
    #[arg(long)]
    pub threads: Option<usize>,
    /// Memory budget of the worker: its tracers take three quarters, the
    /// records it keeps for later tasks at most a quarter (e.g. 2GiB;
    /// default: half of the available memory)
    #[arg(long, value_parser = |s: &str| sray_engine::units::parse_bytes(s))]
    pub memory: Option<u64>,
    /// Where scenes are cached, by content hash
    #[arg(long, default_value = "sray-cache")]
    pub cache_dir: PathBuf,
    /// Bytes of scenes kept in the cache; least recently used are removed past it
    #[arg(long, default_value = "20GiB", value_parser = |s: &str| sray_engine::units::parse_bytes(s))]
    pub cache_max: u64,
    /// A directory shared with the coordinator or other workers that holds
    /// databases as HASH.sdb (e.g. a read-only mount of the coordinator's
    /// --data-dir): each chunk is read from there and checked against the
    /// scene hash before the coordinator is asked for it (repeatable)
    #[arg(long)]
    pub scene_dir: Vec<PathBuf>,
    /// Where spilled rays go (default: the system's temp dir)
    #[arg(long)]
    pub tmp_dir: Option<PathBuf>,
    /// The workers' token (a file holding it)
    #[arg(long)]
    pub token_file: Option<PathBuf>,
    /// Certificate (PEM) to trust for an https coordinator
    #[arg(long)]
    pub tls_ca: Option<PathBuf>,
    /// This worker's client certificate (PEM), for a coordinator with --tls-client-ca; needs --tls-key
    #[arg(long, requires = "tls_key")]
    pub tls_cert: Option<PathBuf>,
    /// The client certificate's private key (PEM)
    #[arg(long, requires = "tls_cert")]
    pub tls_key: Option<PathBuf>,
    /// Name shown in the coordinator's log (default: host name and process id)
    #[arg(long)]
    pub name: Option<String>,
    /// Send records uncompressed: only for a coordinator on this machine
    /// (`sray render --local-workers` starts its workers so), where
    /// compressing costs more time than the bytes save; never across a
    /// network or a tunnel
    #[arg(long)]
    pub raw_records: bool,
    /// A fault to play (`lie`, `wrong-digest`, `stall-from-round=N`), for the tests of
    /// the coordinator's defences only
    #[arg(long, hide = true)]
    pub fault: Option<sray_worker::node::Fault>,
}

fn init_logs() {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    use std::io::IsTerminal;
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::stderr().is_terminal())
        .try_init();
}

fn token(path: &Option<PathBuf>) -> anyhow::Result<Option<Token>> {
    path.as_deref()
        .map(Token::from_file)
        .transpose()
        .map_err(anyhow::Error::msg)
}

fn seconds(s: f64, what: &str) -> anyhow::Result<Duration> {
    if !(s > 0.0 && s < 1e6) {
        anyhow::bail!("{what} must be a positive number of seconds");
    }
    Ok(Duration::from_secs_f64(s))
}

/// Ctrl-C or SIGTERM.
async fn stop_signal() {
    let term = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending().await,
        }
    };
    tokio::select! {
        _ = tokio::signal::ctrl_c() => {}
        _ = term => {}
    }
}

/// A file-size limit (`ulimit -f`) reached is an error to report (a full
/// disk's, naming the file), not a signal that kills the process without a
/// word: SIGXFSZ is ignored, so that the write fails with EFBIG instead.
fn file_size_limit_is_an_error() {
    // SAFETY: signal(2) with SIG_IGN installs no handler of ours (no code
    // runs on the signal), and SIGXFSZ is a valid signal number; it is
    // called before any thread of ours is started.
    unsafe {
        libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
    }
}

pub(crate) fn runtime() -> anyhow::Result<tokio::runtime::Runtime> {
    Ok(tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?)
}

pub fn coordinator(a: CoordinatorArgs) -> anyhow::Result<()> {
    init_logs();
    file_size_limit_is_an_error();
    if a.heartbeat_ms == 0 || a.heartbeat_ms > 60_000 {
        anyhow::bail!("--heartbeat-ms must be 1 to 60000");
    }
    if !(0.0..=1.0).contains(&a.verify_fraction) {
        anyhow::bail!("--verify-fraction must be 0 to 1");
    }
    if !(a.deadline_factor >= 1.0 && a.deadline_factor < 1e6) {
        anyhow::bail!("--deadline-factor must be at least 1");
    }
    let cfg = Config {
        heartbeat: Duration::from_millis(a.heartbeat_ms),
        worker_timeout: seconds(a.worker_timeout, "--worker-timeout")?,
        worker_wait: seconds(a.worker_wait, "--worker-wait")?,
        shard_rays: if a.shard_rays == 0 {
            0
        } else {
            a.shard_rays.clamp(256, 1 << 24)
        },
        data_dir: a.data_dir.clone(),
        tmp_dir: a.tmp_dir.clone(),
        verify_fraction: a.verify_fraction,
        checkpoints: !a.records_at_workers,
        records_at_workers: a.records_at_workers,
        deadline_factor: a.deadline_factor,
        deadline_min: seconds(a.deadline_min, "--deadline-min")?,
        task_timeout: seconds(a.task_timeout, "--task-timeout")?,
        quarantine: seconds(a.quarantine, "--quarantine")?,
        job_retention: seconds(a.job_retention, "--job-retention")?,
        scene_store_max: a.scene_store_max,
        min_worker_memory: a.min_worker_memory,
        records_memory: a.records_memory,
        limits: Limits {
            max_pixels: a.max_pixels,
            max_samples: a.max_samples,
            max_depth: a.max_depth,
            max_scene_bytes: a.max_scene_bytes,
            max_jobs: a.max_jobs.max(1),
            ..Limits::default()
        },
        ..Config::default()
    };
    let shared_token = token(&a.token_file)?;
    let sec = Security {
        worker_token: token(&a.worker_token_file)?.or(shared_token.clone()),
        client_token: token(&a.client_token_file)?.or(shared_token),
        tls: a.tls_cert.clone().zip(a.tls_key.clone()),
        client_ca: a.tls_client_ca.clone(),
    };
    if sec.worker_token.is_none() && sec.client_token.is_none() {
        tracing::warn!(
            "no token file: anyone who can reach this port can use the cluster, as a worker or a client"
        );
    } else if sec.worker_token.is_none() || sec.client_token.is_none() {
        anyhow::bail!(
            "only one role would have a token and the other could not call at all: give both \
             --worker-token-file and --client-token-file (or --token-file for the one missing)"
        );
    }
    let rt = runtime()?;
    let r = rt.block_on(async {
        let shared = Shared::new(cfg)?;
        let listener = tokio::net::TcpListener::bind(&a.listen)
            .await
            .with_context(|| format!("cannot listen on {}", a.listen))?;
        let addr = listener.local_addr()?;
        let http = match &a.http_listen {
            None => None,
            Some(h) => {
                let l = tokio::net::TcpListener::bind(h)
                    .await
                    .with_context(|| format!("cannot listen on {h} (--http-listen)"))?;
                let ha = l.local_addr()?;
                if !ha.ip().is_loopback() {
                    tracing::warn!(
                        address = %ha,
                        "the HTTP listener has no authentication and shows job ids, progress and previews: keep it on a private network"
                    );
                }
                tracing::info!(url = %format!("http://{ha}/"), "operators' HTTP listening");
                // A line for scripts that start one on port 0.
                eprintln!("sray coordinator http on http://{ha}/");
                Some(l)
            }
        };
        let scheme = if sec.tls.is_some() { "https" } else { "http" };
        tracing::info!(url = %format!("{scheme}://{addr}"), data = %a.data_dir.display(), "coordinator listening");
        // A line for scripts that start a coordinator on port 0.
        eprintln!("sray coordinator listening on {scheme}://{addr}");
        serve_with(shared, listener, http, sec, stop_signal()).await
    });
    // Work still on blocking threads (a checkpoint being written is
    // crash-safe) does not hold the exit up.
    rt.shutdown_timeout(Duration::from_millis(500));
    r
}

pub fn worker(a: WorkerArgs) -> anyhow::Result<()> {
    init_logs();
    file_size_limit_is_an_error();
    if a.threads == Some(0) {
        anyhow::bail!("--threads must be at least 1");
    }
    let cfg = sray_worker::WorkerConfig {
        target: sray_proto::net::Target {
            url: a.coordinator.clone(),
            token: token(&a.token_file)?,
            ca: a.tls_ca.clone(),
            identity: a.tls_cert.clone().zip(a.tls_key.clone()),
        },
        name: a.name.clone().unwrap_or_else(|| {
            let host = std::fs::read_to_string("/proc/sys/kernel/hostname").unwrap_or_default();
            format!("{}-{}", host.trim(), std::process::id())
        }),
        threads: a.threads.unwrap_or(0),
        memory: a
            .memory
            .unwrap_or_else(sray_engine::sys::default_memory_budget),
        cache_dir: a.cache_dir.clone(),
        cache_max: a.cache_max,
        scene_dirs: a.scene_dir.clone(),
        tmp_dir: a.tmp_dir.clone(),
        raw_records: a.raw_records,
        fault: a.fault,
    };
    runtime()?.block_on(sray_worker::run(cfg, stop_signal()))
}
