//! PLY (the Stanford polygon file format): ASCII, binary little-endian and
//! binary big-endian.
//!
//! Read: the `vertex` element's `x`, `y`, `z` of any scalar type, its
//! `nx`, `ny`, `nz` (all three: smooth shading) and `red`, `green`, `blue`
//! (all three: the faces' colour, averaged); the `face` element's
//! `vertex_indices` (or `vertex_index`) list of any count and index types,
//! polygons of any number of vertices, and its `red`, `green`, `blue`; the
//! `tristrips` element's `vertex_indices` list (strips separated by -1, as
//! Cyberware and older Stanford files write them).
//!
//! Textures, as scanning and photogrammetry tools write them: the image a
//! `comment TextureFile NAME` names (beside the file), sampled at the
//! vertices' `u v` (or `s t`, `texture_u texture_v`, `texture_s
//! texture_t`) or at the faces' per-corner `texcoord` list; the faces
//! then become textured triangles (v runs up the image, as OpenGL's).
//!
//! Every other element and property is skipped by its declared type;
//! comments and `obj_info` lines are read for a declared up axis and the
//! texture file only.

use super::builder::{MeshBuilder, MeshSummary, NO_INDEX, NO_MATERIAL};
use super::text::{LineReader, coordinate, declared_up, shown, words};
use super::{MeshOptions, Warnings, report_summary};
use crate::error::{At, Error};
use crate::input::{Wrapping, read_error};
use crate::progress::Progress;
use crate::scene::{Material, SceneSink, TextureBinding, TextureImage};
use crate::shapes::MAX_POLYGON_VERTICES;
use std::io::{BufRead, ErrorKind};
use std::path::{Path, PathBuf};

