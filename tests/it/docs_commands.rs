//! The README and the book in `docs/` say what to type; these tests keep
//! them honest (the conventions are in `docs/README.md`, "Commands in
//! these pages"):
//!
//! - every fenced `sh` block right after a line `<!-- run -->` runs as
//!   written, as one `sh -e` script, with `sray` on the `PATH` being the
//!   binary under test and `cargo run --release --` replaced by `sray`, in
//!   a temporary directory per page that links the repository's `docs/`
//!   and `tests/`; every image or file its `sray` commands write with `-o`
//!   must exist afterwards;
//! - every `sray` command in any shell block of the README, BENCHMARKS.md
//!   and `docs/` names a real subcommand, and only options that
//!   `sray SUBCOMMAND --help` lists;
//! - every relative link in those pages and CHANGELOG.md leads to a file
//!   in the repository (and an `#anchor` to one of its headings), and
//!   every chapter of `docs/` is listed in `docs/README.md`;
//! - the README's two first commands are there, the second being a line
//!   of `.ci/run`.

use std::collections::{BTreeMap, BTreeSet};
use std::fs::File;
use std::path::{Component, Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The marker line before a block that must run as written.
const RUN_MARKER: &str = "<!-- run -->";
/// The README's two first commands, which a newcomer types and CI runs.
const FIRST_RENDER: &str = "cargo run --release -- render spd:balls:4 -o balls.png";
const TEST_COMMAND: &str = "cargo test --workspace --release";
/// How long one marked block may take (generous: the machine may be busy).
const BLOCK_TIMEOUT: Duration = Duration::from_secs(300);

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The `sray` under test, as `common::sray` chooses it.
fn sray_bin() -> PathBuf {
    std::env::var_os("SRAY_TEST_BIN")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_BIN_EXE_sray")))
}

/// README.md and the chapters of the book, in a fixed order.
fn pages() -> Vec<PathBuf> {
    let mut v = vec![repo().join("README.md")];
    v.extend(chapters());
    v
}

/// `docs/*.md`, `docs/README.md` first.
fn chapters() -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(repo().join("docs"))
        .expect("docs/")
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "md"))
        .collect();
    v.sort_by_key(|p| (p.file_name().unwrap() != "README.md", p.clone()));
    v
}

