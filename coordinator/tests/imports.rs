//! The coordinator's rooms: no two of its files import each other,
//! directly or in a loop, and none is over [`MAX_LINES`] lines.
//!
//! A file imports another when it names a path into it: a `use` of
//! `crate::…`, `super::…`, `self::…` or of a child module, or such a path
//! written in the code (`crate::jobs::result(..)`). A path is taken to
//! point into the deepest module file it names (`crate::driver::submit`
//! is `driver/submit.rs`; `crate::jobs::JobEntry` is `jobs/mod.rs`, which
//! re-exports it). Comments, strings and a file's own inline modules
//! (`mod tests { use super::*; }`) are not imports.
//!
//! `cargo test -p sray-coordinator --test imports -- --nocapture` prints
//! each file's imports.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The most lines a file of the coordinator may have: past it, split the
/// file by the jobs it does.
const MAX_LINES: usize = 700;

/// A module's path below the crate root (the root itself: empty).
type ModPath = Vec<String>;

/// Files by module path, with their text.
type Sources = BTreeMap<ModPath, (String, String)>;

/// Who imports whom, by file name.
type Graph = BTreeMap<String, BTreeSet<String>>;

#[test]
fn no_two_files_of_the_coordinator_import_each_other() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let sources = read_sources(&src);
    assert!(sources.len() > 5, "read {} files", sources.len());
    let graph = import_graph(&sources);
    println!("{}", listing(&graph));
    if let Some(cycle) = find_cycle(&graph) {
        panic!(
            "files of the coordinator import each other: {}\n\
             move what they share into a file both can import\n\n{}",
            cycle.join(" -> "),
            listing(&graph)
        );
    }
}

#[test]
fn no_file_of_the_coordinator_is_over_the_limit() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let long: Vec<String> = read_sources(&src)
        .values()
        .filter(|(_, text)| text.lines().count() > MAX_LINES)
        .map(|(name, text)| format!("{name} ({} lines)", text.lines().count()))
        .collect();
    assert!(
        long.is_empty(),
        "over {MAX_LINES} lines: {}; split them by the jobs they do",
        long.join(", ")
    );
}

#[test]
fn the_check_finds_a_loop_through_a_re_export() {
    let files = [
        ("lib.rs", "mod a;\nmod b;\n"),
        (
            "a.rs",
            "// use crate::b::Nothing;\n\
             /* crate::b::c::Nothing */\n\
             use crate::b::{X, Y as Z};\n\
             const S: &str = \"crate::b::c::y\";\n\
             #[cfg(test)]\nmod tests {\n    use super::*;\n}\n",
        ),
        ("b/mod.rs", "mod c;\npub use c::{X, Y};\n"),
        (
            "b/c.rs",
            "pub struct X;\npub struct Y;\nfn f() -> char { let _ = '{'; crate::a::g() }\n",
        ),
    ];
    let sources: Sources = files
        .iter()
        .map(|(name, text)| {
            (
                module_of(Path::new(name)),
                (name.to_string(), text.to_string()),
            )
        })
        .collect();
    let graph = import_graph(&sources);
    let edges = |f: &str| graph[f].iter().cloned().collect::<Vec<_>>();
    assert_eq!(edges("lib.rs"), Vec::<String>::new());
    assert_eq!(edges("a.rs"), ["b/mod.rs"]);
    assert_eq!(edges("b/mod.rs"), ["b/c.rs"]);
    assert_eq!(edges("b/c.rs"), ["a.rs"]);
    let cycle = find_cycle(&graph).expect("a loop");
    assert_eq!(cycle, ["a.rs", "b/mod.rs", "b/c.rs", "a.rs"]);

    // Without the path in the code, no loop.
    let c: ModPath = vec!["b".to_string(), "c".to_string()];
    let (_, text) = &sources[&c];
    let mut fixed = sources.clone();
    fixed.insert(c, ("b/c.rs".into(), text.replace("crate::a::g()", "'}'")));
    assert_eq!(find_cycle(&import_graph(&fixed)), None);
}

