//! No fault bigger than its task: real `sray coordinator`, `sray worker`
//! and `sray render` processes on loopback, disks made full with a
//! file-size limit (`prlimit`, which the processes take as an error, not
//! a signal), and fake workers speaking the real protocol that hang.
//! Also the classic Prometheus scraper, a worker's SIGTERM, a killed
//! worker's spill files, two jobs at once and a coordinator killed right
//! after a round.

use crate::common;

use common::cluster::{self, coordinator, coordinator_on};
use common::{Proc, json, ok};
use sray_proto::auth::Token;
use sray_proto::net::{Client, Target};
use sray_proto::v1;
use std::io::{Read, Write};
use std::path::Path;
use std::time::{Duration, Instant};

fn worker(dir: &Path, url: &str, name: &str, extra: &[&str]) -> Proc {
    cluster::worker(dir, url, name, Some("token"), extra)
}

fn registered(coord: &Proc, name: &str) {
    cluster::registered(coord, name)
}

fn port(url: &str) -> String {
    format!("127.0.0.1:{}", url.rsplit(':').next().unwrap())
}

/// The embedded render of a scene (the reference image).
fn embedded(dir: &Path, scene: &str, size: &str) -> Vec<u8> {
    let out = format!("emb-{}-{size}.png", scene.replace([':', '/', '.'], "_"));
    ok(
        dir,
        &[
            "render", scene, "-o", &out, "--mode", "bf", "--width", size, "--height", size,
        ],
    );
    std::fs::read(dir.join(out)).unwrap()
}

fn render_args<'a>(scene: &'a str, url: &'a str, out: &'a str, size: &'a str) -> Vec<&'a str> {
    cluster::render_args(scene, url, "token", out, size, "256")
}

/// A client render in the background.
fn client(dir: &Path, args: &[&str]) -> Proc {
    let tickets = dir.join("tickets");
    Proc::start(dir, args, &[("SRAY_JOBS_DIR", tickets.to_str().unwrap())])
}

fn signal(p: &Proc, sig: libc::c_int) {
    // SAFETY: kill(2) takes two integers; the pid is our own unreaped
    // child's, so it cannot name another process.
    unsafe {
        libc::kill(p.child.id() as libc::pid_t, sig);
    }
}

/// Sets the file-size limit (`ulimit -f`) of the process `p`: its writes
/// past `bytes` fail (EFBIG), as on a full disk.
fn limit_file_size(p: &Proc, bytes: u64) {
    let lim = libc::rlimit {
        rlim_cur: bytes as libc::rlim_t,
        rlim_max: libc::RLIM_INFINITY,
    };
    // SAFETY: prlimit(2) reads the one rlimit we pass and writes nothing
    // (a null old limit); the pid is our own unreaped child's.
    let r = unsafe {
        libc::prlimit(
            p.child.id() as libc::pid_t,
            libc::RLIMIT_FSIZE,
            &lim,
            std::ptr::null_mut(),
        )
    };
    assert_eq!(r, 0, "prlimit: {}", std::io::Error::last_os_error());
}

/// `sray status --json` of the coordinator at `url`.
fn status(dir: &Path, url: &str) -> serde_json::Value {
    json(&ok(
        dir,
        &[
            "status",
            "--coordinator",
            url,
            "--token-file",
            "token",
            "--json",
        ],
    ))
}

fn quarantined(dir: &Path, url: &str) -> Vec<String> {
    status(dir, url)["workers"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|w| w["quarantined"] == true)
        .map(|w| w["name"].as_str().unwrap().to_string())
        .collect()
}

// ---- a fake worker speaking the real protocol ----

fn rt() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap()
}

async fn connect(url: &str, token_file: &Path) -> Client {
    Target {
        url: url.to_string(),
        token: Some(Token::from_file(token_file).unwrap()),
        ca: None,
        identity: None,
    }
    .connect()
    .await
    .unwrap()
}

async fn register(c: &mut Client, name: &str) -> String {
    c.register(v1::RegisterRequest {
        name: name.into(),
        threads: 1,
        memory_bytes: 64 << 20,
        protocol_version: sray_proto::PROTOCOL_VERSION,
    })
    .await
    .unwrap()
    .into_inner()
    .session
}

