//! The deploy files work as written: `deploy/Dockerfile`, `.dockerignore`,
//! `deploy/compose.yaml`, `deploy/k8s/*.yaml`, `deploy/healthz.sh` and
//! `deploy/systemd/*.service`.
//!
//! No container engine, Kubernetes or systemd runs here, so each file is
//! tried the way its runtime would use it. The Dockerfile's run stage is
//! laid out as a directory tree (the directories its `RUN install -d`
//! makes, with their owners and modes, and what it copies); each compose
//! service, Kubernetes workload and systemd unit then runs the real `sray`
//! with its own command line, as the user it names (`setpriv`, as root), on
//! such a tree with its volumes, secrets and directories laid as its
//! runtime lays them. Their healthchecks and probes ask the live processes,
//! and a job renders through the coordinator and worker so started, which
//! must write their volumes as that user. The files also go through their
//! schemas and checkers: `kubernetes-validate` and `check-jsonschema` (from
//! PyPI) and `systemd-analyze verify`; `.ci/run` installs them, and in CI a
//! missing one fails its test.

use crate::common;

use common::Proc;
use std::collections::BTreeMap;
use std::io::{BufRead, BufReader, Write};
use std::net::TcpListener;
use std::os::unix::fs::{MetadataExt, PermissionsExt};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use yaml_rust2::{Yaml, YamlLoader};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn read(rel: &str) -> String {
    std::fs::read_to_string(root().join(rel)).unwrap_or_else(|e| panic!("{rel}: {e}"))
}

fn yaml(rel: &str) -> Vec<Yaml> {
    YamlLoader::load_from_str(&read(rel))
        .unwrap_or_else(|e| panic!("{rel}: {e}"))
        .into_iter()
        .filter(|d| !d.is_null())
        .collect()
}

fn k8s_files() -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(root().join("deploy/k8s"))
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .filter(|n| n.ends_with(".yaml") || n.ends_with(".yml"))
        .map(|n| format!("deploy/k8s/{n}"))
        .collect();
    v.sort();
    assert!(!v.is_empty(), "no manifests in deploy/k8s");
    v
}

fn k8s_docs() -> Vec<(String, Yaml)> {
    k8s_files()
        .into_iter()
        .flat_map(|f| yaml(&f).into_iter().map(move |d| (f.clone(), d)))
        .collect()
}

fn str_of<'a>(y: &'a Yaml, what: &str) -> &'a str {
    y.as_str()
        .unwrap_or_else(|| panic!("{what}: expected a string, found {y:?}"))
}

fn strings(y: &Yaml, what: &str) -> Vec<String> {
    y.as_vec()
        .unwrap_or_else(|| panic!("{what}: expected a list, found {y:?}"))
        .iter()
        .map(|s| str_of(s, what).to_string())
        .collect()
}

/// The value after `--name` in a command line.
fn flag<'a>(args: &'a [String], name: &str) -> Option<&'a str> {
    args.iter().position(|a| a == name).map(|i| {
        args.get(i + 1)
            .unwrap_or_else(|| panic!("{name} without a value"))
            .as_str()
    })
}

/// The port of an `ADDR:PORT` listen address or a URL.
fn port_of(addr: &str) -> u16 {
    addr.trim_end_matches('/')
        .rsplit(':')
        .next()
        .and_then(|p| p.parse().ok())
        .unwrap_or_else(|| panic!("no port in {addr:?}"))
}

/// Whether `path` is `dir` or inside it.
fn under(path: &str, dir: &str) -> bool {
    let dir = dir.trim_end_matches('/');
    path == dir || path.starts_with(&format!("{dir}/"))
}

fn mode_of(y: &Yaml, what: &str) -> u32 {
    y.as_i64()
        .unwrap_or_else(|| panic!("{what}: expected a mode, found {y:?}")) as u32
}

// ---------------------------------------------------------------------
// The image, as its Dockerfile builds it.

/// What the Dockerfile's run stage makes: the user it runs as, its
/// working directory, the directories it creates (path, uid, gid, mode)
/// and the files it copies (from the build context, or the built `sray`).
struct Image {
    uid: u32,
    gid: u32,
    workdir: String,
    dirs: Vec<(String, u32, u32, u32)>,
    /// (source: a path in the context, or "" for the built binary; dest)
    copies: Vec<(String, String)>,
    entrypoint: Vec<String>,
}

impl Image {
    fn parse() -> Image {
        let text = read("deploy/Dockerfile").replace("\\\n", " ");
        let stage = text.rsplit("\nFROM ").next().unwrap();
        let mut img = Image {
            uid: 0,
            gid: 0,
            workdir: "/".into(),
            dirs: Vec::new(),
            copies: Vec::new(),
            entrypoint: Vec::new(),
        };
        for line in stage.lines().map(str::trim) {
            let Some((cmd, rest)) = line.split_once(' ') else {
                continue;
            };
            match cmd {
                "RUN" => {
                    for step in rest.split("&&").map(str::trim) {
                        img.run(step);
                    }
                }
                "COPY" => {
                    let w: Vec<&str> = rest.split_whitespace().collect();
                    let (src, dest) = match w.as_slice() {
                        ["--from=build", src, dest] => {
                            assert!(
                                src.ends_with("/target/release/sray"),
                                "COPY --from=build {src}: teach this test what it is"
                            );
                            (String::new(), dest.to_string())
                        }
                        [src, dest] => (src.to_string(), dest.to_string()),
                        _ => panic!("COPY {rest}: teach this test about it"),
                    };
                    img.copies.push((src, dest));
                }
                "USER" => {
                    let (u, g) = rest
                        .trim()
                        .split_once(':')
                        .expect("USER names uid:gid, numerically (runAsNonRoot needs a number)");
                    img.uid = u.parse().expect("USER's uid is a number");
                    img.gid = g.parse().expect("USER's gid is a number");
                }
                "WORKDIR" => img.workdir = rest.trim().to_string(),
                "ENTRYPOINT" => {
                    img.entrypoint =
                        strings(&YamlLoader::load_from_str(rest).unwrap()[0], "ENTRYPOINT")
                }
                _ => {}
            }
        }
        assert!(img.uid > 0 && img.gid > 0, "the image must not run as root");
        img
    }

