//! The cluster with real processes on loopback: a coordinator, workers and
//! clients started as `sray coordinator`, `sray worker` and `sray render`.

use crate::common;

use common::{Proc, cluster, fails, json, ok, run};
use std::path::Path;

const COUNTS: [&str; 7] = [
    "eye_rays",
    "eye_hit_rays",
    "reflect_rays",
    "refract_rays",
    "shadow_rays",
    "intersection_tests",
    "intersection_tests_by_kind",
];

fn coordinator(dir: &Path, extra: &[&str]) -> (Proc, String) {
    cluster::coordinator(dir, extra)
}

fn worker(dir: &Path, url: &str, name: &str, token: &str) -> Proc {
    cluster::worker(dir, url, name, Some(token), &[])
}

/// The embedded breadth-first render of a scene: image bytes and stats.
fn embedded(dir: &Path, scene: &str, size: &str) -> (Vec<u8>, serde_json::Value) {
    ok(
        dir,
        &[
            "render", scene, "-o", "emb.png", "--mode", "bf", "--width", size, "--height", size,
            "--stats", "emb.json",
        ],
    );
    let df = {
        ok(
            dir,
            &[
                "render", scene, "-o", "df.png", "--mode", "df", "--width", size, "--height", size,
            ],
        );
        std::fs::read(dir.join("df.png")).unwrap()
    };
    let img = std::fs::read(dir.join("emb.png")).unwrap();
    assert!(img == df, "{scene}: embedded bf and df differ");
    let stats = json(&std::fs::read_to_string(dir.join("emb.json")).unwrap());
    (img, stats)
}

fn same(what: &str, img: &[u8], stats: &serde_json::Value, want: &(Vec<u8>, serde_json::Value)) {
    assert!(
        img == want.0.as_slice(),
        "{what}: image differs from the embedded render"
    );
    for k in COUNTS {
        assert_eq!(stats[k], want.1[k], "{what}: {k}");
    }
}

/// A client's render on the coordinator at `url`, in small shards (512
/// rays) so that even small images make many tasks.
fn render_args<'a>(
    scene: &'a str,
    url: &'a str,
    token: &'a str,
    out: &'a str,
    size: &'a str,
) -> Vec<&'a str> {
    cluster::render_args(scene, url, token, out, size, "512")
}

fn cluster_stats(dir: &Path) -> serde_json::Value {
    json(&std::fs::read_to_string(dir.join("cluster.json")).unwrap())
}

/// How the coordinator's log names the worker called `name` (by name:
/// its session secret is never logged), once it has registered.
fn worker_id(coord: &Proc, name: &str) -> String {
    coord.wait_for(&["worker registered", &format!("worker={name} ")], 30.0);
    name.to_string()
}

