//! Seeing what the cluster does: `sray status`, the coordinator's HTTP
//! listener (`/healthz`, `/metrics`, `/api/status`, previews) and its
//! dashboard driven in a real headless browser (Debian's chromium, which
//! .ci/run installs; without one the test says why and skips, or fails in
//! CI). Real processes on loopback, small images.

use crate::common;

use common::{Proc, cluster, fails, json, ok};
use std::io::{Read, Write};
use std::path::Path;

/// A coordinator with the HTTP listener; returns it, its gRPC URL and
/// its HTTP address.
fn coordinator(dir: &Path) -> (Proc, String, String) {
    coordinator_with_timeout(dir, "2")
}

/// The same, declaring a silent worker lost after `worker_timeout` seconds.
fn coordinator_with_timeout(dir: &Path, worker_timeout: &str) -> (Proc, String, String) {
    std::fs::write(dir.join("token"), "observe-token-0123456789abcdef").unwrap();
    let (p, url) = cluster::coordinator(
        dir,
        &[
            "--http-listen",
            "127.0.0.1:0",
            "--worker-timeout",
            worker_timeout,
            "--token-file",
            "token",
        ],
    );
    let line = p.wait_for(&["sray coordinator http on"], 5.0);
    let http = line
        .rsplit(' ')
        .next()
        .unwrap()
        .trim_start_matches("http://")
        .trim_end_matches('/')
        .to_string();
    (p, url, http)
}

fn worker(dir: &Path, url: &str, name: &str) -> Proc {
    cluster::worker(dir, url, name, Some("token"), &[])
}

/// Renders 32x32 spd:balls:1 on the cluster; returns the job's id.
fn render(dir: &Path, url: &str) -> String {
    render_sized(dir, url, "32", "32", "256")
}

/// Renders `width`x`height` spd:balls:1 on the cluster, in shards of
/// `shard_rays`; returns the job's id.
fn render_sized(dir: &Path, url: &str, width: &str, height: &str, shard_rays: &str) -> String {
    ok(
        dir,
        &[
            "render",
            "spd:balls:1",
            "-o",
            "out.png",
            "--coordinator",
            url,
            "--token-file",
            "token",
            "--width",
            width,
            "--height",
            height,
            "--shard-rays",
            shard_rays,
            "--stats",
            "stats.json",
            "--quiet",
        ],
    );
    let stats = json(&std::fs::read_to_string(dir.join("stats.json")).unwrap());
    stats["job_id"]
        .as_str()
        .unwrap_or_else(|| panic!("no job id in the stats: {stats}"))
        .to_string()
}

/// A plain HTTP/1.1 GET: the status code and the body.
fn get(addr: &str, path: &str) -> (u16, Vec<u8>) {
    let mut s = std::net::TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(std::time::Duration::from_secs(30)))
        .unwrap();
    write!(
        s,
        "GET {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n"
    )
    .unwrap();
    let mut raw = Vec::new();
    s.read_to_end(&mut raw).unwrap();
    let end = raw
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .expect("an HTTP header");
    let head = String::from_utf8_lossy(&raw[..end]).to_string();
    let code: u16 = head.split(' ').nth(1).unwrap().parse().unwrap();
    let mut body = raw[end + 4..].to_vec();
    if head
        .to_ascii_lowercase()
        .contains("transfer-encoding: chunked")
    {
        let mut out = Vec::new();
        let mut rest = &body[..];
        loop {
            let nl = rest.windows(2).position(|w| w == b"\r\n").unwrap();
            let n = usize::from_str_radix(std::str::from_utf8(&rest[..nl]).unwrap().trim(), 16)
                .unwrap();
            if n == 0 {
                break;
            }
            out.extend_from_slice(&rest[nl + 2..nl + 2 + n]);
            rest = &rest[nl + 2 + n + 2..];
        }
        body = out;
    }
    (code, body)
}

/// The value of the metric sample `name` (with its labels, as printed).
fn metric(text: &str, name: &str) -> f64 {
    text.lines()
        .find_map(|l| l.strip_prefix(name)?.strip_prefix(' '))
        .unwrap_or_else(|| panic!("no metric {name} in:\n{text}"))
        .trim()
        .parse()
        .unwrap()
}

