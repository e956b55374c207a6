//! `sray coordinator` and `sray worker`: the two long-running services of
//! a cluster. Both log to stderr (`RUST_LOG` filters, default `info`) and
//! stop on Ctrl-C or SIGTERM.

use anyhow::Context;
use clap::Args;
use sray_coordinator::server::{Security, serve};
use sray_coordinator::state::{Config, Shared};
use sray_proto::auth::Token;
use std::path::PathBuf;
use std::time::Duration;

#[derive(Args, Debug)]
pub struct CoordinatorArgs {
    /// Address to listen on
    #[arg(long, default_value = "127.0.0.1:7878")]
    pub listen: String,
    /// Where uploaded scenes are kept
    #[arg(long, default_value = "sray-data")]
    pub data_dir: PathBuf,
    /// Where rays and results in flight are kept (default: the system's temp dir)
    #[arg(long)]
    pub tmp_dir: Option<PathBuf>,
    /// Require this shared token (a file holding it) of workers and clients
    #[arg(long)]
    pub token_file: Option<PathBuf>,
    /// Serve TLS with this certificate chain (PEM); needs --tls-key
    #[arg(long, requires = "tls_key")]
    pub tls_cert: Option<PathBuf>,
    /// The certificate's private key (PEM)
    #[arg(long, requires = "tls_cert")]
    pub tls_key: Option<PathBuf>,
    /// Default rays per shard
    #[arg(long, default_value_t = 1 << 16)]
    pub shard_rays: u64,
    /// Heartbeat interval asked of workers, milliseconds
    #[arg(long, default_value_t = 1000)]
    pub heartbeat_ms: u64,
    /// A worker silent this long (seconds) is declared dead and its task requeued
    #[arg(long, default_value_t = 5.0)]
    pub worker_timeout: f64,
    /// A job with no worker for this long (seconds) fails
    #[arg(long, default_value_t = 60.0)]
    pub worker_wait: f64,
}

#[derive(Args, Debug)]
pub struct WorkerArgs {
    /// The coordinator's URL (http://HOST:PORT, or https:// with --tls-ca)
    #[arg(long)]
    pub coordinator: String,
    /// Tracer threads (default: all cores)
    #[arg(long)]
    pub threads: Option<usize>,
    /// Memory budget of the tracer (e.g. 2GiB; default: half of the available memory)
    #[arg(long, value_parser = |s: &str| sray_engine::units::parse_bytes(s))]
    pub memory: Option<u64>,
    /// Where scenes are cached, by content hash
    #[arg(long, default_value = "sray-cache")]
    pub cache_dir: PathBuf,
    /// Where spilled rays go (default: the system's temp dir)
    #[arg(long)]
    pub tmp_dir: Option<PathBuf>,
    /// The cluster's shared token (a file holding it)
    #[arg(long)]
    pub token_file: Option<PathBuf>,
    /// Certificate (PEM) to trust for an https coordinator
    #[arg(long)]
    pub tls_ca: Option<PathBuf>,
    /// Name shown in the coordinator's log (default: host name and process id)
    #[arg(long)]
    pub name: Option<String>,
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

fn runtime() -> anyhow::Result<tokio::runtime::Runtime> {
    Ok(tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?)
}

pub fn coordinator(a: CoordinatorArgs) -> anyhow::Result<()> {
    init_logs();
    if a.heartbeat_ms == 0 || a.heartbeat_ms > 60_000 {
        anyhow::bail!("--heartbeat-ms must be 1 to 60000");
    }
    let cfg = Config {
        heartbeat: Duration::from_millis(a.heartbeat_ms),
        worker_timeout: seconds(a.worker_timeout, "--worker-timeout")?,
        worker_wait: seconds(a.worker_wait, "--worker-wait")?,
        shard_rays: a.shard_rays.clamp(256, 1 << 24),
        data_dir: a.data_dir.clone(),
        tmp_dir: a.tmp_dir.clone(),
        ..Config::default()
    };
    let sec = Security {
        token: token(&a.token_file)?,
        tls: a.tls_cert.clone().zip(a.tls_key.clone()),
    };
    if sec.token.is_none() {
        tracing::warn!("no --token-file: anyone who can reach this port can use the cluster");
    }
    runtime()?.block_on(async {
        let shared = Shared::new(cfg)?;
        let listener = tokio::net::TcpListener::bind(&a.listen)
            .await
            .with_context(|| format!("cannot listen on {}", a.listen))?;
        let addr = listener.local_addr()?;
        let scheme = if sec.tls.is_some() { "https" } else { "http" };
        tracing::info!(url = %format!("{scheme}://{addr}"), data = %a.data_dir.display(), "coordinator listening");
        // A line for scripts that start a coordinator on port 0.
        eprintln!("sray coordinator listening on {scheme}://{addr}");
        serve(shared, listener, sec, stop_signal()).await
    })
}

pub fn worker(a: WorkerArgs) -> anyhow::Result<()> {
    init_logs();
    if a.threads == Some(0) {
        anyhow::bail!("--threads must be at least 1");
    }
    let cfg = sray_worker::WorkerConfig {
        target: sray_proto::net::Target {
            url: a.coordinator.clone(),
            token: token(&a.token_file)?,
            ca: a.tls_ca.clone(),
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
        tmp_dir: a.tmp_dir.clone(),
    };
    runtime()?.block_on(sray_worker::run(cfg, stop_signal()))
}
