//! `sray render --local-workers N`: a coordinator in this process and N
//! worker processes on loopback, started for one render and stopped after
//! it, on error and on Ctrl-C alike (the children are killed when their
//! handles drop). A random token keeps other local users out.

use super::client::{self, JobResult};
use anyhow::{Context, bail};
use sray_coordinator::server::{Security, serve};
use sray_coordinator::state::{Config, Shared};
use sray_engine::progress::Progress;
use sray_engine::render::ImageFormat;
use sray_proto::auth::Token;
use sray_proto::net::Target;
use sray_proto::v1;
use std::path::Path;
use std::process::Stdio;
use std::time::Duration;
use tokio::net::TcpListener;
use tokio::process::{Child, Command};

/// How to split this machine among the local workers.
pub struct LocalPlan {
    pub workers: usize,
    /// Memory budget of the whole render, split evenly.
    pub memory: u64,
    /// Threads of the whole render (0: all cores), split evenly.
    pub threads: usize,
    pub tmp_dir: Option<std::path::PathBuf>,
}

pub async fn render(
    plan: &LocalPlan,
    db: &Path,
    params: v1::RenderParams,
    shard_rays: u64,
    format: ImageFormat,
    progress: &dyn Progress,
) -> anyhow::Result<JobResult> {
    if plan.workers == 0 || plan.workers > 256 {
        bail!("--local-workers takes 1 to 256, not {}", plan.workers);
    }
    let dir = match &plan.tmp_dir {
        Some(d) => tempfile::Builder::new().prefix("sray-local-").tempdir_in(d),
        None => tempfile::Builder::new().prefix("sray-local-").tempdir(),
    }
    .context("cannot create a temporary directory")?;
    // The records in flight take an eighth of the render's memory in the
    // coordinator (beyond it they spill); the workers share the rest.
    let records_memory = plan.memory / 8;
    let token = sray_proto::ids::random_hex(32);
    let token_file = dir.path().join("token");
    std::fs::write(&token_file, &token).context("cannot write the token file")?;
    let shared = Shared::new(Config {
        data_dir: dir.path().join("data"),
        tmp_dir: plan.tmp_dir.clone(),
        worker_wait: Duration::from_secs(30),
        // The user split their own --memory among the workers.
        min_worker_memory: 0,
        records_memory,
        // The data directory goes with this process: no restart could
        // resume from a checkpoint.
        checkpoints: false,
        // The workers keep their results and spawned rays: sending them
        // here and back cost more than the tracing. Should one die, the
        // job starts again on those left.
        records_at_workers: true,
        // The workers are this process's children, running its executable
        // on this machine: a wrong answer of theirs would be a fault the
        // embedded render shares, which re-tracing samples here cannot
        // tell apart. Verification is for workers elsewhere.
        verify_fraction: 0.0,
        ..Config::default()
    })?;
    // The workers share one cache, where the scene is put (a link to the
    // database) once hashed, so that they verify it instead of fetching it.
    let cache = dir.path().join("cache");
    std::fs::create_dir_all(&cache)?;
    let abs = std::fs::canonicalize(db)?;
    // A database that cannot be opened fails here, before any worker
    // starts (it is hashed while they do).
    sray_engine::sdb::Database::open(&abs)?;

    let listener = TcpListener::bind("127.0.0.1:0")
        .await
        .context("cannot listen on loopback")?;
    let url = format!("http://{}", listener.local_addr()?);
    let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
    // One random token for the workers, another for this client.
    let client_token = Token::new(&sray_proto::ids::random_hex(32)).map_err(anyhow::Error::msg)?;
    let sec = Security {
        worker_token: Some(Token::new(&token).map_err(anyhow::Error::msg)?),
        client_token: Some(client_token.clone()),
        tls: None,
        client_ca: None,
    };
    let server = tokio::spawn(serve(shared.clone(), listener, sec.clone(), async {
        let _ = stop_rx.await;
    }));

    let cpus = sray_engine::sys::cpus();
    let threads = if plan.threads == 0 {
        cpus
    } else {
        plan.threads
    };
    let each_threads = (threads / plan.workers).max(1);
    let each_memory = ((plan.memory - records_memory) / plan.workers as u64).max(1 << 20);
    let exe = std::env::current_exe().context("cannot find the sray executable")?;
    let mut children: Vec<Child> = Vec::new();
    let mut logs = Vec::new();
    for i in 0..plan.workers {
        let log_path = dir.path().join(format!("worker-{i}.log"));
        let log = std::fs::File::create(&log_path)?;
        let child = Command::new(&exe)
            .arg("worker")
            .args(["--coordinator", &url])
            .arg("--token-file")
            .arg(&token_file)
            .arg("--cache-dir")
            .arg(&cache)
            .args(["--threads", &each_threads.to_string()])
            .args(["--memory", &each_memory.to_string()])
            .args(["--name", &format!("local-{i}")])
            // The coordinator is this process: compressing records costs
            // more than sending them raw over loopback.
            .arg("--raw-records")
            .args(
                plan.tmp_dir
                    .iter()
                    .flat_map(|d| [std::ffi::OsStr::new("--tmp-dir"), d.as_os_str()]),
            )
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::from(log))
            .kill_on_drop(true)
            .spawn()
            .context("cannot start a worker process")?;
        children.push(child);
        logs.push(log_path);
    }

    // The scene is hashed while the workers start: they need it only when
    // the job comes.
    let hashed = {
        let shared = shared.clone();
        let file = abs.clone();
        tokio::task::spawn_blocking(move || shared.scenes.add_file(&file))
            .await
            .map_err(anyhow::Error::from)
            .and_then(|r| r)
            .and_then(|hash| {
                std::os::unix::fs::symlink(&abs, cache.join(format!("{hash}.sdb")))?;
                Ok(hash)
            })
    };
    let hash = match hashed {
        Ok(h) => h,
        Err(e) => {
            stop_all(&mut children).await;
            let _ = stop_tx.send(());
            let _ = server.await;
            return Err(e);
        }
    };
    // The first round is cut into shards for the workers there are (and
    // later rounds follow its cut when records stay at the workers): the
    // workers are given a moment to join first.
    let joined = std::time::Instant::now();
    while shared.worker_count() < plan.workers && joined.elapsed() < Duration::from_secs(10) {
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    let target = Target {
        url,
        token: Some(client_token),
        ca: None,
        identity: None,
    };
    let job = client::render_with(
        &target,
        db,
        Some(hash),
        params,
        shard_rays,
        format,
        progress,
        false,
    );
    let mut traced = shared.traced.subscribe();
    // A worker exiting before the job's tracing ends fails the render; once
    // it has ended, the workers are asked to stop while the coordinator
    // encodes and keeps the image (their exit takes as long).
    let supervise = async {
        tokio::select! {
            _ = wait_all(&mut children) => {
                let tail = logs.iter().filter_map(|p| std::fs::read_to_string(p).ok()).filter_map(|s| s.lines().last().map(String::from)).collect::<Vec<_>>().join("\n");
                return anyhow::anyhow!("every local worker exited:\n{tail}");
            }
            _ = traced.wait_for(|&n| n > 0) => {}
        }
        terminate(&children);
        std::future::pending().await
    };
    let r = tokio::select! {
        r = job => r,
        e = supervise => Err(e),
    };
    stop_all(&mut children).await;
    let _ = stop_tx.send(());
    let _ = server.await;
    r
}

async fn wait_all(children: &mut [Child]) {
    for c in children.iter_mut() {
        let _ = c.wait().await;
    }
}

/// Asks the workers still running to stop (SIGTERM: they finish cleaning
/// up their spill files).
fn terminate(children: &[Child]) {
    for c in children {
        // `id` is none once the child has been reaped.
        if let Some(pid) = c.id() {
            // SAFETY: kill(2) takes two integers and touches no memory of
            // ours. `pid` is the id of our own child, which has not been
            // reaped (`id` said so), so it cannot have been reused for
            // another process.
            unsafe {
                libc::kill(pid as libc::pid_t, libc::SIGTERM);
            }
        }
    }
}

/// Asks the workers to stop, and kills those still running after a grace
/// period.
async fn stop_all(children: &mut [Child]) {
    terminate(children);
    for c in children.iter_mut() {
        if tokio::time::timeout(Duration::from_secs(5), c.wait())
            .await
            .is_err()
        {
            let _ = c.kill().await;
        }
    }
}