#[test]
fn status_json_healthz_metrics_and_preview() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (coord, url, http) = coordinator(d);
    let _w = worker(d, &url, "obs-w1");
    cluster::registered(&coord, "obs-w1");

    // Healthy as soon as it serves.
    let (code, body) = get(&http, "/healthz");
    assert_eq!(code, 200);
    assert_eq!(String::from_utf8_lossy(&body).trim(), "ok");

    let job = render(d, &url);
    // The job's lifecycle is in the coordinator's log.
    for what in [
        "job submitted",
        "job started",
        "round started",
        "round done",
        "job finished",
    ] {
        coord.wait_for(&[what, &job], 10.0);
    }
    coord.wait_for(&["task assigned", &job], 10.0);
    coord.wait_for(&["task completed", &job], 10.0);

    // sray status --json: one object, workers and jobs.
    let out = ok(
        d,
        &[
            "status",
            "--coordinator",
            &url,
            "--token-file",
            "token",
            "--json",
        ],
    );
    let s = json(&out);
    let workers = s["workers"].as_array().expect("workers");
    let jobs = s["jobs"].as_array().expect("jobs");
    assert_eq!(workers.len(), 1, "{s}");
    let w = &workers[0];
    assert_eq!(w["name"], "obs-w1");
    assert_eq!(w["id"], "w1");
    assert_eq!(w["threads"], 1);
    assert_eq!(w["memory_bytes"], 64u64 << 20);
    assert_eq!(w["quarantined"], false);
    assert!(w["tasks_done"].as_u64().unwrap() >= 2, "{w}");
    assert_eq!(w["failures"], 0);
    assert!(
        w["address"].as_str().unwrap().starts_with("127.0.0.1:"),
        "{w}"
    );
    assert!(
        ["idle", "busy"].contains(&w["state"].as_str().unwrap()),
        "{w}"
    );
    assert!(w["tasks"].is_array());
    assert_eq!(jobs.len(), 1, "{s}");
    let j = &jobs[0];
    assert_eq!(j["id"], job.as_str());
    assert_eq!(j["state"], "done");
    assert_eq!(
        (j["width"].as_u64(), j["height"].as_u64()),
        (Some(32), Some(32))
    );
    assert_eq!(j["progress_percent"], 100.0);
    assert!(j["round"].as_u64().unwrap() >= 1);
    assert!(!j["rounds"].as_array().unwrap().is_empty());
    for t in ["submitted_unix", "started_unix", "finished_unix"] {
        assert!(j[t].as_u64().unwrap() > 1_700_000_000, "{t}: {j}");
    }
    assert!(j["scene"].as_str().unwrap().len() == 64, "{j}");
    // No secret anywhere.
    assert!(!out.contains("secret"), "{out}");

    // The table, for a terminal.
    let table = ok(
        d,
        &["status", "--coordinator", &url, "--token-file", "token"],
    );
    assert!(
        table.contains("WORKERS (1)") && table.contains("obs-w1"),
        "{table}"
    );
    assert!(
        table.contains("JOBS (1)") && table.contains(&job) && table.contains("32x32"),
        "{table}"
    );

    // A client's token is needed.
    let err = fails(d, &["status", "--coordinator", &url, "--json"]);
    assert!(err.to_lowercase().contains("token"), "{err}");

    // /api/status is the same JSON.
    let (code, body) = get(&http, "/api/status");
    assert_eq!(code, 200);
    let api = json(&String::from_utf8(body).unwrap());
    assert_eq!(api["jobs"][0]["id"], job.as_str());
    assert_eq!(api["workers"][0]["name"], "obs-w1");

    // /metrics: real names and values.
    let (code, body) = get(&http, "/metrics");
    assert_eq!(code, 200);
    let m = String::from_utf8(body).unwrap();
    assert_eq!(
        metric(&m, "sray_jobs_finished_total{outcome=\"done\"}"),
        1.0,
        "{m}"
    );
    assert_eq!(
        metric(&m, "sray_jobs_finished_total{outcome=\"failed\"}"),
        0.0
    );
    assert_eq!(metric(&m, "sray_jobs_submitted_total"), 1.0);
    assert_eq!(metric(&m, "sray_jobs{state=\"done\"}"), 1.0);
    assert_eq!(metric(&m, "sray_jobs{state=\"running\"}"), 0.0);
    let busy = metric(&m, "sray_workers{state=\"busy\"}");
    let idle = metric(&m, "sray_workers{state=\"idle\"}");
    assert_eq!(busy + idle, 1.0, "{m}");
    assert_eq!(metric(&m, "sray_workers{state=\"quarantined\"}"), 0.0);
    // Every eye ray (33 x 33 pixel corners) was intersected.
    assert!(
        metric(&m, "sray_rays_total{stage=\"intersect\"}") >= 33.0 * 33.0,
        "{m}"
    );
    assert!(
        metric(&m, "sray_rays_total{stage=\"shade\"}") >= 33.0 * 33.0,
        "{m}"
    );
    assert!(metric(&m, "sray_tasks_completed_total{stage=\"intersect\"}") >= 1.0);
    assert!(metric(&m, "sray_wire_bytes_total{direction=\"from_workers\"}") > 0.0);
    assert!(metric(&m, "sray_wire_bytes_total{direction=\"to_workers\"}") > 0.0);
    assert_eq!(metric(&m, "sray_verification_mismatches_total"), 0.0);
    assert_eq!(metric(&m, "sray_queue_depth"), 0.0);
    assert!(m.contains("# TYPE sray_rays_total counter"), "{m}");
    // The worker asks for its next task with its output, and a shading of
    // results it holds comes with its input: one call a task, not three.
    let with_output = metric(&m, "sray_tasks_given_total{asked=\"with_output\"}");
    let on_request = metric(&m, "sray_tasks_given_total{asked=\"next_task\"}");
    assert!(
        with_output >= 1.0 && with_output > on_request,
        "{with_output} tasks given with an output, {on_request} on request: {m}"
    );
    assert!(
        metric(&m, "sray_task_inputs_total{how=\"inline\"}") >= 1.0,
        "{m}"
    );

    // The preview of a finished job is its image.
    let (code, png) = get(&http, &format!("/jobs/{job}/preview.png"));
    assert_eq!(code, 200);
    let img = image::load_from_memory(&png).expect("a PNG");
    assert_eq!((img.width(), img.height()), (32, 32));
    assert_eq!(png, std::fs::read(d.join("out.png")).unwrap());
    // Bad ids are refused cleanly.
    assert_eq!(get(&http, "/jobs/nope/preview.png").0, 400);
    assert_eq!(
        get(&http, &format!("/jobs/{}/preview.png", "0".repeat(32))).0,
        404
    );
    assert_eq!(get(&http, "/nothing-here").0, 404);
}

