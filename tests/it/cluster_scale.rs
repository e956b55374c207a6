//! A cluster beyond a few workers: the scene read from storage the
//! workers share instead of served by the coordinator once per worker,
//! and sixteen worker processes of which two are killed mid-round.
//! (The coordinator under 100 and 1,000 workers is `sray bench load`, a
//! benchmark, not a test.)

use crate::common;

use common::cluster::{self, coordinator};
use common::{Proc, json, ok};
use std::path::Path;

fn worker(dir: &Path, url: &str, name: &str, extra: &[&str]) -> Proc {
    cluster::worker(dir, url, name, Some("token"), extra)
}

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

fn stats(dir: &Path) -> serde_json::Value {
    json(&std::fs::read_to_string(dir.join("cluster.json")).unwrap())
}

/// The one scene the coordinator holds: its path in the data directory.
fn stored_scene(dir: &Path) -> std::path::PathBuf {
    std::fs::read_dir(dir.join("data"))
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .find(|p| p.extension().is_some_and(|e| e == "sdb"))
        .expect("the coordinator holds no scene")
}

/// Workers given the coordinator's data directory as shared storage
/// (`--scene-dir`, as a mount would be) read the scene from there: the
/// coordinator serves none of its bytes. A shared copy that is damaged is
/// caught by the chunk hashes, and only then does the coordinator serve
/// the scene.
#[test]
fn workers_read_the_scene_from_shared_storage_checked_by_hash() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("token"), "s3cret\n").unwrap();
    let want = embedded(d, "spd:balls:3", "48");
    let (coord, url) = coordinator(d, &["--token-file", "token"]);
    let ws: Vec<Proc> = ["w0", "w1", "w2"]
        .iter()
        .map(|n| worker(d, &url, n, &["--scene-dir", "data"]))
        .collect();
    for n in ["w0", "w1", "w2"] {
        cluster::registered(&coord, n);
    }
    let args = cluster::render_args("spd:balls:3", &url, "token", "a.png", "48", "2048");
    ok(d, &args);
    assert!(std::fs::read(d.join("a.png")).unwrap() == want);
    let s = stats(d);
    assert_eq!(s["scene_bytes_served"], 0, "{s}");
    assert!(s["workers"].as_u64().unwrap() >= 2, "{s}");
    for w in &ws {
        if w.log().contains("scene fetched") {
            assert!(w.log().contains("from_coordinator=0"), "{}", w.log());
        }
    }
    drop(ws);

    // A damaged shared copy: its chunk fails its hash and comes from the
    // coordinator instead.
    let scene = stored_scene(d);
    let size = std::fs::metadata(&scene).unwrap().len();
    std::fs::create_dir(d.join("shared")).unwrap();
    let mut bytes = std::fs::read(&scene).unwrap();
    let mid = bytes.len() / 2;
    bytes[mid] ^= 0xff;
    std::fs::write(d.join("shared").join(scene.file_name().unwrap()), bytes).unwrap();
    let w3 = worker(d, &url, "w3", &["--scene-dir", "shared"]);
    cluster::registered(&coord, "w3");
    ok(d, &args);
    assert!(std::fs::read(d.join("a.png")).unwrap() == want);
    let s = stats(d);
    let served = s["scene_bytes_served"].as_u64().unwrap();
    assert!(served > 0 && served <= size, "{served} of {size}: {s}");
    assert!(w3.log().contains("from_shared=0"), "{}", w3.log());
}

/// Sixteen worker processes (one thread, 64 MiB each) reading the scene
/// from shared storage; two are killed while a round runs. The job ends
/// with the embedded image, never starts again from its eye rays (their
/// tasks go to the others), and the coordinator served no scene bytes.
#[test]
fn sixteen_workers_two_killed_mid_round() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("token"), "s3cret\n").unwrap();
    let want = embedded(d, "spd:balls:3", "96");
    let (coord, url) = coordinator(d, &["--token-file", "token"]);
    let names: Vec<String> = (0..16).map(|i| format!("w{i}")).collect();
    let mut ws: Vec<Proc> = names
        .iter()
        .map(|n| worker(d, &url, n, &["--scene-dir", "data"]))
        .collect();
    for n in &names {
        cluster::registered(&coord, n);
    }
    let args = cluster::render_args("spd:balls:3", &url, "token", "c.png", "96", "1024");
    let tickets = d.join("tickets");
    let mut mark = coord.mark();
    let mut c = Proc::start(d, &args, &[("SRAY_JOBS_DIR", tickets.to_str().unwrap())]);
    // Kill two workers, each as soon as it is given a task of round 2.
    let mut killed = Vec::new();
    while killed.len() < 2 {
        let line = coord.wait_for_after(mark, &["task assigned", "round=2 "], 120.0);
        mark = coord.mark();
        let victim = (0..16)
            .find(|&i| !killed.contains(&i) && line.contains(&format!("worker={} ", names[i])));
        if let Some(i) = victim {
            ws[i].child.kill().unwrap();
            killed.push(i);
        }
    }
    assert!(!killed.is_empty(), "no worker was killed");
    assert!(c.wait(300.0).success(), "{}", c.log());
    assert!(std::fs::read(d.join("c.png")).unwrap() == want);
    let s = stats(d);
    assert_eq!(s["job_restarts"], 0, "{s}");
    assert_eq!(s["scene_bytes_served"], 0, "{s}");
    assert!(s["tasks_requeued"].as_u64().unwrap() >= 1, "{s}");
}
