//! A cluster that never returns a wrong image and never loses a job: real
//! `sray coordinator`, `sray worker` and `sray render` processes on
//! loopback, and fake workers and clients speaking the real protocol
//! (tonic) that lie, fail, hang or try what they may not.
//!
//! Each test names the item of the issue it covers.

use crate::common;

use common::cluster::{self, coordinator, coordinator_on};
use common::{Proc, fails, json, ok};
use sray_proto::auth::Token;
use sray_proto::net::{Client, Target};
use sray_proto::v1;
use std::path::Path;
use std::time::{Duration, Instant};

fn port(url: &str) -> String {
    format!("127.0.0.1:{}", url.rsplit(':').next().unwrap())
}

fn worker(dir: &Path, url: &str, name: &str, token: &str, extra: &[&str]) -> Proc {
    common::cluster::worker(dir, url, name, Some(token), extra)
}

fn registered(coord: &Proc, name: &str) {
    common::cluster::registered(coord, name)
}

/// The embedded render of a scene (the reference image).
fn embedded(dir: &Path, scene: &str, size: &str) -> Vec<u8> {
    let out = format!("emb-{}.png", scene.replace([':', '/', '.'], "_"));
    ok(
        dir,
        &[
            "render", scene, "-o", &out, "--mode", "bf", "--width", size, "--height", size,
        ],
    );
    std::fs::read(dir.join(out)).unwrap()
}

/// A client's render on the coordinator at `url`, in small shards (256
/// rays) so that even small images make many tasks.
fn render_args<'a>(
    scene: &'a str,
    url: &'a str,
    token: &'a str,
    out: &'a str,
    size: &'a str,
) -> Vec<&'a str> {
    cluster::render_args(scene, url, token, out, size, "256")
}

/// A client render in the background, its tickets in `dir/tickets`.
fn client(dir: &Path, args: &[&str]) -> Proc {
    let tickets = dir.join("tickets");
    Proc::start(dir, args, &[("SRAY_JOBS_DIR", tickets.to_str().unwrap())])
}

fn stats(dir: &Path) -> serde_json::Value {
    json(&std::fs::read_to_string(dir.join("cluster.json")).unwrap())
}

fn sigterm(p: &Proc) {
    // SAFETY: kill(2) takes two integers; the pid is our own unreaped
    // child's, so it cannot name another process.
    unsafe {
        libc::kill(p.child.id() as libc::pid_t, libc::SIGTERM);
    }
}

// ---- a fake worker or client speaking the real protocol ----

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

async fn next(c: &mut Client, session: &str) -> Option<v1::Task> {
    c.next_task(v1::NextTaskRequest {
        session: session.into(),
        held: vec![],
    })
    .await
    .ok()?
    .into_inner()
    .task
}

fn tref(session: &str, t: &v1::Task) -> v1::TaskRef {
    v1::TaskRef {
        session: session.into(),
        task_id: t.task_id,
        attempt: t.attempt,
        ..Default::default()
    }
}

/// Sends an output: intersection results (plausible lies: in-range
/// object ids at finite distances), or for shading nothing at all.
async fn lie(c: &mut Client, session: &str, t: &v1::Task, seed: &mut u64) -> bool {
    use v1::task_output::Part;
    let mut msgs = vec![v1::TaskOutput {
        part: Some(Part::Header(tref(session, t))),
    }];
    if t.stage == v1::Stage::Intersect as i32 {
        let mut recs = Vec::new();
        for i in 0..t.ray_count {
            *seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let r = sray_engine::bf::ResultRec {
                ray: t.first_ray + i,
                prim: sray_engine::hit::PrimId::object(((*seed >> 33) % 4) as u32),
                t: 1.0 + (*seed >> 40) as f64 / 1e6,
            };
            recs.push(r);
        }
        for chunk in recs.chunks(10_000) {
            msgs.push(v1::TaskOutput {
                part: Some(Part::Records(v1::RecordChunk {
                    kind: v1::RecordKind::Results as i32,
                    data: sray_proto::wire::encode(chunk),
                    held: None,
                    raw: false,
                })),
            });
        }
    }
    msgs.push(v1::TaskOutput {
        part: Some(Part::Summary(v1::TaskSummary::default())),
    });
    c.complete_task(tokio_stream::iter(msgs))
        .await
        .map(|r| r.into_inner().accepted)
        .unwrap_or(false)
}