/// Beats for `session` until the runtime ends.
fn keep_beating(c: &Client, session: &str) {
    let mut c = c.clone();
    let session = session.to_string();
    tokio::spawn(async move {
        loop {
            let _ = c
                .heartbeat(v1::HeartbeatRequest {
                    session: session.clone(),
                    running_tasks: vec![],
                })
                .await;
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
    });
}

// ---- the tests ----

/// A classic Prometheus text-format scraper (no OpenMetrics `Accept`
/// header) types every sample: each sample's name has its own `# TYPE`
/// line, and every `_total` is a counter. One that asks for OpenMetrics
/// gets it.
#[test]
fn metrics_are_typed_for_a_classic_scraper() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("token"), "s3cret\n").unwrap();
    let (coord, url) = coordinator(
        d,
        &["--token-file", "token", "--http-listen", "127.0.0.1:0"],
    );
    let line = coord.wait_for(&["sray coordinator http on"], 10.0);
    let http = line
        .rsplit(' ')
        .next()
        .unwrap()
        .trim_start_matches("http://")
        .trim_end_matches('/')
        .to_string();
    let _w = worker(d, &url, "w0", &[]);
    registered(&coord, "w0");
    ok(d, &render_args("spd:balls:1", &url, "c.png", "32"));

    let (head, body) = get(&http, "/metrics", None);
    assert!(head.contains("text/plain; version=0.0.4"), "{head}");
    let mut types = std::collections::HashMap::new();
    let mut samples = 0;
    for l in body.lines() {
        if let Some(t) = l.strip_prefix("# TYPE ") {
            let (name, kind) = t.split_once(' ').unwrap();
            assert!(
                types.insert(name.to_string(), kind.to_string()).is_none(),
                "two # TYPE lines for {name}"
            );
        } else if !l.starts_with('#') && !l.is_empty() {
            let name = l.split(['{', ' ']).next().unwrap();
            let kind = types
                .get(name)
                .unwrap_or_else(|| panic!("{name} is untyped to a classic parser:\n{body}"));
            assert!(
                !name.ends_with("_total") || kind == "counter",
                "{name} is a {kind}"
            );
            samples += 1;
        }
    }
    let counters = types.values().filter(|k| *k == "counter").count();
    assert!(counters >= 12, "{counters} counters:\n{body}");
    assert!(samples > 20, "{body}");
    assert!(!body.contains("# EOF"), "{body}");
    assert!(
        body.contains("sray_jobs_finished_total{outcome=\"done\"} 1"),
        "{body}"
    );
    let (head, body) = get(
        &http,
        "/metrics",
        Some("application/openmetrics-text;version=1.0.0,text/plain;version=0.0.4;q=0.5"),
    );
    assert!(head.contains("application/openmetrics-text"), "{head}");
    assert!(body.contains("# TYPE sray_rays counter"), "{body}");
    assert!(body.trim_end().ends_with("# EOF"), "{body}");
}

/// A plain HTTP/1.1 GET: the head and the body.
fn get(addr: &str, path: &str, accept: Option<&str>) -> (String, String) {
    let mut s = std::net::TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(30))).unwrap();
    let accept = accept.map_or(String::new(), |a| format!("Accept: {a}\r\n"));
    write!(
        s,
        "GET {path} HTTP/1.1\r\nHost: {addr}\r\n{accept}Connection: close\r\n\r\n"
    )
    .unwrap();
    let mut raw = Vec::new();
    s.read_to_end(&mut raw).unwrap();
    let raw = String::from_utf8(raw).unwrap();
    let (head, body) = raw.split_once("\r\n\r\n").unwrap();
    let body = if head.to_ascii_lowercase().contains("chunked") {
        let mut out = String::new();
        let mut rest = body;
        loop {
            let (n, tail) = rest.split_once("\r\n").unwrap();
            let n = usize::from_str_radix(n.trim(), 16).unwrap();
            if n == 0 {
                break;
            }
            out.push_str(&tail[..n]);
            rest = &tail[n + 2..];
        }
        out
    } else {
        body.to_string()
    };
    (head.to_string(), body)
}

