//! OFF (Geomview's object file format) and its variants COFF (a colour
//! per vertex), NOFF (a normal per vertex) and CNOFF: polygons of any
//! number of vertices, `#` comments anywhere, a colour per face (RGB or
//! RGBA, integers 0-255 or reals 0-1) as the face's diffuse colour. A face
//! without a colour of its own in a COFF file takes the mean of its
//! vertices' colours. The keyword may be missing (the file starts with its
//! counts), as Geomview allows. Texture coordinates (ST), 4D, nD and
//! binary OFF are refused with a message saying so.

use super::builder::{MeshBuilder, MeshSummary, NO_INDEX, NO_MATERIAL};
use super::text::{LineReader, component, coordinate, declared_up, integer, real, shown, words};
use super::{MeshOptions, Warnings, report_summary};
use crate::error::Error;
use crate::input::Wrapping;
use crate::progress::Progress;
use crate::scene::SceneSink;
use crate::shapes::MAX_POLYGON_VERTICES;
use std::io::BufRead;
use std::path::Path;

/// Longest line accepted: a face of the most vertices sray takes, with
/// room to spare.
pub const MAX_LINE_BYTES: usize = 1 << 20;

/// Reads the OFF file at `path` (gzip or zstd wrapped or not) into `sink`.
pub fn read_off(
    path: &Path,
    sink: &mut dyn SceneSink,
    progress: &dyn Progress,
    opts: &MeshOptions,
) -> Result<MeshSummary, Error> {
    let input = crate::input::open(path, progress)?;
    read_off_from(input.reader, input.wrapping, path, sink, progress, opts)
}

/// The next line that has words once its comment is cut off, as a copy;
/// `None` at the end of the file. Comments may declare an up axis.
fn content<R: BufRead>(
    lines: &mut LineReader<R>,
    up: &mut Option<[f64; 3]>,
) -> Result<Option<Vec<u8>>, Error> {
    while let Some(l) = lines.next_line()? {
        let (body, comment) = match l.iter().position(|&b| b == b'#') {
            Some(i) => (&l[..i], Some(&l[i + 1..])),
            None => (l, None),
        };
        if let Some(c) = comment
            && up.is_none()
        {
            *up = declared_up(c);
        }
        if words(body).next().is_some() {
            return Ok(Some(body.to_vec()));
        }
    }
    Ok(None)
}

/// A colour given as integers 0-255 or reals 0-1.
fn color(toks: &[&[u8]]) -> Result<[f32; 3], String> {
    let reals = toks
        .iter()
        .any(|t| t.iter().any(|b| matches!(b, b'.' | b'e' | b'E')));
    let mut c = [0.0f32; 3];
    for k in 0..3 {
        let v = real(toks[k])?;
        c[k] = component(if reals { v } else { v / 255.0 }, "colour")?;
    }
    Ok(c)
}