#[test]
fn a_coordinator_and_three_workers() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("token"), "cluster-secret\n").unwrap();
    std::fs::write(d.join("wrong"), "not-the-secret\n").unwrap();
    let (coord, url) = coordinator(d, &["--token-file", "token"]);
    let mut workers: Vec<Proc> = ["w0", "w1", "w2"]
        .iter()
        .map(|n| worker(d, &url, n, "token"))
        .collect();
    let mut ids: Vec<String> = ["w0", "w1", "w2"]
        .iter()
        .map(|n| worker_id(&coord, n))
        .collect();

    // 1. The same image and counts as the embedded render.
    let want = embedded(d, "spd:balls:3", "96");
    ok(
        d,
        &render_args("spd:balls:3", &url, "token", "c1.png", "96"),
    );
    let s = cluster_stats(d);
    same(
        "three workers",
        &std::fs::read(d.join("c1.png")).unwrap(),
        &s,
        &want,
    );
    assert_eq!(s["mode"], "cluster");
    assert_eq!(s["workers"], 3);
    assert!(s["tasks"].as_u64().unwrap() > 6, "{s}");
    assert!(s["bytes_per_ray"].as_f64().unwrap() > 0.0);

    // 2. A client with the wrong token, or none, is refused; no output.
    let err = fails(
        d,
        &render_args("spd:balls:3", &url, "wrong", "bad.png", "32"),
    );
    assert!(err.contains("token"), "{err}");
    let mut no_token = render_args("spd:balls:3", &url, "token", "bad.png", "32");
    no_token.drain(6..8);
    let err = fails(d, &no_token);
    assert!(err.contains("token"), "{err}");
    assert!(!d.join("bad.png").exists());

    // 3. So is a worker with the wrong token: it stops with a message.
    let mut bad = worker(d, &url, "intruder", "wrong");
    assert!(!bad.wait(30.0).success());
    assert!(bad.log().contains("refused"), "{}", bad.log());
    drop(bad);

    // 4. A worker killed while it holds a task: the task goes to the
    //    others and the image is still the embedded one. The kill races
    //    with the worker finishing its task (on a loaded machine it may
    //    win), so the scenario repeats with a fresh worker until a task
    //    was taken back; every attempt must give the embedded image.
    let want2 = embedded(d, "spd:gears:2", "128");
    let victim = 1;
    let mut requeued = 0;
    for attempt in 0..5 {
        let mark = coord.mark();
        let mut client = Proc::start(
            d,
            &render_args("spd:gears:2", &url, "token", "c2.png", "128"),
            &[],
        );
        // Its first task of the job: the worker builds its grids before
        // it can answer, so it is usually killed with the task in hand.
        coord.wait_for_after(
            mark,
            &["task assigned", &format!("worker={}", ids[victim])],
            60.0,
        );
        workers[victim].child.kill().unwrap();
        let status = client.wait(300.0);
        assert!(status.success(), "{}", client.log());
        let s = cluster_stats(d);
        same(
            &format!("a worker killed (attempt {attempt})"),
            &std::fs::read(d.join("c2.png")).unwrap(),
            &s,
            &want2,
        );
        requeued = s["tasks_requeued"].as_u64().unwrap();
        if requeued >= 1 {
            break;
        }
        // The worker finished first: bring up another and try again.
        let name = format!("w1-{attempt}");
        workers[victim] = worker(d, &url, &name, "token");
        ids[victim] = worker_id(&coord, &name);
    }
    assert!(
        requeued >= 1,
        "no task was ever taken back from a killed worker"
    );

    // 5. A corrupted chunk in a worker's cached scene is found and fetched
    //    again (only w0 left, so w0 runs the job).
    workers[2].child.kill().unwrap();
    let cache = d.join("cache-w0");
    let cached = std::fs::read_dir(&cache)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| {
            p.extension().is_some_and(|e| e == "sdb")
                && std::fs::read(p).unwrap().len() < 1 << 20
                && ok(d, &["info", p.to_str().unwrap(), "--json"]).contains("\"objects\": 821")
        })
        .expect("w0 cached balls:3");
    let mut bytes = std::fs::read(&cached).unwrap();
    let good = bytes.clone();
    let mid = bytes.len() / 2;
    bytes[mid] ^= 0x5a;
    std::fs::write(&cached, &bytes).unwrap();
    ok(
        d,
        &render_args("spd:balls:3", &url, "token", "c3.png", "96"),
    );
    let s = cluster_stats(d);
    same(
        "after repair",
        &std::fs::read(d.join("c3.png")).unwrap(),
        &s,
        &want,
    );
    assert_eq!(s["scene_chunks_served"], 1, "{s}");
    assert!(
        std::fs::read(&cached).unwrap() == good,
        "the cached scene was not repaired"
    );
    assert!(
        workers[0].log().contains("fetching those chunks again"),
        "{}",
        workers[0].log()
    );
    drop(coord);
}