/// A headless browser, if one is installed.
fn browser() -> Option<String> {
    [
        "chromium",
        "chromium-browser",
        "google-chrome",
        "google-chrome-stable",
    ]
    .into_iter()
    .find(|b| {
        std::process::Command::new(b)
            .arg("--version")
            .output()
            .is_ok_and(|o| o.status.success())
    })
    .map(String::from)
}

/// A headless browser, or None after saying why the test skips (in CI,
/// where it must run, it fails instead).
fn browser_or_skip() -> Option<String> {
    let b = browser();
    if b.is_none() {
        common::cannot_run(
            "no headless browser (chromium) installed; .ci/run installs Debian's chromium",
        );
    }
    b
}

/// The page's DOM after its scripts ran for a few (virtual) seconds.
fn dump_dom(browser: &str, profile: &Path, url: &str) -> String {
    let o = std::process::Command::new(browser)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-dev-shm-usage",
            "--no-first-run",
            "--virtual-time-budget=4000",
        ])
        .arg(format!("--user-data-dir={}", profile.display()))
        .arg("--dump-dom")
        .arg(url)
        .output()
        .expect("run the browser");
    assert!(
        o.status.success(),
        "{browser} failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).to_string()
}

#[test]
fn dashboard_in_a_headless_browser() {
    let Some(browser) = browser_or_skip() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (coord, url, http) = coordinator(d);
    let _w = worker(d, &url, "dash-w1");
    cluster::registered(&coord, "dash-w1");

    // While no job runs: the worker is shown.
    let profile = d.join("profile");
    let dom = dump_dom(&browser, &profile, &format!("http://{http}/"));
    assert!(dom.contains("dash-w1"), "no worker in the page:\n{dom}");

    // A wide image, wider than the preview's room: shown smaller, at the
    // image's aspect ratio (not squeezed into the room's width at the
    // image's full height).
    let job = render_sized(d, &url, "320", "120", "4096");
    let dom = dump_dom(&browser, &profile, &format!("http://{http}/"));
    assert!(dom.contains("dash-w1"), "no worker in the page:\n{dom}");
    assert!(dom.contains(&job), "no job {job} in the page:\n{dom}");
    assert!(
        dom.contains("job-state done"),
        "the job is not shown done:\n{dom}"
    );
    // The preview image is in the page, and loaded in the browser at the
    // job's size.
    let src = format!("/jobs/{job}/preview.png");
    assert!(dom.contains(&src), "no preview <img> in the page:\n{dom}");
    assert!(
        dom.contains("data-loaded=\"320x120\""),
        "the preview did not load in the browser:\n{dom}"
    );
    let (w, h) = shown_size(&dom, &src);
    assert!(
        w <= 256 && (w * 120).abs_diff(h * 320) <= 320,
        "the 320x120 preview is shown at {w}x{h}, not at its aspect ratio:\n{dom}"
    );
    let (code, png) = get(&http, &src);
    assert_eq!(code, 200);
    let img = image::load_from_memory(&png).expect("a PNG");
    assert_eq!((img.width(), img.height()), (320, 120));
}