    /// One shell step of a `RUN`: the directories it makes; user and group
    /// creation must name the image's numeric ids.
    fn run(&mut self, step: &str) {
        let w: Vec<&str> = step.split_whitespace().collect();
        let opt = |name: &str| {
            w.iter()
                .position(|x| *x == name)
                .map(|i| w[i + 1])
                .unwrap_or_else(|| panic!("{step}: no {name}"))
        };
        match w[0] {
            "groupadd" | "useradd" => {}
            "install" if w.contains(&"-d") => {
                let (uid, gid) = (opt("-o").parse().unwrap(), opt("-g").parse().unwrap());
                let mode = u32::from_str_radix(opt("-m"), 8).unwrap();
                let mut i = 1;
                while i < w.len() {
                    match w[i] {
                        "-d" => i += 1,
                        "-o" | "-g" | "-m" => i += 2,
                        p => {
                            self.dirs.push((p.to_string(), uid, gid, mode));
                            i += 1;
                        }
                    }
                }
            }
            _ => panic!("RUN {step}: teach this test what it makes"),
        }
    }

    /// The user and group creation name the uid and gid that USER runs as.
    fn check_users(&self) {
        let text = read("deploy/Dockerfile").replace("\\\n", " ");
        let (u, g) = (self.uid, self.gid);
        assert!(
            text.contains(&format!("groupadd --system --gid {g} ")),
            "the run stage creates group {g}"
        );
        assert!(
            text.contains(&format!("--uid {u} --gid {g}")),
            "the run stage creates user {u} in group {g}"
        );
    }
}

// ---------------------------------------------------------------------
// A container (or a unit's view of the machine): a directory tree standing
// for its filesystem, and the user its processes run as.

struct Container {
    tree: tempfile::TempDir,
    uid: u32,
    gid: u32,
    groups: Vec<u32>,
    cwd: String,
    env: Vec<(String, String)>,
}

/// Creates `dir` (and its parents, root's, 0755) with this owner and mode.
fn make_dir(dir: &Path, uid: u32, gid: u32, mode: u32) {
    std::fs::create_dir_all(dir).unwrap();
    std::os::unix::fs::chown(dir, Some(uid), Some(gid)).unwrap();
    std::fs::set_permissions(dir, std::fs::Permissions::from_mode(mode)).unwrap();
}

fn write_file(path: &Path, text: &str, uid: u32, gid: u32, mode: u32) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(path, text).unwrap();
    std::os::unix::fs::chown(path, Some(uid), Some(gid)).unwrap();
    std::fs::set_permissions(path, std::fs::Permissions::from_mode(mode)).unwrap();
}

impl Container {
    /// An empty tree (everything in it root's, 0755), processes as `uid`.
    fn empty(uid: u32, gid: u32) -> Container {
        let tree = tempfile::tempdir_in(env!("CARGO_TARGET_TMPDIR")).unwrap();
        std::fs::set_permissions(tree.path(), std::fs::Permissions::from_mode(0o755)).unwrap();
        Container {
            tree,
            uid,
            gid,
            groups: Vec::new(),
            cwd: "/".into(),
            env: Vec::new(),
        }
    }

    /// A container of the image: its directories and files, its user.
    fn of(img: &Image) -> Container {
        let c = Container::empty(img.uid, img.gid);
        for (p, uid, gid, mode) in &img.dirs {
            make_dir(&c.path(p), *uid, *gid, *mode);
        }
        for (src, dest) in &img.copies {
            let src = if src.is_empty() {
                PathBuf::from(env!("CARGO_BIN_EXE_sray"))
            } else {
                root().join(src)
            };
            c.install(&src, dest);
        }
        Container {
            cwd: img.workdir.clone(),
            ..c
        }
    }

    /// `src` at `dest`, as COPY or an install puts it (owner root, mode kept).
    fn install(&self, src: &Path, dest: &str) {
        let to = self.path(dest);
        std::fs::create_dir_all(to.parent().unwrap()).unwrap();
        if std::fs::hard_link(src, &to).is_err() {
            std::fs::copy(src, &to).unwrap();
        }
    }

    /// Where the absolute path `p` of the container is in the tree.
    fn path(&self, p: &str) -> PathBuf {
        assert!(p.starts_with('/'), "{p} is not absolute");
        self.tree.path().join(p.trim_start_matches('/'))
    }

    /// `program ARGS` as the container's user, in its working directory,
    /// with its environment only.
    fn command(&self, program: &str, args: &[String]) -> Command {
        let groups = if self.groups.is_empty() {
            "--clear-groups".to_string()
        } else {
            let g: Vec<String> = self.groups.iter().map(u32::to_string).collect();
            format!("--groups={}", g.join(","))
        };
        let mut c = Command::new("setpriv");
        c.arg(format!("--reuid={}", self.uid))
            .arg(format!("--regid={}", self.gid))
            .arg(groups)
            .arg("--inh-caps=-all")
            .arg("--")
            .arg(program)
            .args(args)
            .current_dir(self.path(&self.cwd))
            .env_clear()
            .env("PATH", "/usr/local/bin:/usr/bin:/bin")
            .env("RUST_LOG", "info,sray_coordinator=debug");
        for (k, v) in &self.env {
            c.env(k, v);
        }
        c
    }

    /// Runs `sray ARGS` (the container's, at `/usr/local/bin/sray`) in the
    /// background.
    fn start_sray(&self, args: &[String]) -> Proc {
        let bin = self.path("/usr/local/bin/sray");
        Proc::spawn(self.command(bin.to_str().unwrap(), args))
    }

    /// Files under the container's `dir` that its user owns.
    fn files_of_user(&self, dir: &str) -> Vec<PathBuf> {
        fn walk(d: &Path, uid: u32, out: &mut Vec<PathBuf>) {
            for e in std::fs::read_dir(d).into_iter().flatten().flatten() {
                let m = e.metadata().unwrap();
                if m.is_dir() {
                    walk(&e.path(), uid, out);
                } else if m.uid() == uid {
                    out.push(e.path());
                }
            }
        }
        let mut v = Vec::new();
        walk(&self.path(dir), self.uid, &mut v);
        v
    }
}