/// A scene too large for every worker's disk fails its job with a
/// message that says so, and costs the workers nothing: none is
/// quarantined, and the next job, whose scene fits, runs at once.
#[test]
fn a_scene_too_large_for_every_worker_then_one_that_fits() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("token"), "s3cret\n").unwrap();
    let want = embedded(d, "spd:balls:1", "32");
    let (coord, url) = coordinator(d, &["--token-file", "token", "--worker-wait", "4"]);
    let workers: Vec<Proc> = ["w0", "w1"]
        .iter()
        .map(|n| worker(d, &url, n, &[]))
        .collect();
    for (w, n) in workers.iter().zip(["w0", "w1"]) {
        registered(&coord, n);
        // Room for a small scene (balls 1: 2 KB), not a large one
        // (tetra 7: about 300 KB).
        limit_file_size(w, 64 << 10);
    }
    let t0 = Instant::now();
    let o = common::run(d, &render_args("spd:tetra:7", &url, "big.png", "32"));
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("no worker could run"), "{err}");
    assert!(err.contains("no room"), "{err}");
    assert!(err.contains("w0") && err.contains("w1"), "{err}");
    assert!(quarantined(d, &url).is_empty(), "{}", coord.log());
    // The next job needs no wait for a quarantine to end.
    ok(d, &render_args("spd:balls:1", &url, "small.png", "32"));
    assert!(std::fs::read(d.join("small.png")).unwrap() == want);
    assert!(
        t0.elapsed() < Duration::from_secs(120),
        "the jobs took {:?}",
        t0.elapsed()
    );
    drop(workers);
}

/// The coordinator's own disk full while records spill: no worker is
/// blamed or quarantined, the job's log names the coordinator's path, and
/// the job ends well once there is room again, as does the next one.
#[test]
fn the_coordinators_full_disk_is_not_blamed_on_workers() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("token"), "s3cret\n").unwrap();
    let want = embedded(d, "spd:balls:2", "48");
    // Every record in flight goes to a spill file.
    let (coord, url) = coordinator(
        d,
        &[
            "--token-file",
            "token",
            "--records-memory",
            "1",
            "--worker-wait",
            "120",
        ],
    );
    let _w0 = worker(d, &url, "w0", &[]);
    let _w1 = worker(d, &url, "w1", &[]);
    registered(&coord, "w0");
    registered(&coord, "w1");
    // Once with room (the scene is uploaded), then with the disk full.
    ok(d, &render_args("spd:balls:2", &url, "a.png", "48"));
    limit_file_size(&coord, 2 << 10);
    let mark = coord.mark();
    let c = client(d, &render_args("spd:balls:2", &url, "b.png", "48"));
    coord.wait_for_after(mark, &["cannot keep a task's records"], 60.0);
    let said = c.wait_for(&["the coordinator cannot keep this job's records"], 60.0);
    let data = std::fs::canonicalize(d.join("data")).unwrap();
    assert!(
        said.contains(data.to_str().unwrap()),
        "the message does not name {}: {said}",
        data.display()
    );
    assert!(quarantined(d, &url).is_empty(), "{}", coord.log());
    assert!(!coord.log().contains("task failed"), "{}", coord.log());
    // Room again: the job goes on and ends well, and so does the next.
    limit_file_size(&coord, u64::MAX);
    let mut c = c;
    assert!(c.wait(120.0).success(), "{}", c.log());
    assert!(std::fs::read(d.join("b.png")).unwrap() == want);
    ok(d, &render_args("spd:balls:2", &url, "c.png", "48"));
    assert!(std::fs::read(d.join("c.png")).unwrap() == want);
    assert!(quarantined(d, &url).is_empty());
}