/// Item 2: a worker that returns plausible lies (random in-range object
/// ids, empty shading) is caught by verification, quarantined, its work
/// redone; the image is the embedded one, and the job's log says so.
#[test]
fn a_lying_worker_is_caught_and_the_image_is_right() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("token"), "s3cret\n").unwrap();
    let want = embedded(d, "spd:balls:1", "32");
    let (coord, url) = coordinator(d, &["--token-file", "token"]);
    let rt = rt();
    let lies = std::sync::Arc::new(std::sync::atomic::AtomicU64::new(0));
    let l2 = lies.clone();
    let (u2, tok) = (url.clone(), d.join("token"));
    rt.spawn(async move {
        let mut c = connect(&u2, &tok).await;
        let session = register(&mut c, "liar").await;
        keep_beating(&c, &session);
        let mut seed = 7u64;
        loop {
            if let Some(t) = next(&mut c, &session).await
                && lie(&mut c, &session, &t, &mut seed).await
            {
                l2.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            }
        }
    });
    registered(&coord, "liar");
    let _w = worker(d, &url, "honest", "token", &[]);
    registered(&coord, "honest");
    ok(d, &render_args("spd:balls:1", &url, "token", "c.png", "32"));
    assert!(
        lies.load(std::sync::atomic::Ordering::Relaxed) > 0,
        "the liar was never accepted once"
    );
    assert!(
        std::fs::read(d.join("c.png")).unwrap() == want,
        "wrong image"
    );
    let s = stats(d);
    assert!(
        s["verification"]["mismatches"].as_u64().unwrap() >= 1,
        "{s}"
    );
    assert_eq!(
        s["verification"]["quarantined"],
        serde_json::json!(["liar"]),
        "{s}"
    );
    let log = s["log"].to_string();
    assert!(log.contains("worker liar quarantined"), "{log}");
    drop(rt);
}

/// Item 2 with records at the workers (`--records-at-workers`): a real
/// worker that sends plausible wrong colours (`--fault lie`: every
/// contribution's channels rotated; its results and spawned rays are
/// right, and stay with it) spoils the image when nothing checks it; with
/// verification, which runs whole shards (a quarter of them here) and
/// the rounds before them again on another worker and, on a mismatch,
/// traces them at the coordinator, the liar is quarantined and the job
/// starts again without it; the image is the embedded one.
#[test]
fn records_at_workers_a_lying_worker_is_caught_and_the_image_is_right() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("token"), "s3cret\n").unwrap();
    let want = embedded(d, "spd:balls:2", "64");
    let cluster = |verify: &str| {
        let (coord, url) = coordinator(
            d,
            &[
                "--token-file",
                "token",
                "--records-at-workers",
                "--verify-fraction",
                verify,
            ],
        );
        let liar = worker(d, &url, "liar", "token", &["--fault", "lie"]);
        registered(&coord, "liar");
        let honest = worker(d, &url, "honest", "token", &[]);
        registered(&coord, "honest");
        (coord, url, [liar, honest])
    };
    // Unchecked, the lies reach the image.
    {
        let (_coord, url, _workers) = cluster("0");
        ok(d, &render_args("spd:balls:2", &url, "token", "u.png", "64"));
        assert!(
            std::fs::read(d.join("u.png")).unwrap() != want,
            "the liar's lies did not show"
        );
    }
    let (_coord, url, _workers) = cluster("0.25");
    let t0 = Instant::now();
    ok(d, &render_args("spd:balls:2", &url, "token", "c.png", "64"));
    let took = t0.elapsed();
    let s = stats(d);
    assert!(
        std::fs::read(d.join("c.png")).unwrap() == want,
        "wrong image: {s}"
    );
    assert!(
        s["verification"]["mismatches"].as_u64().unwrap() >= 1,
        "{s}"
    );
    assert_eq!(
        s["verification"]["quarantined"],
        serde_json::json!(["liar"]),
        "{s}"
    );
    // The liar's colour was in the frame: the job started again without
    // it, once.
    assert_eq!(s["job_restarts"], 1, "{s}");
    let log = s["log"].to_string();
    assert!(log.contains("worker liar quarantined"), "{log}");
    assert!(took < Duration::from_secs(120), "{took:?}");
}

/// The same for a worker whose kept records are not what it says
/// (`--fault wrong-digest`: the digest of the records it keeps is wrong,
/// its colour right): the digests differ, and the coordinator's own
/// trace, whose digests are those of honest workers, finds it out.
#[test]
fn records_at_workers_a_wrong_digest_is_caught() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("token"), "s3cret\n").unwrap();
    let want = embedded(d, "spd:balls:1", "48");
    let (coord, url) = coordinator(d, &["--token-file", "token", "--records-at-workers"]);
    let _liar = worker(d, &url, "liar", "token", &["--fault", "wrong-digest"]);
    registered(&coord, "liar");
    let _honest = worker(d, &url, "honest", "token", &[]);
    registered(&coord, "honest");
    ok(d, &render_args("spd:balls:1", &url, "token", "c.png", "48"));
    let s = stats(d);
    assert!(std::fs::read(d.join("c.png")).unwrap() == want, "{s}");
    // Each worker's first shard is checked: the liar's, or the honest
    // one's by the liar; either way the liar is found.
    assert!(
        s["verification"]["mismatches"].as_u64().unwrap() >= 1,
        "{s}"
    );
    assert_eq!(
        s["verification"]["quarantined"],
        serde_json::json!(["liar"]),
        "{s}"
    );
    assert_eq!(s["job_restarts"], 1, "{s}");
}