/// Every `.rs` file under `src`, by module path.
fn read_sources(src: &Path) -> Sources {
    let mut out = Sources::new();
    let mut dirs = vec![src.to_path_buf()];
    while let Some(dir) = dirs.pop() {
        for e in std::fs::read_dir(&dir).unwrap() {
            let path = e.unwrap().path();
            if path.is_dir() {
                dirs.push(path);
            } else if path.extension().is_some_and(|x| x == "rs") {
                let rel: PathBuf = path.strip_prefix(src).unwrap().into();
                let name = rel.to_string_lossy().replace('\\', "/");
                let text = std::fs::read_to_string(&path).unwrap();
                out.insert(module_of(&rel), (name, text));
            }
        }
    }
    out
}

/// `lib.rs`: the root; `a.rs` and `a/mod.rs`: `a`; `a/b.rs`: `a::b`.
fn module_of(rel: &Path) -> ModPath {
    let mut parts: Vec<String> = rel
        .iter()
        .map(|p| p.to_string_lossy().to_string())
        .collect();
    let last = parts.pop().unwrap();
    let stem = last.trim_end_matches(".rs");
    if stem != "mod" && !(parts.is_empty() && (stem == "lib" || stem == "main")) {
        parts.push(stem.to_string());
    }
    parts
}

/// Each file's imports of other files (see the module documentation).
fn import_graph(sources: &Sources) -> Graph {
    let mut graph = Graph::new();
    for (module, (name, text)) in sources {
        let mut to = BTreeSet::new();
        for path in paths_in(module, &tokens(&strip(text)), sources) {
            // The deepest module file the path names.
            let target = (0..=path.len())
                .rev()
                .find_map(|n| sources.get(&path[..n]))
                .map(|(n, _)| n.clone());
            if let Some(t) = target
                && &t != name
            {
                to.insert(t);
            }
        }
        graph.insert(name.clone(), to);
    }
    graph
}

/// The text with comments, strings and character literals blanked out
/// (lines kept).
fn strip(text: &str) -> String {
    let c: Vec<char> = text.chars().collect();
    let mut out = String::with_capacity(text.len());
    let mut i = 0;
    let blank = |out: &mut String, s: &[char]| {
        for &ch in s {
            out.push(if ch == '\n' { '\n' } else { ' ' });
        }
    };
    while i < c.len() {
        let rest = &c[i..];
        let at = |k: usize| rest.get(k).copied().unwrap_or('\0');
        let ident_before = i > 0 && (c[i - 1].is_alphanumeric() || c[i - 1] == '_');
        let len = if at(0) == '/' && at(1) == '/' {
            rest.iter().position(|&x| x == '\n').unwrap_or(rest.len())
        } else if at(0) == '/' && at(1) == '*' {
            let mut depth = 0;
            let mut k = 0;
            loop {
                if k + 1 >= rest.len() {
                    break rest.len();
                }
                if rest[k] == '/' && rest[k + 1] == '*' {
                    depth += 1;
                    k += 2;
                } else if rest[k] == '*' && rest[k + 1] == '/' {
                    depth -= 1;
                    k += 2;
                    if depth == 0 {
                        break k;
                    }
                } else {
                    k += 1;
                }
            }
        } else if !ident_before && (at(0) == 'r' || (at(0) == 'b' && at(1) == 'r')) && {
            let k = if at(0) == 'r' { 1 } else { 2 };
            let hashes = rest[k..].iter().take_while(|&&x| x == '#').count();
            rest.get(k + hashes) == Some(&'"')
        } {
            // A raw string: r"..", r#".."#, br"..".
            let k = if at(0) == 'r' { 1 } else { 2 };
            let hashes = rest[k..].iter().take_while(|&&x| x == '#').count();
            let body = k + hashes + 1;
            let close: Vec<char> = std::iter::once('"')
                .chain(std::iter::repeat_n('#', hashes))
                .collect();
            (body..rest.len())
                .find(|&j| rest[j..].starts_with(&close))
                .map_or(rest.len(), |j| j + close.len())
        } else if at(0) == '"' || (!ident_before && at(0) == 'b' && at(1) == '"') {
            let mut k = if at(0) == 'b' { 2 } else { 1 };
            while k < rest.len() && rest[k] != '"' {
                k += if rest[k] == '\\' { 2 } else { 1 };
            }
            (k + 1).min(rest.len())
        } else if at(0) == '\'' || (!ident_before && at(0) == 'b' && at(1) == '\'') {
            // A character ('x', '\n', '\u{..}', b'x') or a lifetime ('a).
            let k = if at(0) == 'b' { 2 } else { 1 };
            if at(k) == '\\' {
                rest[(k + 2).min(rest.len())..]
                    .iter()
                    .position(|&x| x == '\'')
                    .map_or(rest.len(), |p| k + 2 + p + 1)
            } else if at(k + 1) == '\'' {
                k + 2
            } else {
                0
            }
        } else {
            0
        };
        if len == 0 {
            out.push(c[i]);
            i += 1;
        } else {
            blank(&mut out, &rest[..len]);
            i += len;
        }
    }
    out
}