/// Longest header line, and most header lines, elements and properties.
const MAX_HEADER_LINE: usize = 64 << 10;
const MAX_HEADER_LINES: u64 = 100_000;
const MAX_ELEMENTS: usize = 1024;
const MAX_PROPERTIES: usize = 1024;
/// Longest value in ASCII data.
const MAX_TOKEN: usize = 128;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(s: &[u8]) -> Option<Scalar> {
        Some(match s {
            b"char" | b"int8" => Scalar::I8,
            b"uchar" | b"uint8" => Scalar::U8,
            b"short" | b"int16" => Scalar::I16,
            b"ushort" | b"uint16" => Scalar::U16,
            b"int" | b"int32" => Scalar::I32,
            b"uint" | b"uint32" => Scalar::U32,
            b"float" | b"float32" => Scalar::F32,
            b"double" | b"float64" => Scalar::F64,
            _ => return None,
        })
    }
    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }
    fn is_integer(self) -> bool {
        !matches!(self, Scalar::F32 | Scalar::F64)
    }
    fn name(self) -> &'static str {
        match self {
            Scalar::I8 => "char",
            Scalar::U8 => "uchar",
            Scalar::I16 => "short",
            Scalar::U16 => "ushort",
            Scalar::I32 => "int",
            Scalar::U32 => "uint",
            Scalar::F32 => "float",
            Scalar::F64 => "double",
        }
    }
    /// The range of an integer type.
    fn range(self) -> (f64, f64) {
        match self {
            Scalar::I8 => (-128.0, 127.0),
            Scalar::U8 => (0.0, 255.0),
            Scalar::I16 => (-32768.0, 32767.0),
            Scalar::U16 => (0.0, 65535.0),
            Scalar::I32 => (-2147483648.0, 2147483647.0),
            Scalar::U32 => (0.0, 4294967295.0),
            Scalar::F32 | Scalar::F64 => (f64::NEG_INFINITY, f64::INFINITY),
        }
    }
    /// A colour component of this type as 0 to 1.
    fn unit(self, v: f64) -> f64 {
        if self.is_integer() {
            v / self.range().1
        } else {
            v
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum PropType {
    Scalar(Scalar),
    List { count: Scalar, item: Scalar },
}

#[derive(Clone, Debug)]
struct Property {
    name: String,
    ty: PropType,
}

#[derive(Clone, Debug)]
struct Element {
    name: String,
    count: u64,
    props: Vec<Property>,
    line: u64,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Encoding {
    Ascii,
    Little,
    Big,
}

struct Header {
    encoding: Encoding,
    elements: Vec<Element>,
    up: Option<[f64; 3]>,
    /// The first `comment TextureFile` name, and how many there were.
    texture_file: Option<String>,
    texture_files: usize,
    lines: u64,
    bytes: u64,
}

/// Reads the PLY file at `path` (gzip or zstd wrapped or not) into `sink`.
pub fn read_ply(
    path: &Path,
    sink: &mut dyn SceneSink,
    progress: &dyn Progress,
    opts: &MeshOptions,
) -> Result<MeshSummary, Error> {
    let input = crate::input::open(path, progress)?;
    read_ply_from(input.reader, input.wrapping, path, sink, progress, opts)
}

/// Reads PLY data from `src`; `name` is used in messages.
pub fn read_ply_from<R: BufRead>(
    src: R,
    wrapping: Wrapping,
    name: &Path,
    sink: &mut dyn SceneSink,
    progress: &dyn Progress,
    opts: &MeshOptions,
) -> Result<MeshSummary, Error> {
    let mut lines = LineReader::new(src, name, wrapping, MAX_HEADER_LINE);
    let header = read_header(&mut lines)?;
    let src = lines.into_inner();
    let vertex_normals = true;
    let mut b = MeshBuilder::new(
        name,
        opts.memory,
        opts.spill_dir.as_deref(),
        vertex_normals,
        progress,
    );
    if let Some(up) = header.up {
        b.declare_up(up);
    }
    let mut warnings = Warnings::default();
    let material = texture_material(&header, name, &mut b, &mut warnings);
    match header.encoding {
        Encoding::Ascii => {
            let mut d = Ascii {
                src,
                name: name.to_path_buf(),
                wrapping,
                line: header.lines + 1,
                last: header.lines,
                tok: Vec::with_capacity(MAX_TOKEN),
            };
            // The first value's line, past blank lines.
            d.skip_space()?;
            read_body(&header, &mut d, &mut b, material, &mut warnings)?;
        }
        Encoding::Little | Encoding::Big => {
            let mut d = Binary {
                src,
                name: name.to_path_buf(),
                wrapping,
                pos: header.bytes,
                big: header.encoding == Encoding::Big,
            };
            read_body(&header, &mut d, &mut b, material, &mut warnings)?;
        }
    }
    warnings.report(name, progress);
    let summary = b.finish(sink)?;
    report_summary(name, &summary, progress);
    Ok(summary)
}

/// The material of a file whose `comment TextureFile` names an image
/// that reads and decodes (white, the texture its colour), or
/// [`NO_MATERIAL`] with a warning.
fn texture_material(
    h: &Header,
    name: &Path,
    b: &mut MeshBuilder<'_>,
    warnings: &mut Warnings,
) -> u32 {
    let Some(file) = &h.texture_file else {
        return NO_MATERIAL;
    };
    let has =
        |el: &str, f: &dyn Fn(&Element) -> bool| h.elements.iter().any(|e| e.name == el && f(e));
    let uvs = has("vertex", &|e| {
        let slots = vertex_slots(e);
        slots.contains(&Slot::Keep(9)) && slots.contains(&Slot::Keep(10))
    }) || has("face", &|e| face_slots(e).contains(&Slot::TexCoords));
    if !uvs {
        warnings.add(
            "a TextureFile without texture coordinates (vertex u v or face texcoord) is ignored",
            || file.clone(),
        );
        return NO_MATERIAL;
    }
    if h.texture_files > 1 {
        warnings.add(
            "several TextureFile comments: only the first texture is used",
            || file.clone(),
        );
    }
    let path = name
        .parent()
        .unwrap_or(Path::new(""))
        .join(file.replace('\\', "/"));
    let what = path.display().to_string();
    let bytes = match std::fs::read(&path) {
        Ok(b) => b,
        Err(e) => {
            warnings.add(
                "the TextureFile is not found; the mesh is untextured",
                || format!("{what}: {e}"),
            );
            return NO_MATERIAL;
        }
    };
    if let Err(e) = crate::texture::decode_rgba8(&bytes, &what) {
        warnings.add(
            "the TextureFile does not decode; the mesh is untextured",
            || e.to_string(),
        );
        return NO_MATERIAL;
    }
    let image = b.add_image(TextureImage::encoded(what, bytes));
    b.add_material(Material {
        color: [1.0; 3],
        texture: Some(TextureBinding {
            image,
            sampler: Default::default(),
            transform: Default::default(),
            cutoff: 0.0,
            alpha: 1.0,
        }),
        maps: crate::scene::Maps::NONE,
        ..super::NEUTRAL
    })
}

fn read_header<R: BufRead>(lines: &mut LineReader<R>) -> Result<Header, Error> {
    let first = lines.next_line()?.map(|l| l.trim_ascii_end().to_vec());
    if first.as_deref() != Some(b"ply") {
        return Err(lines.err("not a PLY file: the first line must be 'ply'"));
    }
    let mut encoding = None;
    let mut elements: Vec<Element> = Vec::new();
    let mut up = None;
    let (mut texture_file, mut texture_files) = (None, 0);
    loop {
        let Some(line) = lines.next_line()? else {
            return Err(lines.err("the file ends inside the header (no 'end_header')"));
        };
        let line = line.to_vec();
        if lines.line() > MAX_HEADER_LINES {
            return Err(lines.err(format!(
                "the header is longer than {MAX_HEADER_LINES} lines"
            )));
        }
        let mut w = words(&line);
        let Some(key) = w.next() else { continue };
        match key {
            b"comment" | b"obj_info" => {
                let rest = line[key.len()..].trim_ascii();
                if key == b"comment"
                    && let Some(name) = rest.strip_prefix(b"TextureFile")
                    && name.first().is_some_and(u8::is_ascii_whitespace)
                {
                    texture_files += 1;
                    texture_file.get_or_insert_with(|| {
                        String::from_utf8_lossy(name.trim_ascii()).into_owned()
                    });
                } else if up.is_none() {
                    up = declared_up(&line[key.len()..]);
                }
            }
            b"format" => {
                if encoding.is_some() {
                    return Err(lines.err("a second 'format' line"));
                }
                let e = match w.next() {
                    Some(b"ascii") => Encoding::Ascii,
                    Some(b"binary_little_endian") => Encoding::Little,
                    Some(b"binary_big_endian") => Encoding::Big,
                    Some(other) => {
                        return Err(lines.err(format!(
                            "unknown PLY format '{}' (ascii, binary_little_endian or binary_big_endian)",
                            shown(other)
                        )));
                    }
                    None => return Err(lines.err("'format' needs a format and a version")),
                };
                match w.next() {
                    Some(b"1.0" | b"1") => {}
                    Some(v) => {
                        return Err(lines.err(format!(
                            "PLY version '{}' is not supported (1.0 is)",
                            shown(v)
                        )));
                    }
                    None => return Err(lines.err("'format' needs a version (1.0)")),
                }
                encoding = Some(e);
            }
            b"element" => {
                let (Some(n), Some(c), None) = (w.next(), w.next(), w.next()) else {
                    return Err(lines.err("'element' takes a name and a count"));
                };
                let count: u64 = std::str::from_utf8(c)
                    .ok()
                    .and_then(|s| s.parse().ok())
                    .ok_or_else(|| {
                        lines.err(format!(
                            "element count '{}' is not a whole number",
                            shown(c)
                        ))
                    })?;
                if elements.len() >= MAX_ELEMENTS {
                    return Err(lines.err(format!("more than {MAX_ELEMENTS} elements")));
                }
                let name = String::from_utf8_lossy(n).into_owned();
                if name == "vertex" && elements.iter().any(|e| e.name == "vertex") {
                    return Err(lines.err("a second 'vertex' element"));
                }
                elements.push(Element {
                    name,
                    count,
                    props: Vec::new(),
                    line: lines.line(),
                });
            }
            b"property" => {
                let Some(el) = elements.last_mut() else {
                    return Err(lines.err("a 'property' before any 'element'"));
                };
                let ty_word = w.next();
                let ty = match ty_word {
                    Some(b"list") => {
                        let (Some(c), Some(i)) = (w.next(), w.next()) else {
                            return Err(lines.err(
                                "'property list' takes a count type, an item type and a name",
                            ));
                        };
                        let count = Scalar::parse(c).ok_or_else(|| {
                            lines.err(format!("unknown property type '{}'", shown(c)))
                        })?;
                        let item = Scalar::parse(i).ok_or_else(|| {
                            lines.err(format!("unknown property type '{}'", shown(i)))
                        })?;
                        if !count.is_integer() {
                            return Err(lines.err(format!(
                                "a list's count must be of an integer type, not {}",
                                count.name()
                            )));
                        }
                        PropType::List { count, item }
                    }
                    Some(t) => PropType::Scalar(Scalar::parse(t).ok_or_else(|| {
                        lines.err(format!("unknown property type '{}'", shown(t)))
                    })?),
                    None => return Err(lines.err("'property' takes a type and a name")),
                };
                let (Some(n), None) = (w.next(), w.next()) else {
                    return Err(lines.err("'property' takes a type and one name"));
                };
                if el.props.len() >= MAX_PROPERTIES {
                    return Err(lines.err(format!(
                        "more than {MAX_PROPERTIES} properties in one element"
                    )));
                }
                el.props.push(Property {
                    name: String::from_utf8_lossy(n).into_owned(),
                    ty,
                });
            }
            b"end_header" => break,
            other => {
                return Err(lines.err(format!("unknown PLY header keyword '{}'", shown(other))));
            }
        }
    }
    let encoding = encoding.ok_or_else(|| lines.err("the header has no 'format' line"))?;
    let header = Header {
        encoding,
        elements,
        up,
        texture_file,
        texture_files,
        lines: lines.line(),
        bytes: lines.consumed,
    };
    check_roles(&header, lines.name())?;
    Ok(header)
}

/// What a property of a vertex or face element is for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Slot {
    /// Index into the values kept per vertex (x y z nx ny nz r g b u v)
    /// or per face (r g b).
    Keep(usize),
    Indices,
    /// A face's texture coordinates, two per corner.
    TexCoords,
    Skip,
}

fn vertex_slots(el: &Element) -> Vec<Slot> {
    el.props
        .iter()
        .map(|p| {
            let keep = match p.name.as_str() {
                "x" => 0,
                "y" => 1,
                "z" => 2,
                "nx" => 3,
                "ny" => 4,
                "nz" => 5,
                "red" | "diffuse_red" => 6,
                "green" | "diffuse_green" => 7,
                "blue" | "diffuse_blue" => 8,
                "u" | "s" | "texture_u" | "texture_s" => 9,
                "v" | "t" | "texture_v" | "texture_t" => 10,
                _ => return Slot::Skip,
            };
            match p.ty {
                PropType::Scalar(_) => Slot::Keep(keep),
                PropType::List { .. } => Slot::Skip,
            }
        })
        .collect()
}

fn face_slots(el: &Element) -> Vec<Slot> {
    let mut have_indices = false;
    el.props
        .iter()
        .map(|p| match (p.name.as_str(), p.ty) {
            ("vertex_indices" | "vertex_index", PropType::List { .. }) if !have_indices => {
                have_indices = true;
                Slot::Indices
            }
            ("texcoord", PropType::List { .. }) => Slot::TexCoords,
            ("red" | "diffuse_red", PropType::Scalar(_)) => Slot::Keep(0),
            ("green" | "diffuse_green", PropType::Scalar(_)) => Slot::Keep(1),
            ("blue" | "diffuse_blue", PropType::Scalar(_)) => Slot::Keep(2),
            _ => Slot::Skip,
        })
        .collect()
}

/// Checks that the elements sray reads have properties of usable types.
fn check_roles(h: &Header, name: &Path) -> Result<(), Error> {
    let err = |line: u64, message: String| Error::Parse {
        file: name.to_path_buf(),
        at: At::Line(line),
        message,
    };
    for el in &h.elements {
        match el.name.as_str() {
            "vertex" => {
                for axis in ["x", "y", "z"] {
                    match el.props.iter().find(|p| p.name == axis) {
                        None => {
                            return Err(err(
                                el.line,
                                format!("the vertex element has no '{axis}' property"),
                            ));
                        }
                        Some(Property {
                            ty: PropType::List { .. },
                            ..
                        }) => {
                            return Err(err(
                                el.line,
                                format!(
                                    "vertex property '{axis}' is a list; a coordinate must be a scalar"
                                ),
                            ));
                        }
                        _ => {}
                    }
                }
            }
            "face" | "tristrips" => {
                let p = el
                    .props
                    .iter()
                    .find(|p| p.name == "vertex_indices" || p.name == "vertex_index");
                match p {
                    None => {
                        return Err(err(
                            el.line,
                            format!("the {} element has no 'vertex_indices' list", el.name),
                        ));
                    }
                    Some(Property {
                        ty: PropType::Scalar(t),
                        ..
                    }) => {
                        return Err(err(
                            el.line,
                            format!(
                                "{}'s vertex_indices is a single {}; it must be a list",
                                el.name,
                                t.name()
                            ),
                        ));
                    }
                    Some(Property {
                        ty: PropType::List { item, .. },
                        ..
                    }) if !item.is_integer() => {
                        return Err(err(
                            el.line,
                            format!(
                                "{}'s vertex indices are {}; they must be of an integer type",
                                el.name,
                                item.name()
                            ),
                        ));
                    }
                    _ => {}
                }
            }
            _ => {}
        }
    }
    Ok(())
}

/// Why a value could not be read.
enum Fail {
    /// The data ends.
    End,
    Bad(Error),
}

impl From<Error> for Fail {
    fn from(e: Error) -> Self {
        Fail::Bad(e)
    }
}

/// The element data, ASCII or binary.
trait Data {
    /// The next value of type `t`, as `f64` (every PLY type fits exactly).
    fn value(&mut self, t: Scalar) -> Result<f64, Fail>;
    fn skip(&mut self, t: Scalar) -> Result<(), Fail>;
    /// Where the next value starts.
    fn at(&self) -> At;
    /// Where the data ended (ASCII: the line of the last value read).
    fn end_at(&self) -> At {
        self.at()
    }
    fn name(&self) -> &Path;
    /// Whether anything but whitespace (ASCII) or nothing (binary) is
    /// left.
    fn more(&mut self) -> Result<bool, Error>;

    fn err_at(&self, at: At, message: String) -> Error {
        Error::Parse {
            file: self.name().to_path_buf(),
            at,
            message,
        }
    }

    /// A list's count, checked against `max`.
    fn count(&mut self, t: Scalar, max: u64, what: &str) -> Result<u64, Fail> {
        let at = self.at();
        let v = self.value(t)?;
        if v < 0.0 {
            return Err(Fail::Bad(
                self.err_at(at, format!("{what} has a negative count {v}")),
            ));
        }
        if v > max as f64 {
            return Err(Fail::Bad(self.err_at(
                at,
                format!("{what} claims {v} entries, more than the limit of {max}"),
            )));
        }
        Ok(v as u64)
    }

    fn skip_property(&mut self, ty: PropType) -> Result<(), Fail> {
        match ty {
            PropType::Scalar(t) => self.skip(t),
            PropType::List { count, item } => {
                let n = self.count(count, u32::MAX as u64, "a list")?;
                for _ in 0..n {
                    self.skip(item)?;
                }
                Ok(())
            }
        }
    }
}

struct Ascii<R> {
    src: R,
    name: PathBuf,
    wrapping: Wrapping,
    /// Line of the next token.
    line: u64,
    /// Line of the last token read.
    last: u64,
    tok: Vec<u8>,
}

impl<R: BufRead> Ascii<R> {
    /// Skips whitespace, counting lines; `false` at the end of the data.
    fn skip_space(&mut self) -> Result<bool, Error> {
        loop {
            let buf = match self.src.fill_buf() {
                Ok(b) => b,
                Err(e) if e.kind() == ErrorKind::Interrupted => continue,
                Err(e) => return Err(read_error(&self.name, self.wrapping, e)),
            };
            if buf.is_empty() {
                return Ok(false);
            }
            let mut i = 0;
            while i < buf.len() && buf[i].is_ascii_whitespace() {
                if buf[i] == b'\n' {
                    self.line += 1;
                }
                i += 1;
            }
            let all = i == buf.len();
            self.src.consume(i);
            if !all {
                return Ok(true);
            }
        }
    }

    /// Reads the next token into `tok`; `false` at the end of the data.
    /// The whitespace after it is skipped too, so that `line` is where the
    /// next value starts (errors about a face name the face's line).
    fn token(&mut self) -> Result<bool, Error> {
        self.tok.clear();
        if !self.skip_space()? {
            return Ok(false);
        }
        // The token.
        loop {
            let buf = match self.src.fill_buf() {
                Ok(b) => b,
                Err(e) if e.kind() == ErrorKind::Interrupted => continue,
                Err(e) => return Err(read_error(&self.name, self.wrapping, e)),
            };
            if buf.is_empty() {
                break;
            }
            let end = buf
                .iter()
                .position(|b| b.is_ascii_whitespace())
                .unwrap_or(buf.len());
            if self.tok.len() + end > MAX_TOKEN {
                return Err(Error::Parse {
                    file: self.name.clone(),
                    at: At::Line(self.line),
                    message: format!("a value longer than {MAX_TOKEN} characters"),
                });
            }
            self.tok.extend_from_slice(&buf[..end]);
            let done = end < buf.len();
            self.src.consume(end);
            if done {
                break;
            }
        }
        self.last = self.line;
        self.skip_space()?;
        Ok(true)
    }
}

impl<R: BufRead> Data for Ascii<R> {
    fn value(&mut self, t: Scalar) -> Result<f64, Fail> {
        if !self.token()? {
            return Err(Fail::End);
        }
        let tok = &self.tok[..];
        let s = std::str::from_utf8(tok).unwrap_or("");
        let line = self.last;
        let bad = |m: String| {
            Fail::Bad(Error::Parse {
                file: self.name.clone(),
                at: At::Line(line),
                message: m,
            })
        };
        if t.is_integer() {
            let v: i64 = s.parse().map_err(|_| {
                bad(format!(
                    "'{}' is not a whole number (the property is {})",
                    shown(tok),
                    t.name()
                ))
            })?;
            let (lo, hi) = t.range();
            if (v as f64) < lo || (v as f64) > hi {
                return Err(bad(format!("{v} is out of range for {}", t.name())));
            }
            Ok(v as f64)
        } else {
            // NaN and infinities are read here and refused where they
            // matter (coordinates, normals), not in skipped properties.
            s.parse::<f64>()
                .map_err(|_| bad(format!("'{}' is not a number", shown(tok))))
        }
    }
    fn skip(&mut self, t: Scalar) -> Result<(), Fail> {
        self.value(t).map(|_| ())
    }
    fn at(&self) -> At {
        At::Line(self.line)
    }
    fn end_at(&self) -> At {
        At::Line(self.last)
    }
    fn name(&self) -> &Path {
        &self.name
    }
    fn more(&mut self) -> Result<bool, Error> {
        self.token()
    }
}

struct Binary<R> {
    src: R,
    name: PathBuf,
    wrapping: Wrapping,
    pos: u64,
    big: bool,
}

impl<R: BufRead> Binary<R> {
    #[inline]
    fn bytes<const N: usize>(&mut self) -> Result<[u8; N], Fail> {
        let mut out = [0u8; N];
        let buf = match self.src.fill_buf() {
            Ok(b) => b,
            Err(e) => return Err(Fail::Bad(read_error(&self.name, self.wrapping, e))),
        };
        if buf.len() >= N {
            out.copy_from_slice(&buf[..N]);
            self.src.consume(N);
            self.pos += N as u64;
            return Ok(out);
        }
        let mut got = 0;
        while got < N {
            let buf = match self.src.fill_buf() {
                Ok(b) => b,
                Err(e) if e.kind() == ErrorKind::Interrupted => continue,
                Err(e) => return Err(Fail::Bad(read_error(&self.name, self.wrapping, e))),
            };
            if buf.is_empty() {
                return Err(Fail::End);
            }
            let k = (N - got).min(buf.len());
            out[got..got + k].copy_from_slice(&buf[..k]);
            self.src.consume(k);
            got += k;
            self.pos += k as u64;
        }
        Ok(out)
    }
}

impl<R: BufRead> Data for Binary<R> {
    #[inline]
    fn value(&mut self, t: Scalar) -> Result<f64, Fail> {
        macro_rules! num {
            ($ty:ty, $n:literal) => {{
                let b = self.bytes::<$n>()?;
                (if self.big {
                    <$ty>::from_be_bytes(b)
                } else {
                    <$ty>::from_le_bytes(b)
                }) as f64
            }};
        }
        Ok(match t {
            Scalar::I8 => num!(i8, 1),
            Scalar::U8 => num!(u8, 1),
            Scalar::I16 => num!(i16, 2),
            Scalar::U16 => num!(u16, 2),
            Scalar::I32 => num!(i32, 4),
            Scalar::U32 => num!(u32, 4),
            Scalar::F32 => num!(f32, 4),
            Scalar::F64 => num!(f64, 8),
        })
    }
    fn skip(&mut self, t: Scalar) -> Result<(), Fail> {
        let mut left = t.size();
        while left > 0 {
            let buf = match self.src.fill_buf() {
                Ok(b) => b,
                Err(e) if e.kind() == ErrorKind::Interrupted => continue,
                Err(e) => return Err(Fail::Bad(read_error(&self.name, self.wrapping, e))),
            };
            if buf.is_empty() {
                return Err(Fail::End);
            }
            let k = left.min(buf.len());
            self.src.consume(k);
            self.pos += k as u64;
            left -= k;
        }
        Ok(())
    }
    fn at(&self) -> At {
        At::Byte(self.pos)
    }
    fn name(&self) -> &Path {
        &self.name
    }
    fn more(&mut self) -> Result<bool, Error> {
        loop {
            match self.src.fill_buf() {
                Ok(b) => return Ok(!b.is_empty()),
                Err(e) if e.kind() == ErrorKind::Interrupted => continue,
                Err(e) => return Err(read_error(&self.name, self.wrapping, e)),
            }
        }
    }
}

/// The truncation error: the element data ends before the count the
/// header declares.
fn truncated(d: &impl Data, el: &Element, i: u64) -> Error {
    d.err_at(
        d.end_at(),
        format!(
            "the file ends after {i} of the {} '{}' elements its header declares (line {}): truncated",
            el.count, el.name, el.line
        ),
    )
}

fn read_body(
    h: &Header,
    d: &mut impl Data,
    b: &mut MeshBuilder<'_>,
    material: u32,
    warnings: &mut Warnings,
) -> Result<(), Error> {
    // Texture coordinates are kept only for a texture.
    let vertex_uvs = material != NO_MATERIAL
        && h.elements
            .iter()
            .find(|e| e.name == "vertex")
            .is_some_and(|e| {
                let slots = vertex_slots(e);
                slots.contains(&Slot::Keep(9)) && slots.contains(&Slot::Keep(10))
            });
    let nv = h
        .elements
        .iter()
        .find(|e| e.name == "vertex")
        .map_or(0, |e| e.count);
    let mut corners: Vec<(u64, u64, u64)> = Vec::new();
    for el in &h.elements {
        let mut i = 0u64;
        let r = match el.name.as_str() {
            "vertex" => read_vertices(el, d, b, vertex_uvs, &mut i),
            "face" => read_faces(el, d, b, nv, (material, vertex_uvs), &mut corners, &mut i),
            "tristrips" => read_strips(el, d, b, nv, &mut i),
            // An element without properties takes no bytes, whatever its
            // count says: nothing to skip (and no loop of 10^10 turns
            // over nothing).
            _ if el.props.is_empty() => Ok(()),
            _ => (|| {
                while i < el.count {
                    for p in &el.props {
                        d.skip_property(p.ty)?;
                    }
                    i += 1;
                }
                Ok(())
            })(),
        };
        match r {
            Ok(()) => {}
            Err(Fail::End) => return Err(truncated(d, el, i)),
            Err(Fail::Bad(e)) => return Err(e),
        }
    }
    if d.more()? {
        let at = d.at();
        warnings.add("data after the last element ignored", || at_text(at));
    }
    Ok(())
}

fn at_text(at: At) -> String {
    match at {
        At::Line(l) => format!("line {l}"),
        At::Byte(b) => format!("byte {b}"),
    }
}

/// The vertices; their texture coordinates too with `keep_uvs`.
fn read_vertices(
    el: &Element,
    d: &mut impl Data,
    b: &mut MeshBuilder<'_>,
    keep_uvs: bool,
    i: &mut u64,
) -> Result<(), Fail> {
    let slots = vertex_slots(el);
    let has = |k: usize| slots.contains(&Slot::Keep(k));
    let normals = has(3) && has(4) && has(5);
    let colors = has(6) && has(7) && has(8);
    let uvs = keep_uvs && has(9) && has(10);
    let color_type: Vec<Scalar> = el
        .props
        .iter()
        .zip(&slots)
        .filter_map(|(p, s)| match (s, p.ty) {
            (Slot::Keep(6..=8), PropType::Scalar(t)) => Some(t),
            _ => None,
        })
        .collect();
    let mut vals = [0.0f64; 11];
    while *i < el.count {
        let at = d.at();
        for (p, s) in el.props.iter().zip(&slots) {
            match (s, p.ty) {
                (Slot::Keep(k), PropType::Scalar(t)) => {
                    let v = d.value(t)?;
                    vals[*k] = if *k >= 6 { t.unit(v) } else { v };
                }
                _ => d.skip_property(p.ty)?,
            }
        }
        let bad = |m: String| Fail::Bad(d.err_at(at, format!("vertex {}: {m}", *i)));
        let mut p = [0.0; 3];
        for k in 0..3 {
            p[k] = coordinate(vals[k]).map_err(bad)?;
        }
        b.add_vertex(p)?;
        if normals {
            let mut n = [0.0f32; 3];
            for k in 0..3 {
                n[k] = super::text::component(vals[3 + k], "normal").map_err(bad)?;
            }
            b.add_normal(n)?;
        }
        if colors && color_type.len() == 3 {
            let c = [vals[6], vals[7], vals[8]].map(|x| if x.is_finite() { x as f32 } else { 0.0 });
            b.add_color(c)?;
        }
        if uvs {
            let f = |x: f64| if x.is_finite() { x as f32 } else { 0.0 };
            // sray's (glTF's) v runs down the image.
            b.add_uv([f(vals[9]), 1.0 - f(vals[10])])?;
        }
        *i += 1;
    }
    Ok(())
}

/// The faces; with `(material, vertex_uvs)`, their material and whether
/// corners take their vertex's texture coordinates (a face's own
/// `texcoord` list wins).
fn read_faces(
    el: &Element,
    d: &mut impl Data,
    b: &mut MeshBuilder<'_>,
    nv: u64,
    (material, vertex_uvs): (u32, bool),
    corners: &mut Vec<(u64, u64, u64)>,
    i: &mut u64,
) -> Result<(), Fail> {
    let slots = face_slots(el);
    let colored = (0..3).all(|k| slots.contains(&Slot::Keep(k)));
    let mut color = [0.0f64; 3];
    let mut wedges: Vec<f32> = Vec::new();
    while *i < el.count {
        let at = d.at();
        corners.clear();
        for (p, s) in el.props.iter().zip(&slots) {
            match (s, p.ty) {
                (Slot::Indices, PropType::List { count, item }) => {
                    let cat = d.at();
                    let v = d.value(count)?;
                    if v < 3.0 {
                        return Err(Fail::Bad(d.err_at(
                            cat,
                            format!("face {} has {v} vertices; at least 3 are needed", *i),
                        )));
                    }
                    if v > MAX_POLYGON_VERTICES as f64 {
                        return Err(Fail::Bad(d.err_at(
                            cat,
                            format!(
                                "face {} claims {v} vertices, more than the limit of {MAX_POLYGON_VERTICES}",
                                *i
                            ),
                        )));
                    }
                    for _ in 0..v as u64 {
                        let x = d.value(item)?;
                        if x < 0.0 || x >= nv as f64 {
                            return Err(Fail::Bad(d.err_at(
                                at,
                                format!(
                                    "face {}: vertex index {x} is out of range (the file has {nv} vertices)",
                                    *i
                                ),
                            )));
                        }
                        let v = x as u64;
                        corners.push((v, NO_INDEX, if vertex_uvs { v } else { NO_INDEX }));
                    }
                }
                (Slot::TexCoords, PropType::List { count, item }) => {
                    let n = d.count(count, 2 * MAX_POLYGON_VERTICES as u64, "a texcoord list")?;
                    wedges.clear();
                    for _ in 0..n {
                        let x = d.value(item)?;
                        wedges.push(if x.is_finite() { x as f32 } else { 0.0 });
                    }
                }
                (Slot::Keep(k), PropType::Scalar(t)) => color[*k] = t.unit(d.value(t)?),
                _ => d.skip_property(p.ty)?,
            }
        }
        let c = colored.then(|| color.map(|x| if x.is_finite() { x as f32 } else { 0.0 }));
        // Per-corner texture coordinates, when the face lists one pair
        // per corner.
        if material != NO_MATERIAL && wedges.len() == 2 * corners.len() && c.is_none() {
            for (corner, uv) in corners.iter_mut().zip(wedges.chunks_exact(2)) {
                corner.2 = b.uv_count();
                b.add_uv([uv[0], 1.0 - uv[1]])?;
            }
        }
        b.add_face_uv(corners, if c.is_some() { NO_MATERIAL } else { material }, c)?;
        *i += 1;
    }
    Ok(())
}

fn read_strips(
    el: &Element,
    d: &mut impl Data,
    b: &mut MeshBuilder<'_>,
    nv: u64,
    i: &mut u64,
) -> Result<(), Fail> {
    let index_prop = el
        .props
        .iter()
        .position(|p| p.name == "vertex_indices" || p.name == "vertex_index");
    while *i < el.count {
        for (k, p) in el.props.iter().enumerate() {
            match (Some(k) == index_prop, p.ty) {
                (true, PropType::List { count, item }) => {
                    let n = d.count(count, u32::MAX as u64, "a triangle strip")?;
                    let mut window: [u64; 2] = [0; 2];
                    let mut have = 0usize;
                    let mut odd = false;
                    for _ in 0..n {
                        let at = d.at();
                        let x = d.value(item)?;
                        if x == -1.0 {
                            have = 0;
                            odd = false;
                            continue;
                        }
                        if x < 0.0 || x >= nv as f64 {
                            return Err(Fail::Bad(d.err_at(
                                at,
                                format!(
                                    "triangle strip {}: vertex index {x} is out of range (the file has {nv} vertices)",
                                    *i
                                ),
                            )));
                        }
                        let x = x as u64;
                        if have < 2 {
                            window[have] = x;
                            have += 1;
                            continue;
                        }
                        let [a, c] = window;
                        // Every other triangle of a strip turns the other
                        // way; swap two corners to keep one orientation.
                        let tri = if odd {
                            [(c, NO_INDEX), (a, NO_INDEX), (x, NO_INDEX)]
                        } else {
                            [(a, NO_INDEX), (c, NO_INDEX), (x, NO_INDEX)]
                        };
                        b.add_face(&tri, NO_MATERIAL, None)?;
                        window = [c, x];
                        odd = !odd;
                    }
                }
                _ => d.skip_property(p.ty)?,
            }
        }
        *i += 1;
    }
    Ok(())
}