#[test]
fn records_at_workers_a_lost_worker_costs_only_its_records() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("token"), "cluster-secret\n").unwrap();
    let (coord, url) = coordinator(d, &["--token-file", "token", "--records-at-workers"]);
    let names = ["k0", "k1", "k2"];
    let mut workers: Vec<Proc> = names.iter().map(|n| worker(d, &url, n, "token")).collect();
    let ids: Vec<String> = names.iter().map(|n| worker_id(&coord, n)).collect();
    let want = embedded(d, "spd:gears:2", "128");

    // 1. Results and spawned rays stay at the workers: the embedded
    //    image, with only colour (and counts) on the wire.
    ok(
        d,
        &render_args("spd:gears:2", &url, "token", "r1.png", "128"),
    );
    let s = cluster_stats(d);
    same(
        "records at the workers",
        &std::fs::read(d.join("r1.png")).unwrap(),
        &s,
        &want,
    );
    assert_eq!(s["job_restarts"], 0, "{s}");
    assert_eq!(s["recomputations"], 0, "{s}");
    let bpr = s["bytes_per_ray"].as_f64().unwrap();
    assert!(
        bpr > 0.0 && bpr < 16.0,
        "{bpr} bytes per ray: records were sent"
    );
    let full = s["tasks"].as_u64().unwrap();

    // 2. A worker killed once it has finished a task of round 2: it holds
    //    records of rounds 2 and 3 that nobody else has. Only the shards
    //    whose records it held are recomputed (from the rounds that led
    //    to them, on another worker); the job does not start again, and
    //    still gives the embedded image and counts.
    let mark = coord.mark();
    let mut client = Proc::start(
        d,
        &render_args("spd:gears:2", &url, "token", "r2.png", "128"),
        &[],
    );
    coord.wait_for_after(
        mark,
        &["task completed", &format!("worker={}", ids[1]), "round=2 "],
        60.0,
    );
    workers[1].child.kill().unwrap();
    let status = client.wait(300.0);
    assert!(status.success(), "{}", client.log());
    let s = cluster_stats(d);
    same(
        "a worker lost with records",
        &std::fs::read(d.join("r2.png")).unwrap(),
        &s,
        &want,
    );
    assert_eq!(s["job_restarts"], 0, "{s}");
    assert!(s["recomputations"].as_u64().unwrap() >= 1, "{s}");
    // What was redone is the lost worker's part, not the whole job.
    let redone = s["recomputed_tasks"].as_u64().unwrap();
    assert!(
        redone >= 1 && redone < full,
        "{redone} of {full} tasks redone: {s}"
    );
    assert!(
        coord.log().contains("task input lost"),
        "the loss was not logged"
    );
    assert!(
        s["log"].to_string().contains("recomputed on worker"),
        "the recomputation is not in the job's log: {s}"
    );
    drop(coord);
}

#[test]
fn local_workers_render_the_embedded_image_and_stop() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let want = embedded(d, "spd:teapot:4", "64");
    let tmp = d.join("tmp");
    std::fs::create_dir(&tmp).unwrap();
    let o = run(
        d,
        &[
            "render",
            "spd:teapot:4",
            "-o",
            "local.png",
            "--local-workers",
            "2",
            "--width",
            "64",
            "--height",
            "64",
            "--shard-rays",
            "300",
            "--stats",
            "cluster.json",
            "--tmp-dir",
            tmp.to_str().unwrap(),
        ],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s = cluster_stats(d);
    same(
        "local workers",
        &std::fs::read(d.join("local.png")).unwrap(),
        &s,
        &want,
    );
    assert_eq!(s["workers"], 2);
    // Nothing is left running or lying around.
    let tmp_s = tmp.to_str().unwrap().to_string();
    let alive: Vec<String> = std::fs::read_dir("/proc")
        .unwrap()
        .filter_map(|e| std::fs::read(e.unwrap().path().join("cmdline")).ok())
        .map(|c| String::from_utf8_lossy(&c).replace('\0', " "))
        .filter(|c| c.contains(&tmp_s) && c.contains("worker"))
        .collect();
    assert!(alive.is_empty(), "workers still running: {alive:?}");
    assert_eq!(
        std::fs::read_dir(&tmp).unwrap().count(),
        0,
        "temporary files left"
    );
}

/// Local workers share one cache, where the scene is a link to the
/// user's own database: no worker touches the user's file (its
/// modification time stays), and none takes another's use of the scene
/// for a changed database (which failed tasks and had them run again).
#[test]
fn local_workers_leave_the_users_database_alone() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(d, &["gen", "balls", "-s", "2", "-o", "b.sdb", "--quiet"]);
    // An old modification time, so that a touch could not go unseen
    // within the file system's time resolution.
    let old = std::time::SystemTime::now() - std::time::Duration::from_secs(3600);
    std::fs::File::options()
        .write(true)
        .open(d.join("b.sdb"))
        .unwrap()
        .set_modified(old)
        .unwrap();
    for _ in 0..2 {
        ok(
            d,
            &[
                "render",
                "b.sdb",
                "-o",
                "b.png",
                "--local-workers",
                "2",
                "--width",
                "48",
                "--height",
                "48",
                "--shard-rays",
                "256",
                "--stats",
                "cluster.json",
            ],
        );
        let s = cluster_stats(d);
        assert_eq!(s["tasks_requeued"], 0, "{s}");
        let now = std::fs::metadata(d.join("b.sdb"))
            .unwrap()
            .modified()
            .unwrap();
        assert_eq!(now, old, "the user's database was touched");
    }
}

