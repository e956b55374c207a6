//! The cluster's wire (issue 17, "a cheap wire"): compact, exact records,
//! nothing sent twice to a worker that holds it, and workers that keep
//! their grids between the tasks of a job.

use crate::common;

use common::{cluster, json, ok, run};
use std::path::Path;

/// The embedded breadth-first image of a scene.
fn embedded(dir: &Path, scene: &str, size: &str, out: &str) -> Vec<u8> {
    ok(
        dir,
        &[
            "render", scene, "-o", out, "--mode", "bf", "--width", size, "--height", size,
        ],
    );
    std::fs::read(dir.join(out)).unwrap()
}

fn stats(dir: &Path, file: &str) -> serde_json::Value {
    json(&std::fs::read_to_string(dir.join(file)).unwrap())
}

/// Renders `scene` at `size`x`size` on `workers` local workers, checks the
/// image equals `want` (the embedded one) bit for bit, and returns the
/// render's statistics.
fn local_render(
    dir: &Path,
    scene: &str,
    size: &str,
    workers: &str,
    shard_rays: &str,
    extra: &[&str],
    want: &[u8],
) -> serde_json::Value {
    let mut args = vec![
        "render",
        scene,
        "-o",
        "local.png",
        "--local-workers",
        workers,
        "--width",
        size,
        "--height",
        size,
        "--shard-rays",
        shard_rays,
        "--stats",
        "cluster.json",
    ];
    args.extend_from_slice(extra);
    let o = run(dir, &args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(
        std::fs::read(dir.join("local.png")).unwrap() == want,
        "the cluster's image differs from the embedded one"
    );
    stats(dir, "cluster.json")
}

/// One local worker: the image is the embedded one, bit for bit, and at
/// most 64 bytes cross the wire per ray traced (the goal; 277 before).
/// The worker builds its grids once for the job's many tasks.
#[test]
fn at_most_64_bytes_per_ray_and_one_grid_build() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let want = embedded(d, "spd:balls:2", "64", "emb.png");
    let s = local_render(d, "spd:balls:2", "64", "1", "1024", &[], &want);
    let bpr = s["bytes_per_ray"].as_f64().unwrap();
    eprintln!(
        "bytes per ray {bpr:.1}: {} to workers, {} from workers",
        s["bytes_to_workers"], s["bytes_from_workers"]
    );
    assert!(bpr > 0.0 && bpr <= 64.0, "{bpr} bytes per ray: {s}");
    let tasks = s["tasks"].as_u64().unwrap();
    assert!(tasks >= 10, "{s}");
    assert_eq!(s["grid_builds"], 1, "{s}");
}

/// Most of tetra's eye rays miss: their background colour goes to the
/// coordinator as runs (one record for a row of misses), not one 32-byte
/// contribution per pixel corner, which took 26 bytes per ray here, and
/// the image is the embedded one bit for bit.
#[test]
fn rows_of_misses_travel_as_runs() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let want = embedded(d, "spd:tetra:3", "64", "emb.png");
    let s = local_render(d, "spd:tetra:3", "64", "1", "65536", &[], &want);
    let (eye, hits) = (
        s["eye_rays"].as_u64().unwrap(),
        s["eye_hit_rays"].as_u64().unwrap(),
    );
    assert!(eye - hits > eye / 2, "most eye rays miss: {s}");
    let bpr = s["bytes_per_ray"].as_f64().unwrap();
    eprintln!("tetra3: {bpr:.1} bytes per ray");
    assert!(bpr < 12.0, "{bpr} bytes per ray: {s}");
}

/// balls2 at 64x64 on a default coordinator (every record sent to it)
/// with one worker started with `worker_args`: checks the image equals
/// the embedded one and returns the bytes per ray on the wire and the
/// render's statistics.
fn one_worker_bytes_per_ray(worker_args: &[&str]) -> (f64, serde_json::Value) {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("token"), "wire-secret\n").unwrap();
    let want = embedded(d, "spd:balls:2", "64", "emb.png");
    let (coord, url) = cluster::coordinator(d, &["--token-file", "token"]);
    let _w = cluster::worker(d, &url, "w0", Some("token"), worker_args);
    coord.wait_for(&["worker registered", "worker=w0 "], 30.0);
    ok(
        d,
        &cluster::render_args("spd:balls:2", &url, "token", "c.png", "64", "1024"),
    );
    assert!(std::fs::read(d.join("c.png")).unwrap() == want);
    let s = stats(d, "cluster.json");
    (s["bytes_per_ray"].as_f64().unwrap(), s)
}