/// Reads OFF text from `src`; `name` is used in messages.
pub fn read_off_from<R: BufRead>(
    src: R,
    wrapping: Wrapping,
    name: &Path,
    sink: &mut dyn SceneSink,
    progress: &dyn Progress,
    opts: &MeshOptions,
) -> Result<MeshSummary, Error> {
    let mut lines = LineReader::new(src, name, wrapping, MAX_LINE_BYTES);
    let mut up = None;
    let mut warnings = Warnings::default();
    let Some(first) = content(&mut lines, &mut up)? else {
        return Err(lines.err("the file is empty: no OFF header"));
    };
    let ws: Vec<&[u8]> = words(&first).collect();
    let (mut vertex_color, mut vertex_normal) = (false, false);
    let mut counts_line: Vec<Vec<u8>> = Vec::new();
    if ws[0].ends_with(b"OFF") {
        let prefix = &ws[0][..ws[0].len() - 3];
        match prefix {
            b"" => {}
            b"C" => vertex_color = true,
            b"N" => vertex_normal = true,
            b"CN" | b"NC" => (vertex_color, vertex_normal) = (true, true),
            p => {
                let what = if p.starts_with(b"ST") {
                    "texture coordinates"
                } else if p.contains(&b'4') {
                    "four-dimensional vertices"
                } else if p.ends_with(b"n") {
                    "n-dimensional vertices"
                } else {
                    "an unknown variant"
                };
                return Err(lines.err(format!(
                    "'{}' is not supported ({what}); sray reads OFF, COFF, NOFF and CNOFF",
                    shown(ws[0])
                )));
            }
        }
        if ws.get(1) == Some(&&b"BINARY"[..]) {
            return Err(lines.err("binary OFF is not supported; sray reads OFF text"));
        }
        counts_line.extend(ws[1..].iter().map(|w| w.to_vec()));
    } else if integer(ws[0]).is_ok() {
        // No keyword: the counts come first.
        counts_line.extend(ws.iter().map(|w| w.to_vec()));
    } else {
        return Err(lines.err(format!(
            "not an OFF file: it starts with '{}', not OFF, COFF, NOFF or CNOFF",
            shown(ws[0])
        )));
    }
    if counts_line.is_empty() {
        let Some(l) = content(&mut lines, &mut up)? else {
            return Err(lines.err("the file ends before the vertex and face counts"));
        };
        counts_line.extend(words(&l).map(|w| w.to_vec()));
    }
    let count_line = lines.line();
    if counts_line.len() < 2 || counts_line.len() > 3 {
        return Err(lines.err(
            "the counts line must hold the numbers of vertices, faces and (optionally) edges",
        ));
    }
    let count = |t: &[u8], what: &str| -> Result<u64, Error> {
        match integer(t) {
            Ok(v) if v >= 0 => Ok(v as u64),
            _ => Err(lines.err(format!(
                "the number of {what} '{}' is not a whole number",
                shown(t)
            ))),
        }
    };
    let nv = count(&counts_line[0], "vertices")?;
    let nf = count(&counts_line[1], "faces")?;
    if let Some(e) = counts_line.get(2) {
        count(e, "edges")?;
    }
    let mut b = MeshBuilder::new(name, opts.memory, opts.spill_dir.as_deref(), true, progress);
    let truncated = |lines: &LineReader<R>, i: u64, n: u64, what: &str| {
        lines.err(format!(
            "the file ends after {i} of the {n} {what} its header (line {count_line}) declares: truncated"
        ))
    };
    let need = 3 + if vertex_normal { 3 } else { 0 };
    for i in 0..nv {
        let Some(l) = content(&mut lines, &mut up)? else {
            return Err(truncated(&lines, i, nv, "vertices"));
        };
        let ws: Vec<&[u8]> = words(&l).collect();
        let colors_given = ws.len().saturating_sub(need);
        if ws.len() < need || (vertex_color && !(3..=4).contains(&colors_given)) {
            return Err(lines.err(format!(
                "vertex {i} has {} values; {} takes {}",
                ws.len(),
                if vertex_color {
                    "COFF"
                } else {
                    "this OFF file"
                },
                match (vertex_color, vertex_normal) {
                    (false, false) => "x y z",
                    (false, true) => "x y z nx ny nz",
                    (true, false) => "x y z r g b [a]",
                    (true, true) => "x y z nx ny nz r g b [a]",
                }
            )));
        }
        if !vertex_color && ws.len() > need {
            warnings.add("extra values on vertex lines ignored", || {
                format!("line {}", lines.line())
            });
        }
        let bad = |m: String| lines.err(format!("vertex {i}: {m}"));
        let mut p = [0.0; 3];
        for k in 0..3 {
            p[k] = real(ws[k]).and_then(coordinate).map_err(bad)?;
        }
        b.add_vertex(p)?;
        if vertex_normal {
            let mut n = [0.0f32; 3];
            for k in 0..3 {
                n[k] = real(ws[3 + k])
                    .and_then(|v| component(v, "normal"))
                    .map_err(bad)?;
            }
            b.add_normal(n)?;
        }
        if vertex_color {
            b.add_color(color(&ws[need..need + 3]).map_err(bad)?)?;
        }
    }
    if let Some(up) = up {
        b.declare_up(up);
    }
    let mut corners: Vec<(u64, u64)> = Vec::new();
    for i in 0..nf {
        let Some(l) = content(&mut lines, &mut up)? else {
            return Err(truncated(&lines, i, nf, "faces"));
        };
        let ws: Vec<&[u8]> = words(&l).collect();
        let bad = |m: String| lines.err(format!("face {i}: {m}"));
        let n = integer(ws[0]).map_err(bad)?;
        if n < 3 {
            return Err(bad(format!("{n} vertices; at least 3 are needed")));
        }
        if n > MAX_POLYGON_VERTICES as i64 {
            return Err(bad(format!(
                "{n} vertices, more than the limit of {MAX_POLYGON_VERTICES}"
            )));
        }
        let n = n as usize;
        if ws.len() < 1 + n {
            return Err(bad(format!(
                "it lists {} vertex indices, its count says {n}",
                ws.len() - 1
            )));
        }
        corners.clear();
        for t in &ws[1..=n] {
            let x = integer(t).map_err(bad)?;
            if x < 0 || x as u64 >= nv {
                return Err(bad(format!(
                    "vertex index {x} is out of range (the file has {nv} vertices)"
                )));
            }
            corners.push((x as u64, NO_INDEX));
        }
        let rest = &ws[1 + n..];
        let c = match rest.len() {
            0 => None,
            1 => {
                warnings.add("colour-map indices of faces ignored", || {
                    format!("line {}", lines.line())
                });
                None
            }
            3 | 4 => Some(color(rest).map_err(bad)?),
            k => {
                return Err(bad(format!(
                    "{k} values after the vertex indices; a colour is 3 or 4 (or a colour-map index)"
                )));
            }
        };
        b.add_face(&corners, NO_MATERIAL, c)?;
    }
    if content(&mut lines, &mut up)?.is_some() {
        warnings.add("data after the last face ignored", || {
            format!("line {}", lines.line())
        });
    }
    warnings.report(name, progress);
    let summary = b.finish(sink)?;
    report_summary(name, &summary, progress);
    Ok(summary)
}