#[test]
fn a_job_without_workers_fails_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (_coord, url) = coordinator(d, &["--worker-wait", "1"]);
    let err = fails(
        d,
        &[
            "render",
            "spd:balls:1",
            "-o",
            "none.png",
            "--coordinator",
            &url,
            "--width",
            "16",
            "--height",
            "16",
        ],
    );
    assert!(err.contains("no worker"), "{err}");
    assert!(!d.join("none.png").exists());
    // An unreachable coordinator is a clear error too.
    let err = fails(
        d,
        &[
            "render",
            "spd:balls:1",
            "-o",
            "none.png",
            "--coordinator",
            "http://127.0.0.1:9",
        ],
    );
    assert!(err.contains("cannot reach the coordinator"), "{err}");
}

/// TLS: a CA, a certificate for 127.0.0.1 signed by it; the coordinator
/// serves TLS, the worker and the client trust the CA.
#[test]
fn tls_end_to_end() {
    use rcgen::{BasicConstraints, CertificateParams, IsCa, Issuer, KeyPair};
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mut ca_params = CertificateParams::new(Vec::<String>::new()).unwrap();
    ca_params.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
    let ca_key = KeyPair::generate().unwrap();
    let ca = ca_params.self_signed(&ca_key).unwrap();
    let leaf_key = KeyPair::generate().unwrap();
    let leaf = CertificateParams::new(vec!["127.0.0.1".to_string(), "localhost".to_string()])
        .unwrap()
        .signed_by(&leaf_key, &Issuer::new(ca_params, ca_key))
        .unwrap();
    std::fs::write(d.join("ca.pem"), ca.pem()).unwrap();
    std::fs::write(d.join("cert.pem"), leaf.pem()).unwrap();
    std::fs::write(d.join("key.pem"), leaf_key.serialize_pem()).unwrap();
    std::fs::write(d.join("token"), "tls-secret").unwrap();
    let (_coord, url) = coordinator(
        d,
        &[
            "--tls-cert",
            "cert.pem",
            "--tls-key",
            "key.pem",
            "--token-file",
            "token",
        ],
    );
    assert!(url.starts_with("https://"), "{url}");
    let _w = Proc::start(
        d,
        &[
            "worker",
            "--coordinator",
            &url,
            "--tls-ca",
            "ca.pem",
            "--token-file",
            "token",
            "--cache-dir",
            "cache",
            "--threads",
            "1",
            "--memory",
            "64MiB",
        ],
        &[],
    );
    let want = embedded(d, "spd:tetra:2", "48");
    let mut args = render_args("spd:tetra:2", &url, "token", "tls.png", "48");
    args.extend_from_slice(&["--tls-ca", "ca.pem"]);
    ok(d, &args);
    same(
        "tls",
        &std::fs::read(d.join("tls.png")).unwrap(),
        &cluster_stats(d),
        &want,
    );
    // Without the CA the client cannot connect.
    let err = fails(
        d,
        &render_args("spd:tetra:2", &url, "token", "no.png", "48"),
    );
    assert!(err.contains("--tls-ca"), "{err}");
}