/// Sends a shading output of `recs` contributions; the coordinator's
/// answer (an error's message, or whether it accepted the output).
async fn contribute(
    c: &mut Client,
    session: &str,
    t: &v1::Task,
    recs: &[sray_engine::bf::Contribution],
) -> Result<bool, String> {
    let data = sray_proto::wire::encode(recs);
    send_chunk(c, session, t, v1::RecordKind::Contributions, data).await
}

/// Sends a shading output of one chunk of `kind`; as [`contribute`].
async fn send_chunk(
    c: &mut Client,
    session: &str,
    t: &v1::Task,
    kind: v1::RecordKind,
    data: Vec<u8>,
) -> Result<bool, String> {
    use v1::task_output::Part;
    let msgs = vec![
        v1::TaskOutput {
            part: Some(Part::Header(tref(session, t))),
        },
        v1::TaskOutput {
            part: Some(Part::Records(v1::RecordChunk {
                kind: kind as i32,
                data,
                held: None,
                raw: false,
            })),
        },
        v1::TaskOutput {
            part: Some(Part::Summary(v1::TaskSummary::default())),
        },
    ];
    c.complete_task(tokio_stream::iter(msgs))
        .await
        .map(|r| r.into_inner().accepted)
        .map_err(|s| s.message().to_string())
}

/// A run of contributions (one record for a row of frame slots) is taken
/// only from a worker that keeps its records, and no shard's
/// contributions may cover more slots than it has rays: a few bytes from
/// a worker can never ask the coordinator for unbounded work. Colour
/// packed per slot is taken only from a worker that keeps its records
/// too (elsewhere verification compares contributions one by one).
#[test]
fn contributions_cover_no_more_slots_than_their_rays() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("token"), "s3cret\n").unwrap();
    let (coord, url) = coordinator(d, &["--token-file", "token", "--verify-fraction", "0"]);
    let _render = client(d, &render_args("spd:balls:1", &url, "token", "c.png", "32"));
    let rt = rt();
    let answers = rt.block_on(async {
        let mut c = connect(&url, &d.join("token")).await;
        let session = register(&mut c, "greedy").await;
        keep_beating(&c, &session);
        let mut seed = 11u64;
        let mut answers = Vec::new();
        let t0 = Instant::now();
        while answers.len() < 3 && t0.elapsed() < Duration::from_secs(60) {
            let Some(t) = next(&mut c, &session).await else {
                continue;
            };
            if t.stage == v1::Stage::Intersect as i32 {
                lie(&mut c, &session, &t, &mut seed).await;
                continue;
            }
            let one = |corner: u32, run: u32| sray_engine::bf::Contribution {
                corner,
                run,
                rgb: [1, 2, 3],
            };
            if answers.len() == 2 {
                let mut one = vec![sray_proto::colour::SlotColour {
                    slot: 0,
                    run: 0,
                    rgb: [1, 2, 3],
                }];
                let data = sray_proto::wire::encode(&sray_proto::colour::pack(&mut one));
                let kind = v1::RecordKind::Colour;
                answers.push(send_chunk(&mut c, &session, &t, kind, data).await);
                continue;
            }
            let recs: Vec<_> = if answers.is_empty() {
                // A run of four slots, where runs are not taken.
                vec![one(0, 3)]
            } else {
                // One slot more than the shard has rays.
                (0..=t.ray_count)
                    .map(|i| one((i % 100) as u32, 0))
                    .collect()
            };
            answers.push(contribute(&mut c, &session, &t, &recs).await);
        }
        answers
    });
    drop(rt);
    drop(coord);
    assert_eq!(answers.len(), 3, "{answers:?}");
    let msg = |a: &Result<bool, String>| a.clone().err().unwrap_or_default();
    assert!(
        msg(&answers[0]).contains("a run of contributions"),
        "{answers:?}"
    );
    assert!(
        msg(&answers[1]).contains("frame slots from a shard of"),
        "{answers:?}"
    );
    assert!(
        msg(&answers[2]).contains("packed colour from a task whose output is checked"),
        "{answers:?}"
    );
}