#[derive(Clone, Debug, PartialEq)]
enum Tok {
    Ident(String),
    /// `::`
    Sep,
    Punct(char),
}

fn tokens(text: &str) -> Vec<Tok> {
    let c: Vec<char> = text.chars().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < c.len() {
        if c[i].is_alphabetic() || c[i] == '_' {
            let start = i;
            while i < c.len() && (c[i].is_alphanumeric() || c[i] == '_') {
                i += 1;
            }
            let word: String = c[start..i].iter().collect();
            // Raw identifiers (`r#type`).
            if word == "r" && c.get(i) == Some(&'#') {
                i += 1;
                continue;
            }
            out.push(Tok::Ident(word));
        } else if c[i] == ':' && c.get(i + 1) == Some(&':') {
            out.push(Tok::Sep);
            i += 2;
        } else {
            if !c[i].is_whitespace() {
                out.push(Tok::Punct(c[i]));
            }
            i += 1;
        }
    }
    out
}

/// The absolute module paths (below the crate root) named in a file of
/// module `module`: in its `use` items and in its code.
fn paths_in(module: &ModPath, toks: &[Tok], sources: &Sources) -> Vec<ModPath> {
    let ident = |i: usize| match toks.get(i) {
        Some(Tok::Ident(s)) => Some(s.as_str()),
        _ => None,
    };
    // The file's inline modules, as a stack of (path, brace depth).
    let mut scopes: Vec<(ModPath, usize)> = vec![(module.clone(), 0)];
    let mut depth = 0usize;
    let mut out = Vec::new();
    let mut i = 0;
    while i < toks.len() {
        let here = scopes.last().unwrap().0.clone();
        match &toks[i] {
            Tok::Punct('{') => depth += 1,
            Tok::Punct('}') => {
                depth = depth.saturating_sub(1);
                if scopes.len() > 1 && scopes.last().unwrap().1 == depth {
                    scopes.pop();
                }
            }
            Tok::Ident(w) if w == "mod" => {
                if let (Some(name), Some(Tok::Punct('{'))) = (ident(i + 1), toks.get(i + 2)) {
                    let mut inner = here.clone();
                    inner.push(name.to_string());
                    scopes.push((inner, depth));
                    depth += 1;
                    i += 3;
                    continue;
                }
            }
            Tok::Ident(w) if w == "use" => {
                let mut leaves = Vec::new();
                i = use_tree(toks, i + 1, Vec::new(), &mut leaves);
                for leaf in leaves {
                    out.extend(absolute(&here, &leaf, sources));
                }
                continue;
            }
            // A path in the code: into the crate, or into a child module.
            Tok::Ident(w)
                if toks.get(i + 1) == Some(&Tok::Sep) && (i == 0 || toks[i - 1] != Tok::Sep) =>
            {
                let mut path = vec![w.clone()];
                let mut k = i + 1;
                while toks.get(k) == Some(&Tok::Sep) {
                    match ident(k + 1) {
                        Some(s) => path.push(s.to_string()),
                        None => break,
                    }
                    k += 2;
                }
                out.extend(absolute(&here, &path, sources));
                i = k;
                continue;
            }
            _ => {}
        }
        i += 1;
    }
    out
}