/// A process as another user needs root here (CI runs as root).
fn as_root() -> bool {
    let root = std::fs::read_to_string("/proc/self/status")
        .unwrap()
        .lines()
        .find_map(|l| l.strip_prefix("Uid:"))
        .is_some_and(|ids| ids.split_whitespace().nth(1) == Some("0"));
    if !root {
        common::cannot_run("running the deploy files' processes as their users needs root");
    }
    root
}

// ---------------------------------------------------------------------
// The live cluster the deploy files describe.

/// A coordinator started from a deploy file: its gRPC URL, its HTTP
/// address, and the ports its file gave them (`--listen`, `--http-listen`).
struct Live {
    proc: Proc,
    url: String,
    ports: BTreeMap<u16, u16>,
}

/// The command line `args` (of `sray`) for a process of `c` on this
/// machine: absolute paths into its tree, the listen addresses to free
/// ports on loopback, and `--coordinator` to the live coordinator.
fn localize(c: &Container, args: &[String], live: Option<&Live>) -> Vec<String> {
    let mut out = Vec::new();
    let mut i = 0;
    while i < args.len() {
        let a = &args[i];
        out.push(a.clone());
        if a.starts_with("--") && i + 1 < args.len() && !args[i + 1].starts_with("--") {
            let v = &args[i + 1];
            out.push(match a.as_str() {
                "--listen" | "--http-listen" => "127.0.0.1:0".into(),
                "--coordinator" => live.expect("a coordinator first").url.clone(),
                _ if v.starts_with('/') => c.path(v).to_string_lossy().into_owned(),
                _ => v.clone(),
            });
            i += 1;
        }
        i += 1;
    }
    out
}

/// Starts the coordinator of a deploy file in `c`.
fn start_coordinator(c: &Container, args: &[String], what: &str) -> Live {
    assert_eq!(args[0], "coordinator", "{what}");
    let proc = c.start_sray(&localize(c, args, None));
    let line = proc.wait_for(&["listening on"], 30.0);
    let url = line.rsplit(' ').next().unwrap().to_string();
    let mut ports = BTreeMap::new();
    ports.insert(port_of(flag(args, "--listen").unwrap()), port_of(&url));
    if let Some(h) = flag(args, "--http-listen") {
        let line = proc.wait_for(&["http on"], 10.0);
        ports.insert(port_of(h), port_of(line.rsplit(' ').next().unwrap()));
    }
    Live { proc, url, ports }
}

/// Starts a worker of a deploy file in `c` and waits until it registers.
fn start_worker(c: &Container, args: &[String], live: &Live, what: &str) -> Proc {
    assert_eq!(args[0], "worker", "{what}");
    let mark = live.proc.mark();
    let w = c.start_sray(&localize(c, args, Some(live)));
    if std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        live.proc.wait_for_after(mark, &["worker registered"], 30.0)
    }))
    .is_err()
    {
        panic!("{what}: the worker did not register; it said:\n{}", w.log());
    }
    w
}

/// A plain HTTP/1.1 GET; the status code.
fn http_get(addr: &str, path: &str) -> u16 {
    let mut s = std::net::TcpStream::connect(addr).unwrap();
    write!(
        s,
        "GET {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n"
    )
    .unwrap();
    let mut head = String::new();
    BufReader::new(s).read_line(&mut head).unwrap();
    head.split(' ').nth(1).unwrap().parse().unwrap()
}

/// Renders a small job through the live coordinator with the clients'
/// token `token` (as root, like a user's client elsewhere).
fn render_through(live: &Live, token: &str, what: &str) {
    let d = tempfile::tempdir().unwrap();
    std::fs::write(d.path().join("client.token"), token).unwrap();
    let args = [
        "render",
        "spd:balls:1",
        "-o",
        "out.png",
        "--coordinator",
        &live.url,
        "--token-file",
        "client.token",
        "--width",
        "24",
        "--height",
        "16",
        "--quiet",
    ];
    let o = common::run(d.path(), &args);
    assert!(
        o.status.success(),
        "{what}: a render through the deploy's coordinator failed: {}\ncoordinator:\n{}",
        String::from_utf8_lossy(&o.stderr),
        live.proc.log()
    );
    assert!(d.path().join("out.png").is_file());
}

/// Runs a probe's or healthcheck's command `cmd` in `c` (its programs from
/// the container's tree, `/proc/1` the process `pid`); whether it passed.
fn probe(c: &Container, cmd: &[String], pid: u32, ports: &BTreeMap<u16, u16>) -> Output {
    let mut cmd: Vec<String> = cmd
        .iter()
        .map(|a| {
            let a = a.replace("/proc/1/", &format!("/proc/{pid}/"));
            match a.parse::<u16>().ok().and_then(|p| ports.get(&p)) {
                Some(live) => live.to_string(),
                None => a,
            }
        })
        .collect();
    if cmd[0].starts_with("/usr/local/") {
        cmd[0] = c.path(&cmd[0]).to_string_lossy().into_owned();
    }
    c.command(&cmd[0], &cmd[1..]).output().unwrap()
}

/// A probe of a live process passes; stopped (SIGSTOP), it fails; then the
/// process goes on.
fn probe_tells_a_stopped_process(c: &Container, cmd: &[String], p: &Proc, what: &str) {
    let pid = p.child.id();
    let no_ports = BTreeMap::new();
    let o = probe(c, cmd, pid, &no_ports);
    assert!(
        o.status.success(),
        "{what}: fails on a live process: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let kill = |sig: &str| {
        assert!(
            Command::new("kill")
                .args([sig, &pid.to_string()])
                .status()
                .unwrap()
                .success()
        )
    };
    kill("-STOP");
    // A stopped process shows so in /proc a moment after the signal.
    std::thread::sleep(std::time::Duration::from_millis(100));
    let o = probe(c, cmd, pid, &no_ports);
    kill("-CONT");
    assert!(!o.status.success(), "{what}: passes on a stopped process");
}

/// Files the container's user wrote under each of `dirs`: none means it
/// could not (or did not) write there.
fn wrote(c: &Container, dirs: &[&str], what: &str) {
    for d in dirs {
        assert!(
            !c.files_of_user(d).is_empty(),
            "{what}: nothing written by uid {} under {d}",
            c.uid
        );
    }
}

const WORKER_TOKEN: &str = "deploy-test-worker-token-0123456789";
const CLIENT_TOKEN: &str = "deploy-test-client-token-0123456789";