/// An intersection result naming an instance's triangle past every
/// model of the scene (here a scene without models) is refused when it
/// arrives; one within the models is checked against the instance's own
/// model when it is shaded (`bf::shade`).
#[test]
fn an_instance_hit_past_every_model_is_refused() {
    use v1::task_output::Part;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("token"), "s3cret\n").unwrap();
    let (coord, url) = coordinator(d, &["--token-file", "token", "--verify-fraction", "0"]);
    let _render = client(d, &render_args("spd:balls:1", &url, "token", "c.png", "32"));
    let rt = rt();
    let answer = rt.block_on(async {
        let mut c = connect(&url, &d.join("token")).await;
        let session = register(&mut c, "forger").await;
        keep_beating(&c, &session);
        let t0 = Instant::now();
        while t0.elapsed() < Duration::from_secs(60) {
            let Some(t) = next(&mut c, &session).await else {
                continue;
            };
            if t.stage != v1::Stage::Intersect as i32 {
                continue;
            }
            let recs: Vec<_> = (0..t.ray_count)
                .map(|i| sray_engine::bf::ResultRec {
                    ray: t.first_ray + i,
                    prim: match i {
                        0 => sray_engine::hit::PrimId::instance(0, 5),
                        _ => sray_engine::hit::PrimId::NONE,
                    },
                    t: if i == 0 { 1.0 } else { f64::INFINITY },
                })
                .collect();
            let msgs = vec![
                v1::TaskOutput {
                    part: Some(Part::Header(tref(&session, &t))),
                },
                v1::TaskOutput {
                    part: Some(Part::Records(v1::RecordChunk {
                        kind: v1::RecordKind::Results as i32,
                        data: sray_proto::wire::encode(&recs),
                        held: None,
                        raw: false,
                    })),
                },
                v1::TaskOutput {
                    part: Some(Part::Summary(v1::TaskSummary::default())),
                },
            ];
            return Some(
                c.complete_task(tokio_stream::iter(msgs))
                    .await
                    .map(|r| r.into_inner().accepted)
                    .map_err(|s| s.message().to_string()),
            );
        }
        None
    });
    drop(rt);
    drop(coord);
    let answer = answer.expect("no intersection task came");
    assert!(
        answer.as_ref().is_err_and(|m| m.contains("no object")),
        "{answer:?}"
    );
}

/// Item 1: job ids are random and workers key their caches by content:
/// after a coordinator restart with the same worker up, a render of
/// another scene gives that scene's image, not the cached one's.
#[test]
fn a_restarted_coordinator_never_hands_out_another_scenes_image() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("token"), "s3cret\n").unwrap();
    let want = embedded(d, "spd:tetra:2", "32");
    let (coord, url) = coordinator(d, &["--token-file", "token", "--verify-fraction", "0"]);
    let _w = worker(d, &url, "w0", "token", &[]);
    registered(&coord, "w0");
    ok(d, &render_args("spd:balls:2", &url, "token", "a.png", "32"));
    drop(coord);
    let (coord, url2) = coordinator_on(
        d,
        &port(&url),
        &["--token-file", "token", "--verify-fraction", "0"],
    );
    assert_eq!(url, url2);
    registered(&coord, "w0");
    ok(d, &render_args("spd:tetra:2", &url, "token", "b.png", "32"));
    assert!(
        std::fs::read(d.join("b.png")).unwrap() == want,
        "tetra rendered as another scene"
    );
}

/// Item 3: a SIGKILLed coordinator resumes its job from the last finished
/// round; the client reconnects and gets the image; the image can be
/// fetched again by job id; no spill file of the killed run is left.
#[test]
fn a_killed_coordinator_resumes_and_the_image_can_be_fetched_again() {
    killed_coordinator_resumes(&[]);
}

/// A job checkpointed by a coordinator that took every record resumes on
/// one that leaves them at the workers: the resumed round's rays are the
/// checkpoint's, cut into shards as before (not along held segments, of
/// which there are none).
#[test]
fn a_checkpoint_resumes_on_a_coordinator_with_records_at_the_workers() {
    killed_coordinator_resumes(&["--records-at-workers"]);
}

/// Kills the coordinator once round 1 is journaled, starts it again with
/// `restart_extra` as well, and checks the image, the spill files and a
/// fetch after the job.
fn killed_coordinator_resumes(restart_extra: &[&str]) {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("token"), "s3cret\n").unwrap();
    let tmp = d.join("tmp");
    std::fs::create_dir(&tmp).unwrap();
    let tmp_s = tmp.to_str().unwrap().to_string();
    let want = embedded(d, "spd:balls:2", "48");
    let extra = ["--token-file", "token", "--tmp-dir", &tmp_s];
    let (coord, url) = coordinator(d, &extra);
    let _w = worker(d, &url, "w0", "token", &[]);
    registered(&coord, "w0");
    let mut c = client(d, &render_args("spd:balls:2", &url, "token", "c.png", "48"));
    // Killed once round 1 is journaled.
    coord.wait_for(&["checkpoint", "round=2"], 120.0);
    let before: Vec<_> = walk(&tmp);
    drop(coord);
    let again: Vec<&str> = extra.iter().chain(restart_extra).copied().collect();
    let (coord, _) = coordinator_on(d, &port(&url), &again);
    coord.wait_for(&["resuming at round"], 30.0);
    for f in &before {
        assert!(
            !f.exists(),
            "spill file of the killed run left: {}",
            f.display()
        );
    }
    assert!(c.wait(180.0).success(), "{}", c.log());
    assert!(
        std::fs::read(d.join("c.png")).unwrap() == want,
        "wrong image after resuming"
    );
    let id = stats(d)["job_id"].as_str().unwrap().to_string();
    let tickets = d.join("tickets");
    let o = common::sray()
        .current_dir(d)
        .args(["fetch", &id, "-o", "again.png", "--token-file", "token"])
        .env("SRAY_JOBS_DIR", &tickets)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(std::fs::read(d.join("again.png")).unwrap() == want);
    drop(coord);
}