/// Reads a use tree from `toks[i]` on (after `use`, or inside its
/// braces), with `prefix` so far; pushes each leaf's path (a glob's path
/// ends at its module). Returns where the tree ends.
fn use_tree(
    toks: &[Tok],
    mut i: usize,
    mut prefix: Vec<String>,
    leaves: &mut Vec<Vec<String>>,
) -> usize {
    loop {
        match toks.get(i) {
            Some(Tok::Ident(w)) if w == "as" => i += 2,
            Some(Tok::Ident(w)) => {
                if w != "self" || prefix.is_empty() {
                    prefix.push(w.clone());
                }
                i += 1;
            }
            Some(Tok::Sep) => i += 1,
            Some(Tok::Punct('{')) => {
                i += 1;
                loop {
                    if toks.get(i) == Some(&Tok::Punct('}')) {
                        i += 1;
                        break;
                    }
                    i = use_tree(toks, i, prefix.clone(), leaves);
                    match toks.get(i) {
                        Some(Tok::Punct(',')) => i += 1,
                        Some(Tok::Punct('}')) => {
                            i += 1;
                            break;
                        }
                        _ => break,
                    }
                }
                return if toks.get(i) == Some(&Tok::Punct(';')) {
                    i + 1
                } else {
                    i
                };
            }
            Some(Tok::Punct('*')) => i += 1,
            _ => {
                if !prefix.is_empty() {
                    leaves.push(prefix);
                }
                return if toks.get(i) == Some(&Tok::Punct(';')) {
                    i + 1
                } else {
                    i
                };
            }
        }
    }
}

/// A path as written in module `here`, made absolute; `None` for a path
/// out of the crate (`std::…`, `sray_engine::…`).
fn absolute(here: &ModPath, path: &[String], sources: &Sources) -> Option<ModPath> {
    let mut base = here.clone();
    let mut rest = path;
    match path.first().map(String::as_str) {
        Some("crate") => {
            base.clear();
            rest = &path[1..];
        }
        Some("super" | "self") => {
            while let Some(s) = rest.first() {
                match s.as_str() {
                    "super" => {
                        base.pop();
                    }
                    "self" => {}
                    _ => break,
                }
                rest = &rest[1..];
            }
        }
        // A child module of this one (`mod x;` ... `use x::Y;`).
        Some(first) => {
            let mut child = here.clone();
            child.push(first.to_string());
            if !sources.contains_key(&child) {
                return None;
            }
        }
        None => return None,
    }
    base.extend(rest.iter().cloned());
    Some(base)
}

/// A loop of imports (its first file again at its end), if any.
fn find_cycle(graph: &Graph) -> Option<Vec<String>> {
    #[derive(Clone, Copy, PartialEq)]
    enum Mark {
        New,
        Open,
        Done,
    }
    fn visit<'g>(
        n: &'g str,
        graph: &'g Graph,
        marks: &mut BTreeMap<&'g str, Mark>,
        stack: &mut Vec<&'g str>,
    ) -> Option<Vec<String>> {
        marks.insert(n, Mark::Open);
        stack.push(n);
        for m in graph.get(n).into_iter().flatten() {
            match marks.get(m.as_str()).copied().unwrap_or(Mark::New) {
                Mark::Open => {
                    let at = stack.iter().position(|s| s == m).unwrap();
                    let mut cycle: Vec<String> =
                        stack[at..].iter().map(|s| s.to_string()).collect();
                    cycle.push(m.clone());
                    return Some(cycle);
                }
                Mark::New => {
                    if let Some(c) = visit(m, graph, marks, stack) {
                        return Some(c);
                    }
                }
                Mark::Done => {}
            }
        }
        stack.pop();
        marks.insert(n, Mark::Done);
        None
    }
    let mut marks = BTreeMap::new();
    for n in graph.keys() {
        if marks.get(n.as_str()).copied().unwrap_or(Mark::New) == Mark::New
            && let Some(c) = visit(n, graph, &mut marks, &mut Vec::new())
        {
            return Some(c);
        }
    }
    None
}

/// Each file and the files it imports, a line each.
fn listing(graph: &Graph) -> String {
    graph
        .iter()
        .map(|(f, to)| {
            format!(
                "{f} -> {}",
                to.iter().cloned().collect::<Vec<_>>().join(", ")
            )
        })
        .collect::<Vec<_>>()
        .join("\n")
}