/// The token a deploy file's secret holds: the workers' or the clients'.
fn token_for(secret: &str) -> &'static str {
    match (secret.contains("worker"), secret.contains("client")) {
        (true, false) => WORKER_TOKEN,
        (false, true) => CLIENT_TOKEN,
        _ => panic!("secret {secret}: the workers' or the clients'?"),
    }
}

// ---------------------------------------------------------------------
// The Dockerfile and its context.

#[test]
fn dockerfile_makes_an_image_whose_user_owns_its_home() {
    let img = Image::parse();
    img.check_users();
    assert_eq!(img.entrypoint, ["/usr/local/bin/sray"]);
    assert!(
        img.copies
            .iter()
            .any(|(s, d)| s.is_empty() && d == "/usr/local/bin/sray"),
        "the image carries the built sray"
    );
    // The image's user can write where it starts.
    assert!(
        img.dirs
            .iter()
            .any(|(p, u, _, m)| *p == img.workdir && *u == img.uid && m & 0o700 == 0o700),
        "WORKDIR {} is not a directory the image makes for its user",
        img.workdir
    );
    if !as_root() {
        return;
    }
    // Laid out, what it copies runs as its user.
    let c = Container::of(&img);
    let o = c
        .command(
            c.path("/usr/local/bin/sray").to_str().unwrap(),
            &["--help".into()],
        )
        .output()
        .unwrap();
    assert!(o.status.success(), "the image's sray --help failed");
    let o = probe(
        &c,
        &["/usr/local/bin/sray-healthz".into(), "1".into()],
        0,
        &BTreeMap::new(),
    );
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("nothing listens"),
        "the image's sray-healthz does not run: {}",
        String::from_utf8_lossy(&o.stderr)
    );
}

/// One `.dockerignore` pattern against a path relative to the context
/// (enough of Docker's matching for the patterns used there).
fn ignored_by(pattern: &str, path: &str) -> bool {
    let p = pattern.trim_start_matches('/').trim_end_matches('/');
    if let Some(ext) = p.strip_prefix("**/*") {
        return path.ends_with(ext);
    }
    if let Some(rest) = p.strip_prefix("**/") {
        let comps: Vec<&str> = path.split('/').collect();
        return (0..comps.len()).any(|i| under(&comps[i..].join("/"), rest));
    }
    assert!(
        !p.contains('*'),
        "pattern {pattern:?}: teach ignored_by about it"
    );
    under(path, p)
}

fn files_under(dir: &Path, rel: &str, out: &mut Vec<String>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let e = e.unwrap();
        let name = e.file_name().into_string().unwrap();
        let r = format!("{rel}{name}");
        if name == "target" {
            continue;
        }
        if e.file_type().unwrap().is_dir() {
            files_under(&e.path(), &format!("{r}/"), out);
        } else {
            out.push(r);
        }
    }
}

#[test]
fn dockerignore_leaves_out_target_git_and_secrets_but_not_the_sources() {
    let text = read(".dockerignore");
    let patterns: Vec<&str> = text
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
        .collect();
    assert!(
        patterns.iter().all(|p| !p.starts_with('!')),
        "no exceptions: keep the matching simple"
    );
    let ignored = |path: &str| patterns.iter().any(|p| ignored_by(p, path));
    for gone in [
        "target/release/sray",
        ".git",
        ".git/HEAD",
        "fuzz/target/x",
        "deploy/token",
        "client.token",
        "deploy/key.pem",
    ] {
        assert!(ignored(gone), "{gone} must stay out of the build context");
    }
    // Everything `cargo build --release --locked --bin sray` reads, and
    // what the Dockerfile copies out of the context.
    let mut needed = vec!["Cargo.toml".to_string(), "Cargo.lock".to_string()];
    needed.extend(
        Image::parse()
            .copies
            .into_iter()
            .map(|(s, _)| s)
            .filter(|s| !s.is_empty()),
    );
    for dir in ["src", "engine", "proto", "worker", "coordinator", "bench"] {
        files_under(&root().join(dir), &format!("{dir}/"), &mut needed);
    }
    assert!(needed.iter().any(|f| f == "proto/sray.proto"));
    for f in &needed {
        assert!(!ignored(f), "{f} is needed by the image build but ignored");
    }
}

// ---------------------------------------------------------------------
// compose

/// Each service in a container of the image, as compose runs it: its
/// volumes (a fresh named volume holds what the image has at its mount
/// point, with its owners), its secrets (copied in with their uid, gid and
/// mode), its command as the image's user. The coordinator's healthcheck
/// answers, the worker's tells a stopped worker, and a job renders through
/// them, written to their volumes by the image's user.
#[test]
fn compose_services_run_as_the_image_user_and_write_their_volumes() {
    if !as_root() {
        return;
    }
    let img = Image::parse();
    let compose = &yaml("deploy/compose.yaml")[0];
    let service = |name: &str| {
        let s = &compose["services"][name];
        assert!(!s.is_badvalue(), "compose: no service {name}");
        let c = Container::of(&img);
        assert!(
            s["user"].is_badvalue(),
            "compose {name}: runs as the image's user"
        );
        for v in s["volumes"].as_vec().into_iter().flatten() {
            let v = str_of(v, "volume");
            let (vol, at) = v.split_once(':').unwrap();
            assert!(
                !compose["volumes"][vol].is_badvalue(),
                "compose {name}: {vol} is no named volume (a bind mount keeps the host's owners)"
            );
            if !c.path(at).exists() {
                make_dir(&c.path(at), 0, 0, 0o755);
            }
        }
        for sec in s["secrets"].as_vec().into_iter().flatten() {
            let source = str_of(&sec["source"], "secret source");
            assert!(
                compose["secrets"][source]["environment"].as_str().is_some(),
                "compose: secret {source}: a `file:` secret is a bind mount that keeps the host's \
                 owner and mode; take it from the environment"
            );
            let target = sec["target"].as_str().unwrap_or(source);
            let id = |k: &str| str_of(&sec[k], k).parse::<u32>().unwrap();
            write_file(
                &c.path(&format!("/run/secrets/{target}")),
                token_for(source),
                id("uid"),
                id("gid"),
                mode_of(&sec["mode"], "secret mode"),
            );
        }
        (s, c, strings(&s["command"], "command"))
    };

    let (cs, cc, cargs) = service("coordinator");
    let live = start_coordinator(&cc, &cargs, "compose coordinator");
    let test = strings(&cs["healthcheck"]["test"], "healthcheck.test");
    assert_eq!(test[0], "CMD", "compose coordinator: exec form");
    let o = probe(&cc, &test[1..], live.proc.child.id(), &live.ports);
    assert!(
        o.status.success(),
        "compose coordinator: the healthcheck fails on a live coordinator: {}",
        String::from_utf8_lossy(&o.stderr)
    );

    let (ws, wc, wargs) = service("worker");
    assert_eq!(
        ws["depends_on"]["coordinator"]["condition"].as_str(),
        Some("service_healthy"),
        "compose worker: starts once the coordinator is healthy"
    );
    let worker = start_worker(&wc, &wargs, &live, "compose worker");
    let test = strings(&ws["healthcheck"]["test"], "healthcheck.test");
    assert_eq!(test[0], "CMD", "compose worker: exec form");
    probe_tells_a_stopped_process(&wc, &test[1..], &worker, "compose worker's healthcheck");

    render_through(&live, CLIENT_TOKEN, "compose");
    wrote(
        &cc,
        &[flag(&cargs, "--data-dir").unwrap()],
        "compose coordinator",
    );
    wrote(
        &wc,
        &[flag(&wargs, "--cache-dir").unwrap()],
        "compose worker",
    );
    // Published ports only on loopback: no TLS by default.
    for p in cs["ports"].as_vec().into_iter().flatten() {
        let p = str_of(p, "port");
        assert!(
            p.starts_with("127.0.0.1:"),
            "compose: port {p} on all interfaces"
        );
    }
}