fn walk(d: &Path) -> Vec<std::path::PathBuf> {
    let mut v = Vec::new();
    if let Ok(rd) = std::fs::read_dir(d) {
        for e in rd.flatten() {
            let p = e.path();
            if p.is_dir() {
                v.extend(walk(&p));
            } else {
                v.push(p);
            }
        }
    }
    v
}

/// Item 4: SIGTERM stops the coordinator within seconds; the client is
/// told "coordinator restarting" (not a false reason), reconnects to the
/// next run and gets the right image.
#[test]
fn sigterm_stops_promptly_and_the_client_rides_the_restart() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("token"), "s3cret\n").unwrap();
    let want = embedded(d, "spd:balls:2", "48");
    let (mut coord, url) = coordinator(d, &["--token-file", "token"]);
    let _w = worker(d, &url, "w0", "token", &[]);
    registered(&coord, "w0");
    let mut c = client(d, &render_args("spd:balls:2", &url, "token", "c.png", "48"));
    coord.wait_for(&["task assigned"], 60.0);
    // The client is watching (the job's log reaches it by the watch).
    c.wait_for(&["sray: job: job submitted"], 60.0);
    let t0 = Instant::now();
    sigterm(&coord);
    // "Within a few seconds" (it takes well under one when the machine is
    // not loaded; it took 67 s before).
    coord.wait(10.0);
    assert!(
        t0.elapsed() < Duration::from_secs(10),
        "stopping took {:?}",
        t0.elapsed()
    );
    let (_coord, _) = coordinator_on(d, &port(&url), &["--token-file", "token"]);
    assert!(c.wait(180.0).success(), "{}", c.log());
    assert!(c.log().contains("coordinator restarting"), "{}", c.log());
    assert!(!c.log().contains("no worker"), "{}", c.log());
    assert!(std::fs::read(d.join("c.png")).unwrap() == want);
}

/// Item 5: a worker that fails every task does not get the task back, is
/// quarantined, and the job ends well on the healthy worker.
#[test]
fn a_task_that_failed_on_a_worker_goes_elsewhere() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("token"), "s3cret\n").unwrap();
    let want = embedded(d, "spd:balls:1", "32");
    let (coord, url) = coordinator(d, &["--token-file", "token"]);
    let rt = rt();
    let (u2, tok) = (url.clone(), d.join("token"));
    rt.spawn(async move {
        let mut c = connect(&u2, &tok).await;
        let session = register(&mut c, "broken").await;
        keep_beating(&c, &session);
        loop {
            if let Some(t) = next(&mut c, &session).await {
                let _ = c
                    .fail_task(v1::FailTaskRequest {
                        task: Some(tref(&session, &t)),
                        error: "bad RAM".into(),
                        ..Default::default()
                    })
                    .await;
            }
        }
    });
    registered(&coord, "broken");
    let _w = worker(d, &url, "healthy", "token", &[]);
    registered(&coord, "healthy");
    ok(d, &render_args("spd:balls:1", &url, "token", "c.png", "32"));
    assert!(std::fs::read(d.join("c.png")).unwrap() == want);
    coord.wait_for(&["worker quarantined", "worker=broken"], 10.0);
    drop(rt);
}

/// Item 6: a worker whose heartbeat runs but whose task never returns
/// does not hang the job: the task gets a backup attempt elsewhere.
#[test]
fn a_task_that_never_returns_gets_a_backup() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("token"), "s3cret\n").unwrap();
    let want = embedded(d, "spd:balls:1", "32");
    let (coord, url) = coordinator(
        d,
        &[
            "--token-file",
            "token",
            "--deadline-min",
            "1",
            "--deadline-factor",
            "2",
        ],
    );
    let rt = rt();
    let (u2, tok) = (url.clone(), d.join("token"));
    let (got_tx, got_rx) = std::sync::mpsc::channel();
    rt.spawn(async move {
        let mut c = connect(&u2, &tok).await;
        let session = register(&mut c, "stuck").await;
        keep_beating(&c, &session);
        loop {
            if next(&mut c, &session).await.is_some() {
                let _ = got_tx.send(());
                // Holds the task forever, beating.
                std::future::pending::<()>().await;
            }
        }
    });
    registered(&coord, "stuck");
    let mut c = client(d, &render_args("spd:balls:1", &url, "token", "c.png", "32"));
    got_rx.recv_timeout(Duration::from_secs(60)).unwrap();
    let _w = worker(d, &url, "w0", "token", &[]);
    assert!(c.wait(120.0).success(), "{}", c.log());
    assert!(std::fs::read(d.join("c.png")).unwrap() == want);
    assert!(stats(d)["backup_tasks"].as_u64().unwrap() >= 1);
    drop(rt);
}