fn read(p: &Path) -> String {
    std::fs::read_to_string(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

fn rel(p: &Path) -> String {
    p.strip_prefix(repo()).unwrap_or(p).display().to_string()
}

/// A fenced code block of a Markdown page.
struct Block {
    /// 1-based line of the opening fence.
    line: usize,
    /// The info string's first word (`sh`, `console`, `text`, ...).
    lang: String,
    /// Right after a `<!-- run -->` line.
    run: bool,
    /// The lines inside the fences, the fence's indentation removed.
    text: String,
}

impl Block {
    fn is_shell(&self) -> bool {
        matches!(self.lang.as_str(), "sh" | "bash" | "shell" | "console")
    }
}

/// The fenced blocks of a page.
fn blocks(page: &str) -> Vec<Block> {
    let lines: Vec<&str> = page.lines().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < lines.len() {
        let t = lines[i].trim_start();
        if !t.starts_with("```") {
            i += 1;
            continue;
        }
        let indent = lines[i].len() - t.len();
        let fence: String = t.chars().take_while(|&c| c == '`').collect();
        let lang = t[fence.len()..]
            .split(|c: char| c == ',' || c.is_whitespace())
            .next()
            .unwrap_or("")
            .to_string();
        let run = i > 0 && lines[i - 1].trim() == RUN_MARKER;
        let start = i;
        let mut text = String::new();
        i += 1;
        while i < lines.len() && lines[i].trim() != fence {
            let l = lines[i];
            let cut = l.len() - l.trim_start().len();
            text.push_str(&l[cut.min(indent)..]);
            text.push('\n');
            i += 1;
        }
        out.push(Block {
            line: start + 1,
            lang,
            run,
            text,
        });
        i += 1;
    }
    out
}

/// The page with its fenced blocks blanked out (line numbers kept).
fn outside_fences(page: &str) -> String {
    let mut out = String::new();
    let mut fence: Option<String> = None;
    for l in page.lines() {
        let t = l.trim_start();
        match &fence {
            Some(f) => {
                if t.trim_end() == f {
                    fence = None;
                }
            }
            None if t.starts_with("```") => {
                fence = Some(t.chars().take_while(|&c| c == '`').collect());
            }
            None => out.push_str(l),
        }
        out.push('\n');
    }
    out
}

/// The page without its fenced blocks and inline code, for links.
fn prose(page: &str) -> String {
    let mut out = String::new();
    for l in outside_fences(page).lines() {
        let mut in_code = false;
        for c in l.chars() {
            if c == '`' {
                in_code = !in_code;
            } else if !in_code {
                out.push(c);
            }
        }
        out.push('\n');
    }
    out
}

/// A shell word, and whether any of it was quoted (a quoted `|` is no
/// pipe, a quoted `#` no comment).
struct Word {
    text: String,
    quoted: bool,
}

/// The logical command lines of a shell block: continuation lines joined,
/// here-documents' bodies left out, `$ ` prompts taken off (`console`).
fn command_lines(b: &Block) -> Vec<String> {
    let mut out = Vec::new();
    let mut pending = String::new();
    let mut heredoc: Option<String> = None;
    for raw in b.text.lines() {
        if let Some(end) = &heredoc {
            if raw.trim() == end {
                heredoc = None;
            }
            continue;
        }
        let mut l = raw.trim_end();
        if b.lang == "console" && pending.is_empty() {
            match l.trim_start().strip_prefix("$ ") {
                Some(c) => l = c,
                None => continue,
            }
        }
        if let Some(head) = l.strip_suffix('\\') {
            pending.push_str(head);
            pending.push(' ');
            continue;
        }
        pending.push_str(l);
        let line = std::mem::take(&mut pending);
        if let Some(at) = line.find("<<") {
            let tag = line[at + 2..]
                .trim_start_matches('-')
                .trim_start()
                .trim_matches(|c| c == '\'' || c == '"');
            let tag: String = tag
                .chars()
                .take_while(|c| c.is_alphanumeric() || *c == '_')
                .collect();
            if !tag.is_empty() {
                heredoc = Some(tag);
            }
        }
        out.push(line);
    }
    out
}

/// Splits a command line into words, dropping a trailing comment.
fn words(line: &str) -> Vec<Word> {
    let mut out = Vec::new();
    let mut cur = String::new();
    let mut quoted = false;
    let mut started = false;
    let mut chars = line.chars().peekable();
    while let Some(c) = chars.next() {
        match c {
            '\'' | '"' => {
                started = true;
                quoted = true;
                for d in chars.by_ref() {
                    if d == c {
                        break;
                    }
                    cur.push(d);
                }
            }
            '#' if !started => break,
            c if c.is_whitespace() => {
                if started {
                    out.push(Word {
                        text: std::mem::take(&mut cur),
                        quoted,
                    });
                    started = false;
                    quoted = false;
                }
            }
            c => {
                started = true;
                cur.push(c);
            }
        }
    }
    if started {
        out.push(Word { text: cur, quoted });
    }
    out
}

/// The argument lists of the `sray` commands a line runs: `sray ARGS`,
/// `.../sray ARGS` or `cargo run --release -- ARGS`, in command position
/// (after environment assignments and `sudo`, `env`, `time`).
fn sray_invocations(line: &str) -> Vec<Vec<String>> {
    let ws = words(line);
    let mut simple: Vec<Vec<&Word>> = vec![Vec::new()];
    for w in &ws {
        if !w.quoted && matches!(w.text.as_str(), "|" | "||" | "&&" | ";" | "&") {
            simple.push(Vec::new());
        } else {
            simple.last_mut().unwrap().push(w);
        }
    }
    let mut out = Vec::new();
    for cmd in simple {
        let mut i = 0;
        while i < cmd.len() {
            let t = cmd[i].text.as_str();
            let assignment = t.split_once('=').is_some_and(|(name, _)| {
                !name.is_empty() && name.chars().all(|c| c.is_alphanumeric() || c == '_')
            });
            if assignment {
                i += 1; // VAR=value
            } else if matches!(t, "sudo" | "env" | "time" | "nice" | "exec") {
                i += 1;
                while i < cmd.len() && cmd[i].text.starts_with('-') {
                    i += 1;
                }
            } else if t == "/usr/bin/time" {
                i += 1;
                while i < cmd.len() && cmd[i].text.starts_with('-') {
                    let takes_value = matches!(cmd[i].text.as_str(), "-f" | "-o");
                    i += if takes_value { 2 } else { 1 };
                }
            } else {
                break;
            }
        }
        let rest: Vec<&str> = cmd[i.min(cmd.len())..]
            .iter()
            .map(|w| w.text.as_str())
            .collect();
        let args = match rest.as_slice() {
            ["cargo", "run", "--release", "--", args @ ..] => args,
            [first, args @ ..] if *first == "sray" || first.ends_with("/sray") => args,
            _ => continue,
        };
        out.push(
            args.iter()
                .map(|a| a.replace(['[', ']'], ""))
                .filter(|a| !a.is_empty())
                .collect(),
        );
    }
    out
}

/// Subcommands and, for each, the options its `--help` lists.
struct Cli {
    options: BTreeMap<String, BTreeSet<String>>,
}

impl Cli {
    fn load() -> Cli {
        let help = |args: &[&str]| {
            let o = Command::new(sray_bin()).args(args).output().expect("sray");
            assert!(o.status.success(), "sray {args:?} failed");
            String::from_utf8(o.stdout).unwrap()
        };
        let top = help(&["--help"]);
        let subs: Vec<String> = top
            .lines()
            .skip_while(|l| !l.starts_with("Commands:"))
            .skip(1)
            .take_while(|l| !l.trim().is_empty())
            .filter_map(|l| l.split_whitespace().next())
            .filter(|s| *s != "help")
            .map(String::from)
            .collect();
        assert!(subs.len() >= 8, "no subcommands in `sray --help`:\n{top}");
        let mut options = BTreeMap::new();
        for s in subs {
            let text = help(&[&s, "--help"]);
            let mut set = BTreeSet::new();
            for w in text.split(|c: char| c.is_whitespace() || c == ',' || c == '[') {
                let w = w.trim_end_matches(|c: char| !c.is_alphanumeric());
                let long = w.starts_with("--") && w.len() > 2;
                let short =
                    w.len() == 2 && w.starts_with('-') && w.as_bytes()[1].is_ascii_alphabetic();
                if long || short {
                    set.insert(w.to_string());
                }
            }
            options.insert(s, set);
        }
        Cli { options }
    }

    /// What is wrong with `sray ARGS`, if anything.
    fn check(&self, args: &[String]) -> Option<String> {
        let Some(sub) = args.first() else {
            return Some("no subcommand".into());
        };
        if sub == "--help" || sub == "-h" || sub == "--version" || sub == "-V" {
            return None;
        }
        let Some(known) = self.options.get(sub) else {
            return Some(format!("no subcommand `{sub}`"));
        };
        for a in &args[1..] {
            let name = a.split('=').next().unwrap();
            let is_option = name.starts_with("--") && name.len() > 2
                || name.len() >= 2
                    && name.starts_with('-')
                    && name.as_bytes()[1].is_ascii_alphabetic();
            if is_option && !known.contains(name) {
                return Some(format!("`sray {sub} --help` lists no `{name}`"));
            }
        }
        None
    }
}

/// Every `sray` command of every shell block of the README, BENCHMARKS.md
/// and the book uses a real subcommand and real options.
#[test]
fn every_sray_command_uses_options_that_exist() {
    let cli = Cli::load();
    let mut checked = 0;
    let mut wrong = Vec::new();
    let mut files = pages();
    files.push(repo().join("BENCHMARKS.md"));
    for p in &files {
        for b in blocks(&read(p)).iter().filter(|b| b.is_shell()) {
            for line in command_lines(b) {
                for args in sray_invocations(&line) {
                    checked += 1;
                    if let Some(why) = cli.check(&args) {
                        wrong.push(format!("{}:{}: {why}: {line}", rel(p), b.line));
                    }
                }
            }
        }
    }
    assert!(
        checked >= 40,
        "only {checked} sray commands found: is the parser broken?"
    );
    assert!(
        wrong.is_empty(),
        "commands with wrong options:\n{}",
        wrong.join("\n")
    );
}

/// Runs `script` with `sh -e` in `dir`, `sray` on the `PATH`; returns
/// the exit status's success and the output.
fn run_script(dir: &Path, bin: &Path, script: &str) -> (bool, String) {
    let out_path = dir.join(".block-output");
    let out = File::create(&out_path).unwrap();
    let path = format!(
        "{}:{}",
        bin.display(),
        std::env::var("PATH").unwrap_or_default()
    );
    let mut child = Command::new("sh")
        .arg("-e")
        .arg("-c")
        .arg(script)
        .current_dir(dir)
        .env("PATH", path)
        .env("TMPDIR", dir.join(".tmp"))
        .env("SRAY_JOBS_DIR", dir.join(".jobs"))
        .stdin(Stdio::null())
        .stdout(out.try_clone().unwrap())
        .stderr(out)
        .spawn()
        .expect("sh");
    let start = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break Some(s);
        }
        if start.elapsed() > BLOCK_TIMEOUT {
            let _ = child.kill();
            let _ = child.wait();
            break None;
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let mut log = std::fs::read_to_string(&out_path).unwrap_or_default();
    if status.is_none() {
        log.push_str(&format!("\n(killed after {BLOCK_TIMEOUT:?})"));
    }
    (status.is_some_and(|s| s.success()), log)
}

/// The outputs (`-o FILE`, `--output FILE`) a line's `sray` commands write.
fn outputs(line: &str) -> Vec<String> {
    let mut v = Vec::new();
    for args in sray_invocations(line) {
        for w in args.windows(2) {
            if w[0] == "-o" || w[0] == "--output" {
                v.push(w[1].clone());
            }
        }
    }
    v
}

/// Runs the marked blocks of `page`; returns how many ran.
fn run_marked_blocks(page: &Path) -> usize {
    let text = read(page);
    let marked: Vec<Block> = blocks(&text).into_iter().filter(|b| b.run).collect();
    if marked.is_empty() {
        return 0;
    }
    let dir = tempfile::tempdir().unwrap();
    let bin = tempfile::tempdir().unwrap();
    std::os::unix::fs::symlink(sray_bin(), bin.path().join("sray")).unwrap();
    for d in ["docs", "tests"] {
        std::os::unix::fs::symlink(repo().join(d), dir.path().join(d)).unwrap();
    }
    std::fs::create_dir(dir.path().join(".tmp")).unwrap();
    for b in &marked {
        let at = format!("{}:{}", rel(page), b.line);
        assert_eq!(b.lang, "sh", "{at}: a marked block must be a `sh` block");
        let script = b.text.replace("cargo run --release --", "sray");
        let (ok, log) = run_script(dir.path(), bin.path(), &script);
        assert!(
            ok,
            "{at}: the block failed:\n{}\n--- output ---\n{log}",
            b.text
        );
        for line in command_lines(b) {
            for o in outputs(&line) {
                assert!(
                    dir.path().join(&o).is_file(),
                    "{at}: `{line}` wrote no {o}\n--- output ---\n{log}"
                );
            }
        }
    }
    marked.len()
}

#[test]
fn readme_commands_run_as_written() {
    let readme = read(&repo().join("README.md"));
    for c in [FIRST_RENDER, TEST_COMMAND] {
        assert!(
            readme.lines().any(|l| l.trim() == c),
            "README.md must give `{c}` on a line of its own"
        );
    }
    let ci = read(&repo().join(".ci/run"));
    assert!(
        ci.lines().any(|l| l.trim() == TEST_COMMAND),
        ".ci/run must run the README's `{TEST_COMMAND}`"
    );
    let n = run_marked_blocks(&repo().join("README.md"));
    assert!(n >= 4, "README.md has only {n} marked blocks");
}

#[test]
fn book_commands_run_as_written() {
    let mut n = 0;
    for p in chapters() {
        n += run_marked_blocks(&p);
    }
    assert!(n >= 10, "the book has only {n} marked blocks");
}

/// GitHub's anchor for a heading: lowercase, punctuation dropped, spaces
/// as hyphens.
fn slug(heading: &str) -> String {
    heading
        .trim()
        .to_lowercase()
        .chars()
        .filter(|c| c.is_alphanumeric() || *c == ' ' || *c == '-' || *c == '_')
        .map(|c| if c == ' ' { '-' } else { c })
        .collect()
}

/// The anchors of a page's headings (a repeated heading gets `-1`, ...).
fn anchors(page: &str) -> BTreeSet<String> {
    let mut seen: BTreeMap<String, usize> = BTreeMap::new();
    let mut out = BTreeSet::new();
    for l in outside_fences(page).lines() {
        let t = l.trim_start_matches('#');
        if t.len() < l.len() && t.starts_with(' ') && l.len() - t.len() <= 6 {
            let s = slug(t);
            let n = seen.entry(s.clone()).or_insert(0);
            out.insert(if *n == 0 {
                s.clone()
            } else {
                format!("{s}-{n}")
            });
            *n += 1;
        }
    }
    out
}

/// The targets of a page's inline links and images.
fn links(page: &str) -> Vec<String> {
    let text = prose(page);
    let mut out = Vec::new();
    let mut rest = text.as_str();
    while let Some(at) = rest.find("](") {
        rest = &rest[at + 2..];
        if let Some(end) = rest.find(')') {
            out.push(rest[..end].trim().to_string());
            rest = &rest[end..];
        }
    }
    out
}

/// `base/target` with `.` and `..` taken out, without touching the disk.
fn normalize(base: &Path, target: &str) -> PathBuf {
    let mut out = PathBuf::new();
    for c in base.join(target).components() {
        match c {
            Component::ParentDir => {
                out.pop();
            }
            Component::CurDir => {}
            c => out.push(c),
        }
    }
    out
}

#[test]
fn links_between_the_documents_resolve() {
    let root = repo();
    let mut files = pages();
    files.push(root.join("BENCHMARKS.md"));
    files.push(root.join("CHANGELOG.md"));
    let mut wrong = Vec::new();
    let mut checked = 0;
    for p in &files {
        let text = read(p);
        for l in links(&text) {
            if l.contains("://") || l.starts_with("mailto:") {
                continue;
            }
            checked += 1;
            let (file, anchor) = match l.split_once('#') {
                Some((f, a)) => (f, Some(a)),
                None => (l.as_str(), None),
            };
            let target = if file.is_empty() {
                p.clone()
            } else {
                normalize(p.parent().unwrap(), file)
            };
            if !target.starts_with(&root) {
                wrong.push(format!("{}: {l} leads outside the repository", rel(p)));
                continue;
            }
            if !target.exists() {
                wrong.push(format!("{}: {l}: no such file", rel(p)));
                continue;
            }
            if let Some(a) = anchor {
                let is_md = target.extension().is_some_and(|e| e == "md");
                if is_md && !anchors(&read(&target)).contains(a) {
                    wrong.push(format!(
                        "{}: {l}: no heading #{a} in {}",
                        rel(p),
                        rel(&target)
                    ));
                }
            }
        }
    }
    assert!(
        checked >= 50,
        "only {checked} links found: is the parser broken?"
    );
    assert!(wrong.is_empty(), "broken links:\n{}", wrong.join("\n"));
}

#[test]
fn every_chapter_is_in_the_books_index() {
    let index = read(&repo().join("docs/README.md"));
    let listed: BTreeSet<String> = links(&index).into_iter().collect();
    for p in chapters().iter().skip(1) {
        let name = p.file_name().unwrap().to_str().unwrap();
        assert!(
            listed.contains(name),
            "docs/README.md does not list the chapter {name}"
        );
    }
}

/// The parsers above, on the forms the pages use.
#[test]
fn the_command_parser_reads_what_the_pages_write() {
    let b = Block {
        line: 1,
        lang: "sh".into(),
        run: false,
        text: "cat > s.nff <<'EOF'\nsray render nothing\nEOF\n\
               sray render a.ply -o a.png \\\n    --camera fov=40   # a comment\n\
               /usr/bin/time -f \"%e %M\" sray convert x -o y.sdb && sray info y.sdb --json\n\
               SRAY=target/release/sray benchmarks/verify-overhead.sh\n\
               sudo install -m 0755 target/release/sray /usr/local/bin/sray\n\
               cargo run --release -- gen tetra --size 3 -o t.nff [--compress zstd[:LEVEL]]\n"
            .into(),
    };
    let calls: Vec<Vec<String>> = command_lines(&b)
        .iter()
        .flat_map(|l| sray_invocations(l))
        .collect();
    let want: Vec<Vec<&str>> = vec![
        vec!["render", "a.ply", "-o", "a.png", "--camera", "fov=40"],
        vec!["convert", "x", "-o", "y.sdb"],
        vec!["info", "y.sdb", "--json"],
        vec![
            "gen",
            "tetra",
            "--size",
            "3",
            "-o",
            "t.nff",
            "--compress",
            "zstd:LEVEL",
        ],
    ];
    assert_eq!(calls, want);
    assert_eq!(
        slug("Instances: 1,024 dragons stored once"),
        "instances-1024-dragons-stored-once"
    );
    assert_eq!(
        slug("The object database (`.sdb`)"),
        "the-object-database-sdb"
    );
}

/// Files of the workspace's sources under `dir` (relative to the
/// repository) whose code has `unsafe`, outside comments.
fn files_with_unsafe(dir: &str, out: &mut BTreeSet<String>) {
    let Ok(entries) = std::fs::read_dir(repo().join(dir)) else {
        return;
    };
    for e in entries.flatten() {
        let rel = format!("{dir}/{}", e.file_name().to_string_lossy());
        if e.path().is_dir() {
            files_with_unsafe(&rel, out);
        } else if rel.ends_with(".rs") {
            let text = read(&e.path());
            let code = text.lines().map(|l| l.split("//").next().unwrap_or(""));
            if code.clone().any(|l| {
                ["unsafe {", "unsafe fn", "unsafe impl", "unsafe extern"]
                    .iter()
                    .any(|u| l.contains(u))
            }) {
                out.insert(rel);
            }
        }
    }
}

/// The list of unsafe code in docs/workspace.md names every file of the
/// program with `unsafe` and no other.
#[test]
fn the_list_of_unsafe_code_is_true() {
    let mut found = BTreeSet::new();
    for d in [
        "src",
        "engine/src",
        "coordinator/src",
        "worker/src",
        "proto/src",
        "bench/src",
    ] {
        files_with_unsafe(d, &mut found);
    }
    let page = read(&repo().join("docs/workspace.md"));
    let section = page
        .split("## Unsafe code")
        .nth(1)
        .expect("docs/workspace.md has a section \"Unsafe code\"");
    let section = section.split("In tests only").next().unwrap();
    // Each item names its files before a colon: "- `a.rs`, `b.rs`: ...".
    let listed: BTreeSet<String> = section
        .split("\n- ")
        .skip(1)
        .flat_map(|item| {
            let head = item.split("`:").next().unwrap_or("").to_string() + "`";
            head.split('`')
                .skip(1)
                .step_by(2)
                .filter(|w| w.ends_with(".rs"))
                .map(String::from)
                .collect::<Vec<_>>()
        })
        .collect();
    assert_eq!(
        listed, found,
        "docs/workspace.md's list of unsafe code (left) and the files with unsafe code (right)"
    );
}