// ---------------------------------------------------------------------
// Kubernetes

/// The containers of a workload as the kubelet runs them: the image's
/// tree with each volume mounted over it (a PersistentVolumeClaim fresh,
/// group-owned by fsGroup and group-writable; an emptyDir writable by all;
/// a Secret's keys as files of root and group fsGroup, in its defaultMode),
/// as runAsUser and runAsGroup with fsGroup a supplementary group.
fn k8s_container(
    img: &Image,
    pod: &Yaml,
    c: &Yaml,
    secret_keys: &BTreeMap<String, String>,
) -> Container {
    let sc = &pod["securityContext"];
    assert_eq!(sc["runAsNonRoot"].as_bool(), Some(true), "runAsNonRoot");
    let id = |k: &str| sc[k].as_i64().unwrap_or_else(|| panic!("no {k}")) as u32;
    let (uid, gid, fs_group) = (id("runAsUser"), id("runAsGroup"), id("fsGroup"));
    let mut box_ = Container::of(img);
    box_.uid = uid;
    box_.gid = gid;
    box_.groups = vec![fs_group];
    let volumes: BTreeMap<&str, &Yaml> = pod["volumes"]
        .as_vec()
        .expect("volumes")
        .iter()
        .map(|v| (str_of(&v["name"], "volume name"), v))
        .collect();
    for m in c["volumeMounts"].as_vec().expect("volumeMounts") {
        let name = str_of(&m["name"], "mount name");
        let at = box_.path(str_of(&m["mountPath"], "mountPath"));
        let v = volumes
            .get(name)
            .unwrap_or_else(|| panic!("mounts volume {name}, which the pod does not have"));
        let _ = std::fs::remove_dir_all(&at);
        if !v["persistentVolumeClaim"].is_badvalue() {
            make_dir(&at, 0, fs_group, 0o2775);
        } else if !v["emptyDir"].is_badvalue() {
            make_dir(&at, 0, 0, 0o777);
        } else if !v["secret"].is_badvalue() {
            let secret = str_of(&v["secret"]["secretName"], "secretName");
            let key = secret_keys.get(secret).unwrap_or_else(|| {
                panic!("no `kubectl create secret generic {secret}` in the comments")
            });
            make_dir(&at, 0, fs_group, 0o755);
            let mode = v["secret"]["defaultMode"].as_i64().unwrap_or(0o644) as u32;
            write_file(&at.join(key), token_for(secret), 0, fs_group, mode);
        } else {
            panic!("volume {name}: teach this test its kind");
        }
        if m["readOnly"].as_bool() == Some(true) {
            let mode = std::fs::metadata(&at).unwrap().mode() & 0o7555;
            std::fs::set_permissions(&at, std::fs::Permissions::from_mode(mode)).unwrap();
        }
    }
    for e in c["env"].as_vec().into_iter().flatten() {
        let v = str_of(&e["value"], "env value");
        let v = if v.starts_with('/') {
            box_.path(v).to_string_lossy().into_owned()
        } else {
            v.to_string()
        };
        box_.env
            .push((str_of(&e["name"], "env name").to_string(), v));
    }
    box_
}

/// A probe of a container: an HTTP GET or a command. The port of an HTTP
/// probe is a number or a named container port, served by the live
/// process as its deploy file's listen address.
fn k8s_probe(what: &str, p: &Yaml, c: &Yaml, box_: &Container, proc: &Proc, live: &Live) {
    assert!(
        p["tcpSocket"].is_badvalue(),
        "{what}: an open port says nothing of serving"
    );
    if !p["httpGet"].is_badvalue() {
        let port = match &p["httpGet"]["port"] {
            Yaml::Integer(n) => *n as u16,
            Yaml::String(name) => c["ports"]
                .as_vec()
                .into_iter()
                .flatten()
                .find(|q| q["name"].as_str() == Some(name))
                .and_then(|q| q["containerPort"].as_i64())
                .unwrap_or_else(|| panic!("{what}: port {name} is no container port"))
                as u16,
            other => panic!("{what}: port {other:?}"),
        };
        let live_port = live
            .ports
            .get(&port)
            .unwrap_or_else(|| panic!("{what}: nothing listens on port {port}"));
        let path = str_of(&p["httpGet"]["path"], "path");
        let code = http_get(&format!("127.0.0.1:{live_port}"), path);
        assert_eq!(code, 200, "{what}: GET {path}");
    } else if !p["exec"].is_badvalue() {
        let cmd = strings(&p["exec"]["command"], "exec probe");
        probe_tells_a_stopped_process(box_, &cmd, proc, what);
    } else {
        panic!("{what}: teach this test this kind of probe");
    }
}

