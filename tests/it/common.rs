//! Helpers for the end-to-end tests: run the real `sray` binary.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The `sray` under test (`SRAY_TEST_BIN` runs another build, e.g. to
/// check that a test fails on an older one).
pub fn sray() -> Command {
    let mut c = match std::env::var_os("SRAY_TEST_BIN") {
        Some(b) => Command::new(b),
        None => Command::new(env!("CARGO_BIN_EXE_sray")),
    };
    // Job tickets of cluster renders go under target/, not the home
    // directory (a test that needs them sets its own).
    c.env(
        "SRAY_JOBS_DIR",
        Path::new(env!("CARGO_TARGET_TMPDIR")).join("sray-tickets"),
    );
    c
}

/// Runs `sray ARGS` in `dir`.
pub fn run(dir: &Path, args: &[&str]) -> Output {
    sray()
        .current_dir(dir)
        .args(args)
        .output()
        .expect("run sray")
}

/// Runs and requires success; returns stdout.
pub fn ok(dir: &Path, args: &[&str]) -> String {
    let o = run(dir, args);
    assert!(
        o.status.success(),
        "sray {args:?} failed: {}\n{}",
        o.status,
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8(o.stdout).unwrap()
}

/// Runs and requires failure; returns stderr.
pub fn fails(dir: &Path, args: &[&str]) -> String {
    let o = run(dir, args);
    assert!(!o.status.success(), "sray {args:?} should have failed");
    let err = String::from_utf8(o.stderr).unwrap();
    assert!(!err.contains("panicked"), "sray {args:?} panicked:\n{err}");
    err
}

/// The seven default SPD scenes as NFF, written by the SPD programs: the
/// vendored copies in `tests/fixtures/spd`, or `$SRAY_SHARED_DIR/spd` when
/// that variable is set.
pub fn spd_fixtures() -> PathBuf {
    if let Ok(d) = std::env::var("SRAY_SHARED_DIR") {
        return PathBuf::from(d).join("spd");
    }
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/spd")
}

/// `shared/NAME` beside the repository (`$SRAY_SHARED_DIR/NAME` when that
/// is set), if it exists: found by searching upward from the crate.
pub fn shared_dir(name: &str) -> Option<PathBuf> {
    if let Ok(d) = std::env::var("SRAY_SHARED_DIR") {
        return Some(PathBuf::from(d).join(name)).filter(|d| d.is_dir());
    }
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .ancestors()
        .map(|d| d.join("shared").join(name))
        .find(|d| d.is_dir())
}

/// Whether this runs in CI (`CI=true`, which `.ci/run` exports): there,
/// a test must not skip for want of a tool or of ../shared.
pub fn in_ci() -> bool {
    std::env::var("CI").is_ok_and(|v| v == "true" || v == "1")
}

/// A test cannot run here for want of something (`why`). Outside CI, says
/// so on stderr and returns, so that the caller can skip; in CI, fails
/// with that reason, since a green CI must mean that the test ran.
pub fn cannot_run(why: &str) {
    assert!(
        !in_ci(),
        "{why}; in CI (CI=true) this test must run, not skip: .ci/run installs its tools and \
         expects ../shared beside the repository"
    );
    eprintln!("skipping: {why}");
}

/// `shared/meshes` beside the repository (real meshes, not vendored: CI
/// has them). When it is absent, [`cannot_run`] says so (and fails in CI)
/// and this returns None, so that the caller can skip:
/// `let Some(m) = shared_meshes() else { return };`
pub fn shared_meshes() -> Option<PathBuf> {
    let m = shared_dir("meshes");
    if m.is_none() {
        cannot_run(&format!(
            "../shared/meshes not found (searched upward from {} for shared/meshes; set \
             SRAY_SHARED_DIR to its parent)",
            env!("CARGO_MANIFEST_DIR")
        ));
    }
    m
}

pub fn json(s: &str) -> serde_json::Value {
    serde_json::from_str(s).unwrap_or_else(|e| panic!("not JSON ({e}):\n{s}"))
}

/// A background `sray` process whose stderr is collected line by line;
/// killed when dropped.
pub struct Proc {
    pub child: std::process::Child,
    lines: std::sync::Arc<std::sync::Mutex<Vec<String>>>,
}

impl Proc {
    pub fn start(dir: &Path, args: &[&str], env: &[(&str, &str)]) -> Proc {
        let mut cmd = sray();
        cmd.current_dir(dir).args(args);
        for (k, v) in env {
            cmd.env(k, v);
        }
        Proc::spawn(cmd)
    }

    /// Starts `cmd` (another program, or `sray` run some other way), its
    /// stderr collected as by [`Proc::start`].
    pub fn spawn(mut cmd: Command) -> Proc {
        use std::io::BufRead;
        cmd.stdin(std::process::Stdio::null())
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::piped());
        let mut child = cmd
            .spawn()
            .unwrap_or_else(|e| panic!("start {:?}: {e}", cmd.get_program()));
        let err = child.stderr.take().unwrap();
        let lines = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
        let l2 = lines.clone();
        std::thread::spawn(move || {
            for line in std::io::BufReader::new(err).lines() {
                let Ok(line) = line else { break };
                l2.lock().unwrap().push(line);
            }
        });
        Proc { child, lines }
    }

    /// Waits (up to `secs`) for a stderr line containing all of `parts`.
    pub fn wait_for(&self, parts: &[&str], secs: f64) -> String {
        self.wait_for_after(0, parts, secs)
    }

    /// Lines of stderr so far, to wait for later lines only.
    pub fn mark(&self) -> usize {
        self.lines.lock().unwrap().len()
    }

    /// As [`Proc::wait_for`], among the lines after `mark`.
    pub fn wait_for_after(&self, mark: usize, parts: &[&str], secs: f64) -> String {
        let end = std::time::Instant::now() + std::time::Duration::from_secs_f64(secs);
        loop {
            if let Some(l) = self
                .lines
                .lock()
                .unwrap()
                .iter()
                .skip(mark)
                .find(|l| parts.iter().all(|p| l.contains(p)))
            {
                return l.clone();
            }
            assert!(
                std::time::Instant::now() < end,
                "no line with {parts:?} within {secs} s; got:\n{}",
                self.log()
            );
            std::thread::sleep(std::time::Duration::from_millis(20));
        }
    }

    pub fn log(&self) -> String {
        self.lines.lock().unwrap().join("\n")
    }

    /// Waits for the process to end (up to `secs`) and returns its status.
    pub fn wait(&mut self, secs: f64) -> std::process::ExitStatus {
        let end = std::time::Instant::now() + std::time::Duration::from_secs_f64(secs);
        loop {
            if let Some(s) = self.child.try_wait().unwrap() {
                return s;
            }
            assert!(
                std::time::Instant::now() < end,
                "still running after {secs} s:\n{}",
                self.log()
            );
            std::thread::sleep(std::time::Duration::from_millis(20));
        }
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Cluster processes on loopback, as the cluster tests start them.
pub mod cluster {
    use super::Proc;
    use std::path::Path;

    /// The arguments of a client's render of `scene` at `size`x`size` on
    /// the coordinator at `url`, statistics to `cluster.json`.
    pub fn render_args<'a>(
        scene: &'a str,
        url: &'a str,
        token: &'a str,
        out: &'a str,
        size: &'a str,
        shard_rays: &'a str,
    ) -> Vec<&'a str> {
        vec![
            "render",
            scene,
            "-o",
            out,
            "--coordinator",
            url,
            "--token-file",
            token,
            "--width",
            size,
            "--height",
            size,
            "--shard-rays",
            shard_rays,
            "--stats",
            "cluster.json",
        ]
    }

    /// A coordinator listening on `listen` (`127.0.0.1:0` for a free port)
    /// with its data in `data`, fast heartbeats and a worker declared lost
    /// after 2 s of silence (unless `extra` sets `--worker-timeout`), and
    /// debug logs of its lifecycle; returns it and its gRPC URL.
    pub fn coordinator_on(dir: &Path, listen: &str, extra: &[&str]) -> (Proc, String) {
        let mut args = vec![
            "coordinator",
            "--listen",
            listen,
            "--data-dir",
            "data",
            "--heartbeat-ms",
            "200",
        ];
        if !extra.contains(&"--worker-timeout") {
            args.extend_from_slice(&["--worker-timeout", "2"]);
        }
        args.extend_from_slice(extra);
        let p = Proc::start(dir, &args, &[("RUST_LOG", "info,sray_coordinator=debug")]);
        let line = p.wait_for(&["listening on"], 30.0);
        let url = line.rsplit(' ').next().unwrap().to_string();
        (p, url)
    }

    /// [`coordinator_on`] a free port.
    pub fn coordinator(dir: &Path, extra: &[&str]) -> (Proc, String) {
        coordinator_on(dir, "127.0.0.1:0", extra)
    }

    /// A worker named `name` with a cache of its own, one thread and
    /// 64 MiB (unless `extra` sets `--memory`), authenticated with the
    /// token file `token` if one is given.
    pub fn worker(dir: &Path, url: &str, name: &str, token: Option<&str>, extra: &[&str]) -> Proc {
        let cache = format!("cache-{name}");
        let mut args = vec![
            "worker",
            "--coordinator",
            url,
            "--cache-dir",
            &cache,
            "--threads",
            "1",
            "--name",
            name,
        ];
        if let Some(t) = token {
            args.extend_from_slice(&["--token-file", t]);
        }
        if !extra.contains(&"--memory") {
            args.extend_from_slice(&["--memory", "64MiB"]);
        }
        args.extend_from_slice(extra);
        Proc::start(dir, &args, &[])
    }

    /// Waits until the coordinator has registered the worker `name`.
    pub fn registered(coord: &Proc, name: &str) {
        coord.wait_for(&["worker registered", &format!("worker={name} ")], 30.0);
    }
}