/// Item 7: a worker below the memory floor is refused at registration
/// with a message (it would have shrunk every job's grid); the others
/// plan their own grids.
#[test]
fn a_worker_below_the_memory_floor_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("token"), "s3cret\n").unwrap();
    let (coord, url) = coordinator(d, &["--token-file", "token"]);
    let mut small = worker(d, &url, "tiny", "token", &["--memory", "1MiB"]);
    assert!(!small.wait(30.0).success());
    assert!(small.log().contains("floor"), "{}", small.log());
    assert!(coord.log().contains("tiny"), "the refusal is not logged");
    // A worker at the floor is taken, beside a larger one; each plans its
    // own grid and the image is the embedded one.
    let want = embedded(d, "spd:balls:2", "32");
    let _a = worker(d, &url, "floor", "token", &["--memory", "16MiB"]);
    registered(&coord, "floor");
    let _b = worker(d, &url, "large", "token", &["--memory", "512MiB"]);
    registered(&coord, "large");
    ok(d, &render_args("spd:balls:2", &url, "token", "c.png", "32"));
    assert!(
        std::fs::read(d.join("c.png")).unwrap() == want,
        "wrong image"
    );
    drop(coord);
}

/// Item 8: finished jobs expire after their retention, the coordinator's
/// scene store and the workers' caches stay under their caps.
#[test]
fn finished_jobs_expire_and_scene_stores_are_capped() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("token"), "s3cret\n").unwrap();
    let (coord, url) = coordinator(
        d,
        &[
            "--token-file",
            "token",
            "--job-retention",
            "2",
            "--scene-store-max",
            "1KiB",
        ],
    );
    let _w = worker(d, &url, "w0", "token", &["--cache-max", "1KiB"]);
    registered(&coord, "w0");
    // The count and bytes of the scenes in a directory.
    let sdb = |dir: &Path| {
        let sizes: Vec<u64> = std::fs::read_dir(dir)
            .unwrap()
            .flatten()
            .filter(|e| e.path().extension().is_some_and(|x| x == "sdb"))
            .map(|e| e.metadata().unwrap().len())
            .collect();
        (sizes.len(), sizes.iter().sum::<u64>())
    };
    ok(d, &render_args("spd:balls:1", &url, "token", "a.png", "16"));
    let first = stats(d)["job_id"].as_str().unwrap().to_string();
    let (_, balls) = sdb(&d.join("data"));
    assert!(balls > 1024, "the test needs a scene over the cap");
    ok(d, &render_args("spd:tetra:1", &url, "token", "b.png", "16"));
    // Two scenes are over the cap: the least recently used goes once no
    // running job uses it, until the rest fits.
    let end = Instant::now() + Duration::from_secs(10);
    loop {
        let (n, bytes) = sdb(&d.join("data"));
        if n <= 1 && bytes <= 1024 {
            break;
        }
        assert!(
            Instant::now() < end,
            "the store kept scenes past its cap: {:?}\n{}",
            walk(&d.join("data")),
            coord.log()
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    let (n, bytes) = sdb(&d.join("cache-w0"));
    assert!(
        n <= 1 && bytes <= balls.max(1024),
        "the worker's cache kept scenes past its cap"
    );
    coord.wait_for(&["finished job expired", &first], 10.0);
    assert!(!d.join("data/jobs").join(&first).exists());
    let err = fails(
        d,
        &[
            "fetch",
            &format!("{first}:{}", "0".repeat(64)),
            "-o",
            "x.png",
            "--coordinator",
            &url,
            "--token-file",
            "token",
        ],
    );
    assert!(err.contains("no job"), "{err}");
}

/// Item 9: requests beyond the limits are refused with a message, and the
/// coordinator stays up for the next job.
#[test]
fn requests_beyond_the_limits_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("token"), "s3cret\n").unwrap();
    let (coord, url) = coordinator(d, &["--token-file", "token", "--max-pixels", "100000"]);
    let _w = worker(d, &url, "w0", "token", &[]);
    registered(&coord, "w0");
    let rt = rt();
    let (u2, tok) = (url.clone(), d.join("token"));
    let errs = rt.block_on(async move {
        let mut c = connect(&u2, &tok).await;
        let mut errs = Vec::new();
        let huge = v1::JobSpec {
            scene: Some(v1::SceneRef {
                hash: "0".repeat(64),
            }),
            params: Some(v1::RenderParams {
                width: 32768,
                height: 32768,
                max_depth: 5,
                samples: 1024,
                ..Default::default()
            }),
            protocol_version: sray_proto::PROTOCOL_VERSION,
            ..Default::default()
        };
        errs.push(c.submit_job(huge.clone()).await.unwrap_err());
        let mut deep = huge.clone();
        deep.params = Some(v1::RenderParams {
            width: 16,
            height: 16,
            max_depth: 200,
            samples: 1,
            ..Default::default()
        });
        errs.push(c.submit_job(deep).await.unwrap_err());
        let header = v1::SceneUpload {
            part: Some(v1::scene_upload::Part::Header(v1::SceneUploadHeader {
                size: 1 << 50,
                hash: "0".repeat(64),
            })),
        };
        errs.push(
            c.upload_scene(tokio_stream::iter(vec![header]))
                .await
                .unwrap_err(),
        );
        errs
    });
    assert!(errs[0].message().contains("--max-pixels"), "{:?}", errs[0]);
    assert!(errs[1].message().contains("--max-depth"), "{:?}", errs[1]);
    assert!(
        errs[2].message().contains("--max-scene-bytes"),
        "{:?}",
        errs[2]
    );
    let err = fails(
        d,
        &render_args("spd:balls:1", &url, "token", "big.png", "400"),
    );
    assert!(err.contains("--max-pixels"), "{err}");
    // Still serving.
    ok(
        d,
        &render_args("spd:balls:1", &url, "token", "small.png", "16"),
    );
    drop(coord);
}

