//! Wavefront OBJ: `v` (positions; a fourth weight or trailing colour
//! values are ignored), `vn` (normals: a face whose every corner has one is
//! shaded smoothly), `vt` (texture coordinates, for the faces of a
//! material with a `map_Kd` texture: such faces become textured
//! triangles; OBJ's v runs up the image), `f` in all four
//! forms (`v`, `v/vt`, `v//vn`, `v/vt/vn`) with positive or negative
//! (relative) indices and any number of corners, `o`/`g`/`s` (ignored),
//! `usemtl` with the materials of `mtllib` libraries (see [`super::mtl`]
//! for how they map to NFF's model; a missing library is a warning, not an
//! error), and lines continued with a backslash. Indices refer to the
//! vertices defined before the face, as the format intends. Lines, points
//! and free-form geometry are skipped with a warning.

use super::builder::{MeshBuilder, MeshSummary, NO_INDEX, NO_MATERIAL};
use super::text::{LineReader, component, coordinate, declared_up, real, shown, words};
use super::{MeshOptions, Warnings, report_summary};
use crate::error::Error;
use crate::input::Wrapping;
use crate::progress::Progress;
use crate::scene::{SceneSink, TextureBinding, TextureImage};
use crate::shapes::MAX_POLYGON_VERTICES;
use std::collections::HashMap;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};

/// Longest (joined) line accepted.
pub const MAX_LINE_BYTES: usize = 1 << 20;

/// Reads the OBJ file at `path` (gzip or zstd wrapped or not) into `sink`,
/// with material libraries beside it.
pub fn read_obj(
    path: &Path,
    sink: &mut dyn SceneSink,
    progress: &dyn Progress,
    opts: &MeshOptions,
) -> Result<MeshSummary, Error> {
    let input = crate::input::open(path, progress)?;
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    read_obj_from(
        input.reader,
        input.wrapping,
        path,
        Some(&dir),
        sink,
        progress,
        opts,
    )
}

/// Statements of the format that sray does not draw.
const SKIPPED: &[&[u8]] = &[
    b"vp",
    b"cstype",
    b"deg",
    b"bmat",
    b"step",
    b"curv",
    b"curv2",
    b"surf",
    b"parm",
    b"trim",
    b"hole",
    b"scrv",
    b"sp",
    b"end",
    b"con",
    b"bevel",
    b"c_interp",
    b"d_interp",
    b"lod",
    b"maplib",
    b"usemap",
    b"shadow_obj",
    b"trace_obj",
    b"ctech",
    b"stech",
    b"call",
    b"csh",
];

/// Reads the image at `path` for the builder, checked to decode; a
/// missing or unreadable image is a warning (its faces are untextured).
fn read_image(path: &Path, b: &mut MeshBuilder<'_>, warnings: &mut Warnings) -> Option<u32> {
    let what = path.display().to_string();
    let bytes = match std::fs::read(path) {
        Ok(bytes) => bytes,
        Err(e) => {
            warnings.add(
                "a map_Kd texture not found; its faces are untextured",
                || format!("{what}: {e}"),
            );
            return None;
        }
    };
    if let Err(e) = crate::texture::decode_rgba8(&bytes, &what) {
        warnings.add(
            "a map_Kd texture that does not decode; its faces are untextured",
            || e.to_string(),
        );
        return None;
    }
    Some(b.add_image(TextureImage::encoded(what, bytes)))
}