/// The size (CSS pixels, without the border) at which the browser laid
/// out the `<img>` whose source starts with `src`: its `data-shown`.
fn shown_size(dom: &str, src: &str) -> (u64, u64) {
    let tag = dom
        .split("<img ")
        .skip(1)
        .map(|t| &t[..t.find('>').unwrap_or(t.len())])
        .find(|t| t.contains(src))
        .unwrap_or_else(|| panic!("no <img> of {src}:\n{dom}"));
    let shown = tag
        .split("data-shown=\"")
        .nth(1)
        .and_then(|r| r.split('"').next())
        .unwrap_or_else(|| panic!("the preview was not laid out (no data-shown): {tag}"));
    let (w, h) = shown
        .split_once('x')
        .and_then(|(w, h)| Some((w.parse().ok()?, h.parse().ok()?)))
        .unwrap_or_else(|| panic!("data-shown={shown:?}"));
    assert!(w > 0 && h > 0, "the preview is shown at {shown}");
    (w, h)
}

/// Renders on the cluster in the background; the client's process.
fn render_in_background(dir: &Path, url: &str, width: &str, height: &str) -> Proc {
    Proc::start(
        dir,
        &[
            "render",
            "spd:balls:2",
            "-o",
            "out.png",
            "--coordinator",
            url,
            "--token-file",
            "token",
            "--width",
            width,
            "--height",
            height,
            "--shard-rays",
            "256",
            "--quiet",
        ],
        &[],
    )
}

fn signal(p: &Proc, sig: libc::c_int) {
    // SAFETY: kill(2) takes integers only; the pid is our own child's,
    // which has not been waited for, so it names that process.
    let r = unsafe { libc::kill(p.child.id() as libc::pid_t, sig) };
    assert_eq!(r, 0, "kill({sig})");
}