/// The same goal where every record travels: a coordinator that keeps
/// no records at the workers (the default for a cluster) and one worker.
/// The records are compact on the wire, and a worker that holds a task's
/// input is sent its name, not the records.
#[test]
fn records_sent_to_the_coordinator_stay_under_64_bytes_per_ray() {
    let (bpr, s) = one_worker_bytes_per_ray(&[]);
    eprintln!("every record sent: {bpr:.1} bytes per ray");
    // More than records at the workers send (colour only, about 2).
    assert!(bpr > 8.0 && bpr <= 64.0, "{bpr} bytes per ray: {s}");
}

/// A worker on the coordinator's machine may send its records raw
/// (`--raw-records`, as `--local-workers` starts them): rays, results and
/// contributions all arrive as they are, and the image is the same. Raw
/// records are the bigger ones on the wire (those compressed stay under
/// 64 bytes per ray, above), which shows that they were sent raw.
#[test]
fn raw_records_from_a_worker_give_the_same_image() {
    let (bpr, s) = one_worker_bytes_per_ray(&["--raw-records"]);
    eprintln!("raw records: {bpr:.1} bytes per ray");
    assert!(bpr > 64.0, "{bpr} bytes per ray: {s}");
}

/// A worker keeps each shard's results in memory with the surfaces it
/// found with them, so shading them makes no pass over the objects. When
/// its memory cannot hold them they go to a file without surfaces and the
/// shading joins them with the objects (the paper's Pseudocode 4); the
/// coordinator's records go to files too. Either way the image is the
/// embedded one, bit for bit.
#[test]
fn kept_results_shade_without_a_pass_and_spilled_ones_by_the_join() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let want = embedded(d, "spd:teapot:3", "64", "emb.png");
    let s = local_render(d, "spd:teapot:3", "64", "1", "1024", &[], &want);
    assert_eq!(s["shading_scans"], 0, "{s}");
    // 2 MiB: the coordinator may hold 256 KiB of records and the worker
    // 448 KiB, where one round's results with their surfaces (over 4000
    // rays, 88 bytes each) do not fit beside its rays.
    let s = local_render(
        d,
        "spd:teapot:3",
        "64",
        "1",
        "4096",
        &["--memory", "2MiB"],
        &want,
    );
    eprintln!("shading scans with 2 MiB: {}", s["shading_scans"]);
    assert!(s["shading_scans"].as_u64().unwrap() > 0, "{s}");
    // Two workers in 1 MiB: results received from the coordinator (a
    // shard intersected by the other worker, or records dropped to make
    // room) are too many to widen in memory and are read from a file.
    let want = embedded(d, "spd:balls:2", "128", "emb2.png");
    let s = local_render(
        d,
        "spd:balls:2",
        "128",
        "2",
        "4096",
        &["--memory", "1MiB"],
        &want,
    );
    assert!(s["shading_scans"].as_u64().unwrap() > 0, "{s}");
}

/// Two local workers: still the embedded image; the traffic stays small
/// (their records stay with them; only colour and counts travel).
#[test]
fn two_workers_same_image_small_traffic() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let want = embedded(d, "spd:teapot:3", "48", "emb.png");
    let s = local_render(d, "spd:teapot:3", "48", "2", "300", &[], &want);
    let bpr = s["bytes_per_ray"].as_f64().unwrap();
    eprintln!("two workers: {bpr:.1} bytes per ray");
    assert!(bpr > 0.0 && bpr <= 128.0, "{bpr} bytes per ray: {s}");
}

/// Two concurrent jobs with different settings on one worker: the worker
/// keeps both setups' grids, so each job builds them once, not once per
/// switch between the jobs.
#[test]
fn concurrent_jobs_keep_their_grids() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // A generous timeout: a worker slowed by a loaded machine must not be
    // declared lost, which would requeue a task and rebuild grids.
    let (coord, url) = cluster::coordinator(d, &["--worker-timeout", "30"]);
    let _w = cluster::worker(d, &url, "w0", None, &[]);
    cluster::registered(&coord, "w0");
    let jobs: Vec<_> = [("a", "40"), ("b", "44")]
        .into_iter()
        .map(|(name, size)| {
            let (d, url) = (d.to_path_buf(), url.clone());
            std::thread::spawn(move || {
                let out = format!("{name}.png");
                let st = format!("{name}.json");
                ok(
                    &d,
                    &[
                        "render",
                        "spd:balls:2",
                        "-o",
                        &out,
                        "--coordinator",
                        &url,
                        "--width",
                        size,
                        "--height",
                        size,
                        "--shard-rays",
                        "256",
                        "--stats",
                        &st,
                    ],
                );
                stats(&d, &st)
            })
        })
        .collect();
    for j in jobs {
        let s = j.join().unwrap();
        let tasks = s["tasks"].as_u64().unwrap();
        let builds = s["grid_builds"].as_u64().unwrap();
        eprintln!("{tasks} tasks, {builds} grid builds");
        assert!(tasks > 10, "{s}");
        assert_eq!(builds, 1, "{s}");
    }
    drop(coord);
}