/// Reads OBJ text from `src`; `name` is used in messages. Material
/// libraries are looked for in `mtl_dir` (none are read if `None`).
pub fn read_obj_from<R: BufRead>(
    src: R,
    wrapping: Wrapping,
    name: &Path,
    mtl_dir: Option<&Path>,
    sink: &mut dyn SceneSink,
    progress: &dyn Progress,
    opts: &MeshOptions,
) -> Result<MeshSummary, Error> {
    let mut lines = LineReader::new(src, name, wrapping, MAX_LINE_BYTES);
    let mut b = MeshBuilder::new(
        name,
        opts.memory,
        opts.spill_dir.as_deref(),
        false,
        progress,
    );
    let mut warnings = Warnings::default();
    let mut materials: HashMap<String, u32> = HashMap::new();
    let mut libraries: Vec<PathBuf> = Vec::new();
    let mut material = NO_MATERIAL;
    let mut corners: Vec<(u64, u64, u64)> = Vec::new();
    // The images `map_Kd` names, read once each: the builder's number.
    let mut images: HashMap<PathBuf, Option<u32>> = HashMap::new();
    let mut joined: Vec<u8> = Vec::new();
    let mut line: Vec<u8> = Vec::new();
    loop {
        {
            let Some(l) = lines.next_line()? else { break };
            // A backslash at the end continues the line.
            if let Some(head) = l.strip_suffix(b"\\") {
                joined.extend_from_slice(head);
                joined.push(b' ');
                if joined.len() > MAX_LINE_BYTES {
                    return Err(lines.err(format!(
                        "continued line is longer than {MAX_LINE_BYTES} bytes"
                    )));
                }
                continue;
            }
            line.clear();
            line.append(&mut joined);
            line.extend_from_slice(l);
        }
        let (body, comment) = match line.iter().position(|&c| c == b'#') {
            Some(i) => (&line[..i], Some(&line[i + 1..])),
            None => (&line[..], None),
        };
        if let Some(c) = comment
            && let Some(up) = declared_up(c)
        {
            b.declare_up(up);
        }
        let mut w = words(body);
        let Some(key) = w.next() else {
            continue;
        };
        let at = lines.line();
        match key {
            b"v" => {
                let mut p = [0.0; 3];
                let mut k = 0;
                for t in w {
                    if k < 3 {
                        p[k] = real(t).and_then(coordinate).map_err(|m| lines.err(m))?;
                    } else if k >= 7 {
                        return Err(
                            lines.err("'v' takes at most 7 numbers (x y z [w] or x y z r g b)")
                        );
                    } else {
                        real(t).map_err(|m| lines.err(m))?;
                    }
                    k += 1;
                }
                if k < 3 {
                    return Err(lines.err(format!("'v' needs 3 coordinates, found {k}")));
                }
                b.add_vertex(p)?;
            }
            b"vn" => {
                let mut n = [0.0f32; 3];
                let mut k = 0;
                for t in w {
                    if k == 3 {
                        return Err(lines.err("'vn' takes 3 numbers, found more"));
                    }
                    n[k] = real(t)
                        .and_then(|v| component(v, "normal"))
                        .map_err(|m| lines.err(m))?;
                    k += 1;
                }
                if k < 3 {
                    return Err(lines.err(format!("'vn' needs 3 numbers, found {k}")));
                }
                b.add_normal(n)?;
            }
            b"vt" => {
                let mut k = 0;
                let mut uv = [0f32; 2];
                for t in w {
                    if k == 3 {
                        return Err(lines.err("'vt' takes at most 3 numbers"));
                    }
                    let x = real(t).map_err(|m| lines.err(m))?;
                    if k < 2 {
                        uv[k] = if x.is_finite() { x as f32 } else { 0.0 };
                    }
                    k += 1;
                }
                if k == 0 {
                    return Err(lines.err("'vt' needs at least 1 number"));
                }
                // sray's (glTF's) v runs down the image.
                b.add_uv([uv[0], 1.0 - uv[1]])?;
            }
            b"f" | b"fo" => {
                corners.clear();
                let (nv, nn, nt) = (b.vertex_count(), b.normal_count(), b.uv_count());
                for t in w {
                    if corners.len() == MAX_POLYGON_VERTICES {
                        return Err(lines.err(format!(
                            "a face of more than {MAX_POLYGON_VERTICES} vertices"
                        )));
                    }
                    let mut parts = t.split(|&c| c == b'/');
                    let v = parts.next().unwrap_or(b"");
                    let vt = parts.next();
                    let vn = parts.next();
                    if parts.next().is_some() {
                        return Err(lines.err(format!(
                            "'{}' is not a face corner (v, v/vt, v//vn or v/vt/vn)",
                            shown(t)
                        )));
                    }
                    let v = index(v, nv, "vertex").map_err(|m| lines.err(m))?;
                    let t = match vt.filter(|s| !s.is_empty()) {
                        Some(vt) => {
                            index(vt, nt, "texture coordinate").map_err(|m| lines.err(m))?
                        }
                        None => NO_INDEX,
                    };
                    let n = match vn.filter(|s| !s.is_empty()) {
                        Some(vn) => index(vn, nn, "normal").map_err(|m| lines.err(m))?,
                        None => NO_INDEX,
                    };
                    corners.push((v, n, t));
                }
                if corners.len() < 3 {
                    return Err(lines.err(format!(
                        "a face of {} vertices; at least 3 are needed",
                        corners.len()
                    )));
                }
                b.add_face_uv(&corners, material, None)?;
            }
            b"usemtl" => {
                let n = String::from_utf8_lossy(body.trim_ascii()[6..].trim_ascii()).into_owned();
                material = match materials.get(&n) {
                    Some(&m) => m,
                    None => {
                        warnings.add(
                            "'usemtl' of a material no library defines; its faces are grey",
                            || format!("'{n}' at line {at}"),
                        );
                        NO_MATERIAL
                    }
                };
            }
            b"mtllib" => {
                let rest = body.trim_ascii()[6..].trim_ascii();
                let Some(dir) = mtl_dir else {
                    warnings.add("material libraries not read", || format!("line {at}"));
                    continue;
                };
                // A name may hold spaces: the whole rest first, then each
                // word as a name of its own.
                let whole = String::from_utf8_lossy(rest).into_owned();
                let names: Vec<String> = if dir.join(&whole).is_file() {
                    vec![whole]
                } else {
                    words(rest)
                        .map(|w| String::from_utf8_lossy(w).into_owned())
                        .collect()
                };
                for n in names {
                    let path = dir.join(&n);
                    if libraries.contains(&path) {
                        continue;
                    }
                    libraries.push(path.clone());
                    let file = match std::fs::File::open(&path) {
                        Ok(f) => f,
                        Err(e) => {
                            warnings
                                .add("material library not found; its materials are grey", || {
                                    format!("{}: {e}, named at line {at}", path.display())
                                });
                            continue;
                        }
                    };
                    let mut lib_warnings: Vec<(String, u64)> = Vec::new();
                    let mats = super::mtl::read_mtl(
                        BufReader::new(file),
                        &path,
                        &mut |w: &str, l: u64| lib_warnings.push((w.to_string(), l)),
                    )?;
                    for (w, l) in lib_warnings {
                        warnings.add(&w, || format!("{}:{l}", path.display()));
                    }
                    let lib_dir = path.parent().unwrap_or(dir);
                    for (mname, mut m, map) in mats {
                        if materials.len() >= super::mtl::MAX_LIBRARY_MATERIALS * 4 {
                            return Err(lines.err("too many materials in the libraries"));
                        }
                        if materials.contains_key(&mname) {
                            continue;
                        }
                        if let Some(map) = map {
                            let file = lib_dir.join(map.file.replace('\\', "/"));
                            let image = match images.get(&file) {
                                Some(&i) => i,
                                None => {
                                    let i = read_image(&file, &mut b, &mut warnings);
                                    images.insert(file, i);
                                    i
                                }
                            };
                            m.texture = image.map(|image| TextureBinding {
                                image,
                                sampler: map.sampler,
                                transform: map.transform,
                                cutoff: 0.0,
                                alpha: 1.0,
                            });
                        }
                        materials.insert(mname, b.add_material(m));
                    }
                }
            }
            b"o" | b"g" | b"s" | b"mg" => {}
            b"l" | b"p" => warnings.add("lines and points ignored (no surface to draw)", || {
                format!("line {at}")
            }),
            k if SKIPPED.contains(&k) => warnings.add(
                "free-form geometry and rendering statements ignored",
                || format!("'{}' at line {at}", shown(k)),
            ),
            k => warnings.add("unknown statements ignored", || {
                format!("'{}' at line {at}", shown(k))
            }),
        }
    }
    if !joined.is_empty() {
        return Err(lines.err("the file ends inside a continued line"));
    }
    warnings.report(name, progress);
    let summary = b.finish(sink)?;
    report_summary(name, &summary, progress);
    Ok(summary)
}