/// Item 10: workers and clients hold separate tokens, a worker acts only
/// under its session secret, and only a job's submitter (holding its
/// secret) may cancel or watch it; refused calls are logged.
#[test]
fn roles_sessions_and_job_secrets_are_enforced() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("wtoken"), "worker-secret\n").unwrap();
    std::fs::write(d.join("ctoken"), "client-secret\n").unwrap();
    let want = embedded(d, "spd:balls:2", "48");
    let (coord, url) = coordinator(
        d,
        &[
            "--worker-token-file",
            "wtoken",
            "--client-token-file",
            "ctoken",
        ],
    );
    // A worker with a client's token is refused.
    let mut bad = worker(d, &url, "impostor", "ctoken", &[]);
    assert!(!bad.wait(30.0).success());
    assert!(bad.log().contains("refused"), "{}", bad.log());
    let _w = worker(d, &url, "w0", "wtoken", &[]);
    registered(&coord, "w0");
    let mut c = client(
        d,
        &render_args("spd:balls:2", &url, "ctoken", "c.png", "48"),
    );
    let line = c.wait_for(&["sray: job", "submitted"], 60.0);
    let id = line.split_whitespace().nth(2).unwrap().to_string();
    let rt = rt();
    let (u2, ct, wt) = (url.clone(), d.join("ctoken"), d.join("wtoken"));
    let codes = rt.block_on(async move {
        let mut client = connect(&u2, &ct).await;
        let mut worker = connect(&u2, &wt).await;
        let mut codes = Vec::new();
        // Cancel another client's job by its id without its secret.
        codes.push(
            client
                .cancel_job(v1::JobRef {
                    job_id: id.clone(),
                    job_secret: "0".repeat(64),
                })
                .await
                .unwrap_err()
                .code(),
        );
        codes.push(
            client
                .watch_job(v1::JobRef {
                    job_id: id.clone(),
                    job_secret: String::new(),
                })
                .await
                .err()
                .map(|s| s.code())
                .unwrap_or(tonic::Code::Ok),
        );
        // A client's token cannot ask for work; a worker's cannot cancel.
        codes.push(next_err(&mut client, "1").await);
        codes.push(
            worker
                .cancel_job(v1::JobRef {
                    job_id: id.clone(),
                    job_secret: "0".repeat(64),
                })
                .await
                .unwrap_err()
                .code(),
        );
        // A worker's token with a guessed session gets nothing.
        codes.push(next_err(&mut worker, "1").await);
        codes
    });
    use tonic::Code::*;
    assert_eq!(
        codes,
        vec![
            PermissionDenied,
            PermissionDenied,
            PermissionDenied,
            PermissionDenied,
            NotFound
        ]
    );
    assert!(c.wait(120.0).success(), "{}", c.log());
    assert!(std::fs::read(d.join("c.png")).unwrap() == want);
    assert!(coord.log().contains("refused a call"), "{}", coord.log());
}

async fn next_err(c: &mut Client, session: &str) -> tonic::Code {
    c.next_task(v1::NextTaskRequest {
        session: session.into(),
        held: vec![],
    })
    .await
    .err()
    .map(|s| s.code())
    .unwrap_or(tonic::Code::Ok)
}