/// Worker count and shard size change nothing: the seven scenes of
/// tests/fixtures/spd, embedded against one worker with one shard per depth and
/// against three workers with the smallest shards (256 rays) (so that shards complete in any
/// order and every merge has many inputs).
#[test]
fn seven_scenes_any_worker_count_and_shard_size() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("token"), "cluster-secret\n").unwrap();
    let (coord, url) = coordinator(d, &["--token-file", "token"]);
    let mut workers = vec![worker(d, &url, "w0", "token")];
    worker_id(&coord, "w0");
    // Coincident surfaces too: the first object wins on the cluster as in
    // the embedded tracers.
    std::fs::write(
        d.join("coincident.nff"),
        "b 0 0 0\nv\nfrom 0 0 5\nat 0 0 0\nup 0 1 0\nangle 60\nhither 0.01\n\
         resolution 8 8\nl 0 0 10\nf 1 0 0 1 0 0 0 1\np 4\n-2 -2 0\n0 -2 0\n0 2 0\n-2 2 0\n\
         s 1 0 0 0.9\nf 0 1 0 1 0 0 0 1\np 4\n-2 -2 0\n0 -2 0\n0 2 0\n-2 2 0\ns 1 0 0 0.9\n",
    )
    .unwrap();
    let scenes: Vec<(String, (Vec<u8>, serde_json::Value))> = [
        "balls4",
        "gears4",
        "mount6",
        "rings7",
        "tetra6",
        "tree11",
        "teapot12",
        "coincident",
    ]
    .iter()
    .map(|n| {
        let nff = match *n {
            "coincident" => d.join("coincident.nff"),
            _ => common::spd_fixtures().join(format!("{n}.nff")),
        };
        let nff = nff.to_str().unwrap().to_string();
        let want = embedded(d, &nff, "40");
        (nff, want)
    })
    .collect();
    for (workers_now, shard) in [(1, "100000"), (3, "256")] {
        while workers.len() < workers_now {
            let name = format!("w{}", workers.len());
            workers.push(worker(d, &url, &name, "token"));
            worker_id(&coord, &name);
        }
        for (nff, want) in &scenes {
            let mut args = render_args(nff, &url, "token", "c.png", "40");
            let at = args.iter().position(|a| *a == "--shard-rays").unwrap();
            args[at + 1] = shard;
            ok(d, &args);
            let s = cluster_stats(d);
            same(
                &format!("{nff}, {workers_now} workers, shards of {shard} rays"),
                &std::fs::read(d.join("c.png")).unwrap(),
                &s,
                want,
            );
            assert_eq!(s["workers"], workers_now);
        }
    }
}

/// A dense model in a sparse world (thousands of small triangles in a unit
/// box on a wide floor of spheres): the coordinator and the workers plan
/// the same grids from the database's density summary, the model's among
/// them, and the image and counts are the embedded render's.
#[test]
fn local_workers_plan_a_dense_models_grid_as_the_embedded_render_does() {
    use std::fmt::Write;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mut s = String::from(
        "v\nfrom 1.6 1.2 2.0\nat 0 0.4 0\nup 0 1 0\nangle 35\nhither 0.001\nresolution 40 40\n\
         b 0.1 0.1 0.2\nl 3 8 4\nf 0.6 0.6 0.6 1 0 0 0 1\np 4\n-50 0 -50\n-50 0 50\n50 0 50\n\
         50 0 -50\nf 0.9 0.3 0.2 0.6 0.4 20 0 1\n",
    );
    let mut x: u64 = 11;
    let mut next = move || {
        x = x
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (x >> 11) as f64 / (1u64 << 53) as f64
    };
    for _ in 0..3000 {
        let (a, b) = (100.0 * next() - 50.0, 100.0 * next() - 50.0);
        writeln!(s, "s {a:.4} 0.2 {b:.4} 0.2").unwrap();
    }
    for _ in 0..6000 {
        let c = [next() - 0.5, next(), next() - 0.5];
        s.push_str("p 3\n");
        for _ in 0..3 {
            let v: Vec<f64> = c.iter().map(|c| c + 0.12 * next() - 0.06).collect();
            writeln!(s, "{} {} {}", v[0], v[1], v[2]).unwrap();
        }
    }
    std::fs::write(d.join("crowd.nff"), s).unwrap();
    ok(d, &["convert", "crowd.nff", "-o", "crowd.sdb", "--quiet"]);
    let want = embedded(d, "crowd.sdb", "40");
    let model = |stats: &serde_json::Value| {
        stats["grids"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|g| g["objects"].as_u64().unwrap() > 5500)
            .count()
    };
    assert_eq!(model(&want.1), 1, "embedded grids: {}", want.1["grids"]);
    let o = run(
        d,
        &[
            "render",
            "crowd.sdb",
            "-o",
            "local.png",
            "--local-workers",
            "2",
            "--width",
            "40",
            "--height",
            "40",
            "--shard-rays",
            "400",
            "--stats",
            "cluster.json",
        ],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s = cluster_stats(d);
    same(
        "local workers",
        &std::fs::read(d.join("local.png")).unwrap(),
        &s,
        &want,
    );
    assert_eq!(s["grids"], want.1["grids"]);
}