/// An OBJ index (1-based, or negative: relative to the end of the `n`
/// elements defined so far) as a 0-based index.
fn index(t: &[u8], n: u64, what: &str) -> Result<u64, String> {
    let i: i64 = std::str::from_utf8(t)
        .ok()
        .and_then(|s| s.parse().ok())
        .ok_or_else(|| format!("{what} index '{}' is not a whole number", shown(t)))?;
    let r = if i > 0 {
        (i as u64 - 1 < n).then(|| i as u64 - 1)
    } else if i < 0 {
        n.checked_sub(i.unsigned_abs())
    } else {
        return Err(format!("{what} index 0: OBJ indices start at 1"));
    };
    r.ok_or_else(|| format!("{what} index {i} is out of range: {n} are defined before this line"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn indices() {
        assert_eq!(index(b"1", 3, "v"), Ok(0));
        assert_eq!(index(b"3", 3, "v"), Ok(2));
        assert!(index(b"4", 3, "v").is_err());
        assert_eq!(index(b"-1", 3, "v"), Ok(2));
        assert_eq!(index(b"-3", 3, "v"), Ok(0));
        assert!(index(b"-4", 3, "v").is_err());
        assert!(index(b"0", 3, "v").is_err());
        assert!(index(b"x", 3, "v").is_err());
        assert!(index(b"-9223372036854775808", 3, "v").is_err());
    }
}