/// The secrets' keys, from the `kubectl create secret generic NAME
/// --from-file=KEY=...` commands the manifests' comments give.
fn k8s_secret_keys() -> BTreeMap<String, String> {
    let mut keys = BTreeMap::new();
    for f in k8s_files() {
        for l in read(&f).lines() {
            if let Some(rest) = l.split("kubectl create secret generic ").nth(1) {
                let mut w = rest.split_whitespace();
                let name = w.next().unwrap();
                let key = w
                    .find_map(|a| a.strip_prefix("--from-file="))
                    .and_then(|a| a.split_once('='))
                    .map(|(k, _)| k)
                    .unwrap_or_else(|| panic!("{f}: {l}: no --from-file=KEY=FILE"));
                keys.insert(name.to_string(), key.to_string());
            }
        }
    }
    keys
}

/// The coordinator's and the workers' Deployments run as their pods'
/// security context on their volumes; the probes answer the live
/// processes; the workers find the coordinator through its Service; and a
/// job renders through them, written to the volumes by the pods' user.
#[test]
fn kubernetes_workloads_run_as_their_pods_user_and_write_their_volumes() {
    if !as_root() {
        return;
    }
    let img = Image::parse();
    let docs = k8s_docs();
    let keys = k8s_secret_keys();
    let kind = |d: &Yaml| str_of(&d["kind"], "kind").to_string();
    let workload = |role: &str| {
        let (file, d) = docs
            .iter()
            .find(|(_, d)| {
                kind(d) == "Deployment" && d["metadata"]["labels"]["role"].as_str() == Some(role)
            })
            .unwrap_or_else(|| panic!("no Deployment of role {role}"));
        let tpl = &d["spec"]["template"];
        for (k, v) in d["spec"]["selector"]["matchLabels"]
            .as_hash()
            .expect("matchLabels")
        {
            assert_eq!(
                &tpl["metadata"]["labels"][str_of(k, "label")],
                v,
                "{file}: selector"
            );
        }
        let cs = tpl["spec"]["containers"].as_vec().expect("containers");
        assert_eq!(cs.len(), 1, "{file}: one container");
        (file.clone(), tpl.clone(), cs[0].clone())
    };
    for (_, d) in &docs {
        if let Some(cs) = d["spec"]["template"]["spec"]["containers"].as_vec() {
            for c in cs {
                let image = str_of(&c["image"], "image");
                assert!(
                    !image.ends_with(":latest") && image.contains(':'),
                    "image {image}: name a tag, not latest"
                );
                assert!(
                    matches!(
                        c["imagePullPolicy"].as_str(),
                        Some("IfNotPresent" | "Never")
                    ),
                    "image {image}: a local image, never pulled"
                );
            }
        }
    }

    let (cfile, ctpl, cc) = workload("coordinator");
    let cbox = k8s_container(&img, &ctpl["spec"], &cc, &keys);
    let cargs = strings(&cc["args"], "args");
    let live = start_coordinator(&cbox, &cargs, &cfile);
    for p in ["startupProbe", "readinessProbe", "livenessProbe"] {
        if !cc[p].is_badvalue() {
            k8s_probe(
                &format!("{cfile}: {p}"),
                &cc[p],
                &cc,
                &cbox,
                &live.proc,
                &live,
            );
        }
    }
    assert!(
        !cc["readinessProbe"].is_badvalue(),
        "{cfile}: a readinessProbe"
    );

    let (wfile, wtpl, wc) = workload("worker");
    let wbox = k8s_container(&img, &wtpl["spec"], &wc, &keys);
    let wargs = strings(&wc["args"], "args");
    // The worker's coordinator is a Service whose target is the
    // coordinator's gRPC port.
    let target = flag(&wargs, "--coordinator").unwrap();
    let host = target
        .split("://")
        .nth(1)
        .unwrap()
        .split(':')
        .next()
        .unwrap();
    let svc = docs
        .iter()
        .map(|(_, d)| d)
        .find(|d| kind(d) == "Service" && d["metadata"]["name"].as_str() == Some(host))
        .unwrap_or_else(|| panic!("{wfile}: no Service {host}"));
    for (k, v) in svc["spec"]["selector"].as_hash().expect("Service selector") {
        assert_eq!(
            &ctpl["metadata"]["labels"][str_of(k, "label")],
            v,
            "Service {host} selects the coordinator"
        );
    }
    let sp = svc["spec"]["ports"]
        .as_vec()
        .unwrap()
        .iter()
        .find(|p| p["port"].as_i64() == Some(port_of(target) as i64))
        .unwrap_or_else(|| panic!("Service {host} has no port {}", port_of(target)));
    let named = str_of(&sp["targetPort"], "targetPort");
    let cport = cc["ports"]
        .as_vec()
        .unwrap()
        .iter()
        .find(|p| p["name"].as_str() == Some(named))
        .and_then(|p| p["containerPort"].as_i64())
        .unwrap_or_else(|| panic!("Service {host}: targetPort {named} is no container port"));
    assert_eq!(
        cport as u16,
        port_of(flag(&cargs, "--listen").unwrap()),
        "Service {host} reaches --listen"
    );

    let worker = start_worker(&wbox, &wargs, &live, &wfile);
    for p in ["startupProbe", "readinessProbe", "livenessProbe"] {
        if !wc[p].is_badvalue() {
            k8s_probe(&format!("{wfile}: {p}"), &wc[p], &wc, &wbox, &worker, &live);
        }
    }
    render_through(&live, CLIENT_TOKEN, "kubernetes");
    wrote(&cbox, &[flag(&cargs, "--data-dir").unwrap()], &cfile);
    wrote(&wbox, &[flag(&wargs, "--cache-dir").unwrap()], &wfile);
    // Everything the processes write is on a volume, none on the
    // container's layer: --tmp-dir and TMPDIR under a writable mount.
    for (file, c, args) in [(&cfile, &cc, &cargs), (&wfile, &wc, &wargs)] {
        let mounts: Vec<&str> = c["volumeMounts"]
            .as_vec()
            .unwrap()
            .iter()
            .filter(|m| m["readOnly"].as_bool() != Some(true))
            .map(|m| str_of(&m["mountPath"], "mountPath"))
            .collect();
        let tmp = flag(args, "--tmp-dir").unwrap_or_else(|| panic!("{file}: no --tmp-dir"));
        assert!(
            mounts.iter().any(|m| under(tmp, m)),
            "{file}: --tmp-dir {tmp} on no volume"
        );
    }
}