/// The dashboard while a job runs: the worker is stopped (SIGSTOP) in the
/// job's second round, so the job is certainly still running when the
/// browser looks, with the first round's image as its preview, shown at
/// the image's aspect ratio (a 64x32 job: twice as wide as high).
#[test]
fn dashboard_shows_a_running_job_with_its_preview() {
    let Some(browser) = browser_or_skip() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // A stopped worker must not be declared lost while the browser looks.
    let (coord, url, http) = coordinator_with_timeout(d, "120");
    let w = worker(d, &url, "live-w1");
    cluster::registered(&coord, "live-w1");

    let mut client = render_in_background(d, &url, "64", "32");
    let mark = coord.mark();
    if std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        coord.wait_for_after(mark, &["round done"], 60.0);
    }))
    .is_err()
    {
        panic!("the client said: {}", client.log());
    }
    coord.wait_for_after(mark, &["task assigned", "round=2"], 60.0);
    signal(&w, libc::SIGSTOP);

    let (code, body) = get(&http, "/api/status");
    assert_eq!(code, 200);
    let st = json(&String::from_utf8_lossy(&body));
    let job = &st["jobs"][0];
    assert_eq!(job["state"], "running", "{st}");
    let id = job["id"].as_str().unwrap().to_string();

    let dom = dump_dom(&browser, &d.join("profile"), &format!("http://{http}/"));
    signal(&w, libc::SIGCONT);
    assert!(dom.contains("live-w1"), "no worker in the page:\n{dom}");
    assert!(dom.contains(&id), "no job {id} in the page:\n{dom}");
    assert!(
        dom.contains("job-state running"),
        "the job is not shown running:\n{dom}"
    );
    assert!(
        dom.contains(&format!("/jobs/{id}/preview.png")),
        "no preview <img> in the page:\n{dom}"
    );
    assert!(
        dom.contains("data-loaded=\"64x32\""),
        "the first round's preview did not load in the browser:\n{dom}"
    );
    let (w, h) = shown_size(&dom, &format!("/jobs/{id}/preview.png"));
    assert_eq!(w, 2 * h, "the 64x32 preview is shown at {w}x{h}:\n{dom}");

    // Resumed, the job finishes and the client gets its image.
    assert!(client.wait(120.0).success(), "{}", client.log());
    let img = image::open(d.join("out.png")).unwrap();
    assert_eq!((img.width(), img.height()), (64, 32));
}

/// Standard gRPC health and server reflection answer on the gRPC port,
/// without a token (probes and tools such as grpcurl carry none).
#[test]
fn grpc_health_and_reflection_answer() {
    use tonic_health::pb::health_check_response::ServingStatus;
    use tonic_health::pb::{HealthCheckRequest, health_client::HealthClient};
    use tonic_reflection::pb::v1::ServerReflectionRequest;
    use tonic_reflection::pb::v1::server_reflection_client::ServerReflectionClient;
    use tonic_reflection::pb::v1::server_reflection_request::MessageRequest;
    use tonic_reflection::pb::v1::server_reflection_response::MessageResponse;

    let dir = tempfile::tempdir().unwrap();
    let (_coord, url, _http) = coordinator(dir.path());
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    rt.block_on(async {
        let ch = tonic::transport::Endpoint::from_shared(url.clone())
            .unwrap()
            .connect()
            .await
            .unwrap();
        let mut health = HealthClient::new(ch.clone());
        for service in ["", "sray.v1.Coordinator"] {
            let r = health
                .check(HealthCheckRequest {
                    service: service.into(),
                })
                .await
                .unwrap_or_else(|e| panic!("health of '{service}': {e}"))
                .into_inner();
            assert_eq!(r.status, ServingStatus::Serving as i32, "'{service}'");
        }
        let unknown = health
            .check(HealthCheckRequest {
                service: "no.such.Service".into(),
            })
            .await
            .unwrap_err();
        assert_eq!(unknown.code(), tonic::Code::NotFound);

        let mut refl = ServerReflectionClient::new(ch);
        let ask = |r: MessageRequest| ServerReflectionRequest {
            host: String::new(),
            message_request: Some(r),
        };
        let reqs = vec![
            ask(MessageRequest::ListServices(String::new())),
            ask(MessageRequest::FileContainingSymbol(
                "sray.v1.Coordinator".into(),
            )),
        ];
        let mut answers = refl
            .server_reflection_info(tokio_stream::iter(reqs))
            .await
            .unwrap()
            .into_inner();
        let listed = answers.message().await.unwrap().unwrap();
        let Some(MessageResponse::ListServicesResponse(l)) = listed.message_response else {
            panic!("not a service list: {listed:?}");
        };
        let names: Vec<_> = l.service.iter().map(|s| s.name.as_str()).collect();
        for want in ["sray.v1.Coordinator", "grpc.health.v1.Health"] {
            assert!(names.contains(&want), "{want} not listed: {names:?}");
        }
        let file = answers.message().await.unwrap().unwrap();
        let Some(MessageResponse::FileDescriptorResponse(f)) = file.message_response else {
            panic!("no descriptor for sray.v1.Coordinator: {file:?}");
        };
        assert!(!f.file_descriptor_proto.is_empty());
        let text = String::from_utf8_lossy(&f.file_descriptor_proto[0]).to_string();
        assert!(
            text.contains("NextTask"),
            "the descriptor lacks the service's methods"
        );
    });
}