/// A worker that takes tasks and never answers them, while it beats, is
/// given one task: once that times out (a backup goes elsewhere) it gets
/// no other, so it costs the job one backup's time, not one per task.
#[test]
fn a_worker_that_never_answers_costs_one_backup() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("token"), "s3cret\n").unwrap();
    let want = embedded(d, "spd:balls:2", "64");
    let (coord, url) = coordinator(
        d,
        &[
            "--token-file",
            "token",
            "--deadline-min",
            "2",
            "--deadline-factor",
            "2",
        ],
    );
    let rt = rt();
    let taken = std::sync::Arc::new(std::sync::atomic::AtomicU64::new(0));
    let (u2, tok, t2) = (url.clone(), d.join("token"), taken.clone());
    rt.spawn(async move {
        let mut c = connect(&u2, &tok).await;
        let session = register(&mut c, "sink").await;
        keep_beating(&c, &session);
        // Asks again and again, several at once, and answers nothing.
        for _ in 0..4 {
            let (mut c, s, t) = (c.clone(), session.clone(), t2.clone());
            tokio::spawn(async move {
                loop {
                    let r = c
                        .next_task(v1::NextTaskRequest {
                            session: s.clone(),
                            held: vec![],
                        })
                        .await;
                    if r.is_ok_and(|r| r.into_inner().task.is_some()) {
                        t.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                    }
                }
            });
        }
    });
    registered(&coord, "sink");
    let _w = worker(d, &url, "w0", &[]);
    registered(&coord, "w0");
    ok(d, &render_args("spd:balls:2", &url, "c.png", "64"));
    assert!(std::fs::read(d.join("c.png")).unwrap() == want);
    let s = json(&std::fs::read_to_string(d.join("cluster.json")).unwrap());
    let n = taken.load(std::sync::atomic::Ordering::Relaxed);
    assert!(n <= 1, "the silent worker was given {n} tasks");
    assert!(s["backup_tasks"].as_u64().unwrap() <= 2, "{s}");
    drop(rt);
}

/// With records at the workers (`--records-at-workers`), a real worker
/// that holds records of round 1 and then takes a task of round 2 and
/// never answers it (`--fault stall-from-round=2`), beating all the
/// while, costs a backup's deadline: it is taken to be stuck, the records
/// it held are recomputed on the other worker (not the whole job), and
/// the image and every count are the embedded render's.
#[test]
fn records_at_workers_a_worker_that_hangs_holding_records_costs_a_backup() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("token"), "s3cret\n").unwrap();
    let want = embedded(d, "spd:balls:2", "64");
    ok(
        d,
        &[
            "render",
            "spd:balls:2",
            "-o",
            "emb2.png",
            "--mode",
            "bf",
            "--width",
            "64",
            "--height",
            "64",
            "--stats",
            "emb.json",
        ],
    );
    let emb = json(&std::fs::read_to_string(d.join("emb.json")).unwrap());
    let (coord, url) = coordinator(
        d,
        &[
            "--token-file",
            "token",
            "--records-at-workers",
            "--deadline-min",
            "2",
            "--deadline-factor",
            "2",
        ],
    );
    let _w0 = worker(d, &url, "w0", &[]);
    registered(&coord, "w0");
    let _stuck = worker(d, &url, "stuck", &["--fault", "stall-from-round=2"]);
    registered(&coord, "stuck");
    let t0 = Instant::now();
    ok(d, &render_args("spd:balls:2", &url, "c.png", "64"));
    let took = t0.elapsed();
    let s = json(&std::fs::read_to_string(d.join("cluster.json")).unwrap());
    assert!(std::fs::read(d.join("c.png")).unwrap() == want, "{s}");
    for k in [
        "eye_rays",
        "eye_hit_rays",
        "reflect_rays",
        "refract_rays",
        "shadow_rays",
        "intersection_tests",
        "intersection_tests_by_kind",
    ] {
        assert_eq!(s[k], emb[k], "{k}: {s}");
    }
    assert_eq!(s["job_restarts"], 0, "{s}");
    // It held records, and they were recomputed.
    assert!(s["recomputations"].as_u64().unwrap() >= 1, "{s}");
    let log = s["log"].to_string();
    assert!(log.contains("ran past a backup's deadline"), "{log}");
    assert!(log.contains("recomputed on worker w0"), "{log}");
    // A hang guard only: the stall costs a few seconds (the deadline of
    // a backup is 2 s here).
    assert!(took < Duration::from_secs(120), "{took:?}");
}