// ---------------------------------------------------------------------
// systemd

/// `KEY=` lines of a unit (continuation lines joined).
fn unit_key(unit: &str, key: &str) -> Vec<String> {
    unit.replace("\\\n", " ")
        .lines()
        .filter_map(|l| l.strip_prefix(key).and_then(|r| r.strip_prefix('=')))
        .map(String::from)
        .collect()
}

/// The machine as a unit sees it: its StateDirectory and CacheDirectory
/// made by systemd for its user, the rest root's (ProtectSystem=strict
/// makes it read-only anyway), the tokens root's and its group's, 0640, as
/// the comments ask. Returns the container and the unit's command line,
/// its `${VARIABLES}` from the EnvironmentFile the comments show.
fn systemd_unit(name: &str, uid: u32) -> (Container, Vec<String>) {
    let text = read(&format!("deploy/systemd/{name}"));
    let mut c = Container::empty(uid, uid);
    c.install(Path::new(env!("CARGO_BIN_EXE_sray")), "/usr/local/bin/sray");
    for d in unit_key(&text, "StateDirectory") {
        make_dir(&c.path(&format!("/var/lib/{d}")), uid, uid, 0o755);
    }
    for d in unit_key(&text, "CacheDirectory") {
        make_dir(&c.path(&format!("/var/cache/{d}")), uid, uid, 0o755);
    }
    c.cwd = unit_key(&text, "WorkingDirectory")[0].clone();
    for e in unit_key(&text, "Environment") {
        let (k, v) = e.split_once('=').unwrap();
        c.env
            .push((k.into(), c.path(v).to_string_lossy().into_owned()));
    }
    let mut exec = unit_key(&text, "ExecStart")[0].clone();
    // The EnvironmentFile's example lines: "#   KEY=VALUE".
    for l in text.lines() {
        if let Some((k, v)) = l.strip_prefix("#   ").and_then(|l| l.split_once('='))
            && k.chars().all(|ch| ch.is_ascii_uppercase() || ch == '_')
        {
            exec = exec.replace(&format!("${{{k}}}"), v);
        }
    }
    assert!(
        !exec.contains("${"),
        "{name}: {exec}: a variable the comments do not show"
    );
    let args: Vec<String> = exec.split_whitespace().map(String::from).collect();
    assert_eq!(args[0], "/usr/local/bin/sray", "{name}");
    for a in args.iter().filter(|a| a.starts_with("/etc/sray/")) {
        write_file(&c.path(a), token_for(a), 0, uid, 0o640);
    }
    (c, args[1..].to_vec())
}

/// The units' processes as their user (one with a uid systemd would pick),
/// on the directories systemd makes for them: a job renders through them,
/// written there; the units pass `systemd-analyze verify`.
#[test]
fn systemd_units_run_in_their_own_directories_and_verify() {
    let uid = 10_077;
    if as_root() {
        let (cc, cargs) = systemd_unit("sray-coordinator.service", uid);
        let live = start_coordinator(&cc, &cargs, "sray-coordinator.service");
        let (wc, wargs) = systemd_unit("sray-worker.service", uid);
        let _w = start_worker(&wc, &wargs, &live, "sray-worker.service");
        render_through(&live, CLIENT_TOKEN, "systemd");
        wrote(
            &cc,
            &[flag(&cargs, "--data-dir").unwrap()],
            "sray-coordinator.service",
        );
        wrote(
            &wc,
            &[flag(&wargs, "--cache-dir").unwrap()],
            "sray-worker.service",
        );
    }

    if Command::new("systemd-analyze")
        .arg("--version")
        .output()
        .is_err()
    {
        common::cannot_run("systemd-analyze is not installed (Debian: systemd)");
        return;
    }
    // `verify` wants ExecStart's binary to exist: point it at this build.
    let tmp = tempfile::tempdir().unwrap();
    let mut copies = Vec::new();
    for u in ["sray-coordinator.service", "sray-worker.service"] {
        let c = tmp.path().join(u);
        let text = read(&format!("deploy/systemd/{u}"));
        std::fs::write(
            &c,
            text.replace("/usr/local/bin/sray", env!("CARGO_BIN_EXE_sray")),
        )
        .unwrap();
        copies.push(c);
    }
    let out = Command::new("systemd-analyze")
        .arg("verify")
        .args(&copies)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success(),
        "systemd-analyze verify failed:\n{err}"
    );
    // Unknown keys and bad assignments are only warnings: none allowed.
    assert!(
        err.trim().is_empty(),
        "systemd-analyze verify warned:\n{err}"
    );
}

// ---------------------------------------------------------------------
// What the files agree on, and their schemas.