/// Item 10, with TLS: a coordinator started with `--tls-client-ca` serves
/// only callers presenting a certificate signed by that CA (a caller with
/// the right token but no certificate is refused); workers and clients
/// with certificates render as usual, and `sray fetch` reuses the
/// ticket's certificate.
#[test]
fn client_certificates_are_required_where_configured() {
    use rcgen::{BasicConstraints, CertificateParams, IsCa, Issuer, KeyPair};
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("wtoken"), "worker-secret\n").unwrap();
    std::fs::write(d.join("ctoken"), "client-secret\n").unwrap();
    // One CA signs the server's certificate, another the callers'.
    let ca = |name: &str| {
        let mut p = CertificateParams::new(Vec::<String>::new()).unwrap();
        p.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
        let k = KeyPair::generate().unwrap();
        let c = p.self_signed(&k).unwrap();
        std::fs::write(d.join(format!("{name}.pem")), c.pem()).unwrap();
        Issuer::new(p, k)
    };
    fn leaf(d: &Path, issuer: &Issuer<'_, KeyPair>, names: Vec<String>, name: &str) {
        let k = KeyPair::generate().unwrap();
        let c = CertificateParams::new(names)
            .unwrap()
            .signed_by(&k, issuer)
            .unwrap();
        std::fs::write(d.join(format!("{name}.pem")), c.pem()).unwrap();
        std::fs::write(d.join(format!("{name}.key")), k.serialize_pem()).unwrap();
    }
    let server_ca = ca("ca");
    let callers_ca = ca("callers-ca");
    leaf(d, &server_ca, vec!["127.0.0.1".into()], "server");
    leaf(d, &callers_ca, vec!["worker".into()], "worker");
    leaf(d, &callers_ca, vec!["client".into()], "client");
    // A certificate from a CA the coordinator does not trust for callers.
    leaf(d, &server_ca, vec!["stranger".into()], "stranger");
    let want = embedded(d, "spd:balls:1", "32");
    let (coord, url) = coordinator(
        d,
        &[
            "--tls-cert",
            "server.pem",
            "--tls-key",
            "server.key",
            "--tls-client-ca",
            "callers-ca.pem",
            "--worker-token-file",
            "wtoken",
            "--client-token-file",
            "ctoken",
        ],
    );
    assert!(url.starts_with("https://"), "{url}");
    let tls = |cert: &str| -> Vec<String> {
        let mut v = vec!["--tls-ca".to_string(), "ca.pem".to_string()];
        if !cert.is_empty() {
            v.extend([
                "--tls-cert".to_string(),
                format!("{cert}.pem"),
                "--tls-key".to_string(),
                format!("{cert}.key"),
            ]);
        }
        v
    };
    let w_args = tls("worker");
    let w_args: Vec<&str> = w_args.iter().map(String::as_str).collect();
    let _w = worker(d, &url, "w0", "wtoken", &w_args);
    registered(&coord, "w0");
    // Right token, no certificate or an untrusted one: no call gets through.
    let rt = rt();
    let (u2, ca_pem, ct) = (url.clone(), d.join("ca.pem"), d.join("ctoken"));
    let d2 = d.to_path_buf();
    let refused = rt.block_on(async move {
        let mut out = Vec::new();
        for identity in [
            None,
            Some((d2.join("stranger.pem"), d2.join("stranger.key"))),
            Some((d2.join("client.pem"), d2.join("client.key"))),
        ] {
            let t = Target {
                url: u2.clone(),
                token: Some(Token::from_file(&ct).unwrap()),
                ca: Some(ca_pem.clone()),
                identity,
            };
            // The coordinator's own answer (the job does not exist), or
            // a refusal before the call reached it.
            let r = tokio::time::timeout(Duration::from_secs(30), async {
                let mut c = t.connect().await.map_err(|_| tonic::Code::Unavailable)?;
                c.watch_job(v1::JobRef {
                    job_id: "0".repeat(32),
                    job_secret: "0".repeat(64),
                })
                .await
                .map(|_| ())
                .map_err(|s| s.code())
            })
            .await;
            out.push(match r {
                Ok(Err(code)) => code,
                Ok(Ok(())) => tonic::Code::Ok,
                Err(_) => tonic::Code::DeadlineExceeded,
            });
        }
        out
    });
    // Refused at the handshake: the call never reached the service.
    for code in &refused[..2] {
        assert!(
            !matches!(
                code,
                tonic::Code::Ok | tonic::Code::NotFound | tonic::Code::PermissionDenied
            ),
            "a caller without a trusted certificate got through: {refused:?}"
        );
    }
    assert_eq!(refused[2], tonic::Code::NotFound, "{refused:?}");
    // With its certificate the client renders, and fetches again.
    let c_args = tls("client");
    let mut args = render_args("spd:balls:1", &url, "ctoken", "c.png", "32");
    args.extend(c_args.iter().map(String::as_str));
    let mut c = client(d, &args);
    assert!(c.wait(120.0).success(), "{}", c.log());
    assert!(
        std::fs::read(d.join("c.png")).unwrap() == want,
        "wrong image"
    );
    let id = stats(d)["job_id"].as_str().unwrap().to_string();
    // From another directory: the ticket names the files absolutely.
    let elsewhere = d.join("elsewhere");
    std::fs::create_dir(&elsewhere).unwrap();
    let o = common::sray()
        .current_dir(&elsewhere)
        .args(["fetch", &id, "-o", "again.png", "--token-file", "../ctoken"])
        .env("SRAY_JOBS_DIR", d.join("tickets"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(std::fs::read(elsewhere.join("again.png")).unwrap() == want);
    drop(coord);
}