/// A worker given SIGTERM hands its task back and leaves at once: the
/// coordinator hears it (long before the worker's heartbeats would be
/// missed) and the job ends well on the other worker. A worker killed
/// outright leaves its spill directory, which the next worker started on
/// the same `--tmp-dir` removes; a live one's stays.
#[test]
fn sigterm_leaves_and_a_killed_workers_spill_files_go() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("token"), "s3cret\n").unwrap();
    let tmp = d.join("tmp");
    std::fs::create_dir(&tmp).unwrap();
    let tmp_s = tmp.to_str().unwrap();
    let want = embedded(d, "spd:gears:2", "64");
    let (coord, url) = coordinator(d, &["--token-file", "token", "--worker-timeout", "60"]);
    let mut w0 = worker(d, &url, "w0", &["--tmp-dir", tmp_s]);
    registered(&coord, "w0");
    let mark = coord.mark();
    let mut c = client(d, &render_args("spd:gears:2", &url, "c.png", "64"));
    coord.wait_for_after(mark, &["task assigned", "worker=w0"], 60.0);
    let t0 = Instant::now();
    signal(&w0, libc::SIGTERM);
    coord.wait_for_after(mark, &["worker left", "worker=w0"], 20.0);
    assert!(t0.elapsed() < Duration::from_secs(20));
    assert!(w0.wait(30.0).success(), "{}", w0.log());
    let spill_dirs = || {
        std::fs::read_dir(&tmp)
            .unwrap()
            .flatten()
            .map(|e| e.file_name().to_string_lossy().to_string())
            .filter(|n| n.starts_with("sray-worker-"))
            .collect::<Vec<_>>()
    };
    assert!(spill_dirs().is_empty(), "{:?}", spill_dirs());
    let mut w1 = worker(d, &url, "w1", &["--tmp-dir", tmp_s]);
    assert!(c.wait(120.0).success(), "{}", c.log());
    assert!(std::fs::read(d.join("c.png")).unwrap() == want);

    // Killed: its directory stays, until the next worker starts there.
    let before = spill_dirs();
    assert_eq!(before.len(), 1, "{before:?}");
    signal(&w1, libc::SIGKILL);
    w1.wait(30.0);
    let _w2 = worker(d, &url, "w2", &["--tmp-dir", tmp_s]);
    registered(&coord, "w2");
    let now = spill_dirs();
    assert_eq!(now.len(), 1, "{now:?}");
    assert!(!now.contains(&before[0]), "{now:?}");
    let w3 = worker(d, &url, "w3", &["--tmp-dir", tmp_s]);
    registered(&coord, "w3");
    assert_eq!(spill_dirs().len(), 2, "a live worker's spill files went");
    drop(w3);
}

/// Two jobs at once share the workers: a small job submitted after a
/// large one finishes first, not at the large one's pace.
#[test]
fn a_small_job_is_not_held_to_a_large_ones_pace() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("token"), "s3cret\n").unwrap();
    let want = embedded(d, "spd:balls:1", "32");
    let (coord, url) = coordinator(d, &["--token-file", "token", "--verify-fraction", "0"]);
    let _w = worker(d, &url, "w0", &[]);
    registered(&coord, "w0");
    let mut large = client(d, &render_args("spd:balls:3", &url, "large.png", "160"));
    coord.wait_for(&["task assigned"], 60.0);
    ok(d, &render_args("spd:balls:1", &url, "small.png", "32"));
    assert!(std::fs::read(d.join("small.png")).unwrap() == want);
    assert!(
        large.child.try_wait().unwrap().is_none(),
        "the large job ended before the small one"
    );
    assert!(large.wait(300.0).success(), "{}", large.log());
}

/// A coordinator killed right after a round has finished resumes from
/// that round, not the one before (the checkpoint is written before the
/// next round starts).
#[test]
fn a_killed_coordinator_resumes_from_the_last_finished_round() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("token"), "s3cret\n").unwrap();
    // Rounds of about a second (64 tasks each), so that the kill lands
    // in the round after the one awaited.
    let want = embedded(d, "spd:balls:3", "128");
    let (coord, url) = coordinator(d, &["--token-file", "token"]);
    let _w = worker(d, &url, "w0", &[]);
    registered(&coord, "w0");
    let mut c = client(d, &render_args("spd:balls:3", &url, "c.png", "128"));
    coord.wait_for(&["round done", "round=2"], 120.0);
    signal(&coord, libc::SIGKILL);
    drop(coord);
    let (coord, _) = coordinator_on(d, &port(&url), &["--token-file", "token"]);
    coord.wait_for(&["resuming at round 3"], 30.0);
    assert!(c.wait(180.0).success(), "{}", c.log());
    assert!(std::fs::read(d.join("c.png")).unwrap() == want);
}