/// Workers and clients have tokens of their own: in every deploy file,
/// the workers read the secret the coordinator expects of workers, never
/// the clients' (a worker's token cannot submit jobs, nor a client's join).
#[test]
fn workers_and_clients_have_tokens_of_their_own() {
    // (file, role, flag, secret) for every token flag of every process.
    let mut found: Vec<(String, String, String, String)> = Vec::new();
    let compose = &yaml("deploy/compose.yaml")[0];
    for (name, s) in compose["services"].as_hash().unwrap() {
        let cmd = strings(&s["command"], "command");
        let secrets: BTreeMap<String, String> = s["secrets"]
            .as_vec()
            .into_iter()
            .flatten()
            .map(|sec| {
                let src = str_of(&sec["source"], "source").to_string();
                let t = sec["target"].as_str().unwrap_or(&src).to_string();
                (format!("/run/secrets/{t}"), src)
            })
            .collect();
        let what = format!("compose {}", str_of(name, "service"));
        let mut read = 0;
        for (i, a) in cmd
            .iter()
            .enumerate()
            .filter(|(_, a)| a.ends_with("token-file"))
        {
            let secret = secrets
                .get(&cmd[i + 1])
                .unwrap_or_else(|| panic!("{what}: {a} {} is none of its secrets", cmd[i + 1]));
            found.push((what.clone(), cmd[0].clone(), a.clone(), secret.clone()));
            read += 1;
        }
        assert_eq!(
            read,
            secrets.len(),
            "{what}: holds a secret it does not read"
        );
    }
    for (file, d) in k8s_docs() {
        let pod = &d["spec"]["template"]["spec"];
        let Some(cs) = pod["containers"].as_vec() else {
            continue;
        };
        for c in cs {
            let args = strings(&c["args"], "args");
            for (i, a) in args
                .iter()
                .enumerate()
                .filter(|(_, a)| a.ends_with("token-file"))
            {
                let m = c["volumeMounts"]
                    .as_vec()
                    .unwrap()
                    .iter()
                    .find(|m| under(&args[i + 1], str_of(&m["mountPath"], "mountPath")))
                    .unwrap_or_else(|| panic!("{file}: {a} on no volume"));
                let v = pod["volumes"]
                    .as_vec()
                    .unwrap()
                    .iter()
                    .find(|v| v["name"] == m["name"])
                    .unwrap();
                let secret = str_of(&v["secret"]["secretName"], "secretName");
                found.push((file.clone(), args[0].clone(), a.clone(), secret.into()));
            }
        }
    }
    for u in ["sray-coordinator.service", "sray-worker.service"] {
        let exec = unit_key(&read(&format!("deploy/systemd/{u}")), "ExecStart")[0].clone();
        let args: Vec<String> = exec.split_whitespace().skip(1).map(String::from).collect();
        for (i, a) in args
            .iter()
            .enumerate()
            .filter(|(_, a)| a.ends_with("token-file"))
        {
            found.push((u.into(), args[0].clone(), a.clone(), args[i + 1].clone()));
        }
    }
    for flavour in ["compose", "deploy/k8s", "sray-"] {
        let of = |role: &str, f: &str| {
            let v: Vec<&str> = found
                .iter()
                .filter(|(file, r, fl, _)| file.starts_with(flavour) && r == role && fl == f)
                .map(|(_, _, _, s)| s.as_str())
                .collect();
            assert_eq!(v.len(), 1, "{flavour}: {role} {f}: {found:?}");
            v[0].to_string()
        };
        assert!(
            found
                .iter()
                .all(|(file, r, f, _)| !file.starts_with(flavour)
                    || r != "coordinator"
                    || f != "--token-file"),
            "{flavour}: one --token-file would serve workers and clients alike"
        );
        let w = of("coordinator", "--worker-token-file");
        assert_ne!(w, of("coordinator", "--client-token-file"), "{flavour}");
        assert_eq!(
            of("worker", "--token-file"),
            w,
            "{flavour}: the workers read the workers' token"
        );
    }
}

/// A Python validator from PyPI: its console script, or its module (pip's
/// script folder may not be on PATH). None, when neither runs, after
/// saying so (in CI, failing).
fn python_tool(script: &str, module: &str) -> Option<Command> {
    let candidates = [(script, vec![]), ("python3", vec!["-m", module])];
    for (cmd, pre) in candidates {
        let runs = Command::new(cmd)
            .args(&pre)
            .arg("--version")
            .output()
            .is_ok_and(|o| o.status.success());
        if runs {
            let mut c = Command::new(cmd);
            c.args(&pre).current_dir(root());
            return Some(c);
        }
    }
    common::cannot_run(&format!(
        "{script} is not installed (pip install {script}; .ci/run installs it)"
    ));
    None
}

fn run_validator(mut c: Command, what: &str) {
    let out = c.output().unwrap();
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(out.status.success(), "{what} failed:\n{text}");
    assert!(!text.contains("ERROR"), "{what}:\n{text}");
}

/// Against Kubernetes' own OpenAPI schemas (bundled in kubernetes-validate),
/// strictly: an unknown or misplaced field fails.
#[test]
fn kubernetes_manifests_pass_the_kubernetes_schemas() {
    let Some(mut c) = python_tool("kubernetes-validate", "kubernetes_validate") else {
        return;
    };
    c.args(["--strict", "--quiet"]).args(k8s_files());
    run_validator(c, "kubernetes-validate --strict deploy/k8s");
}

/// Against the compose specification's schema (check-jsonschema's copy).
#[test]
fn compose_file_passes_the_compose_schema() {
    let Some(mut c) = python_tool("check-jsonschema", "check_jsonschema") else {
        return;
    };
    c.args([
        "--builtin-schema",
        "vendor.compose-spec",
        "deploy/compose.yaml",
    ]);
    run_validator(c, "check-jsonschema (compose-spec) deploy/compose.yaml");
}

// ---------------------------------------------------------------------
// The healthcheck script against listeners that answer otherwise.

/// Answers one HTTP request with `status`; returns the port and the
/// request line it got.
fn one_answer(status: &'static str) -> (u16, std::thread::JoinHandle<String>) {
    let l = TcpListener::bind("127.0.0.1:0").unwrap();
    let port = l.local_addr().unwrap().port();
    let h = std::thread::spawn(move || {
        let (s, _) = l.accept().unwrap();
        let mut r = BufReader::new(s.try_clone().unwrap());
        let mut first = String::new();
        r.read_line(&mut first).unwrap();
        let mut line = String::new();
        while r.read_line(&mut line).unwrap() > 0 && line != "\r\n" {
            line.clear();
        }
        let mut w = s;
        write!(
            w,
            "HTTP/1.1 {status}\r\nContent-Length: 3\r\nConnection: close\r\n\r\nok\n"
        )
        .unwrap();
        first
    });
    (port, h)
}

fn healthz(port: u16) -> Output {
    Command::new(root().join("deploy/healthz.sh"))
        .arg(port.to_string())
        .output()
        .expect("run deploy/healthz.sh")
}

/// The coordinator's healthcheck (above) passes on a live coordinator;
/// here it fails on a 503 and on a closed port, saying why.
#[test]
fn healthcheck_script_tells_200_from_the_rest() {
    let (port, h) = one_answer("200 OK");
    assert!(healthz(port).status.success());
    assert_eq!(h.join().unwrap(), "GET /healthz HTTP/1.1\r\n");

    let (port, h) = one_answer("503 Service Unavailable");
    let out = healthz(port);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("503"));
    h.join().unwrap();

    let closed = TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let out = healthz(closed);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("nothing listens"));
}
