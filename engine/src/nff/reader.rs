//! Streaming NFF reader: constant memory whatever the file's size, every
//! error naming file and line, no allocation sized by a number in the file.

use crate::error::{Error, IoContext};
use crate::progress::Progress;
use crate::scene::{Light, Material, SceneSink, View};
use crate::shapes::{Cone, MAX_POLYGON_VERTICES, Patch, Polygon, Shape, Sphere};
use std::fs::File;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};

/// Longest line accepted. Real NFF lines are under a hundred bytes.
pub const MAX_LINE_BYTES: usize = 64 * 1024;

/// Reads the NFF file at `path` (gzip or zstd wrapped or not) into
/// `sink`, reporting bytes of the file read.
pub fn read_nff(
    path: &Path,
    sink: &mut dyn SceneSink,
    progress: &dyn Progress,
) -> Result<(), Error> {
    let input = crate::input::open(path, progress)?;
    if input.wrapping == crate::input::Wrapping::Plain {
        drop(input);
        let file = File::open(path).at(path)?;
        return read_nff_from(
            BufReader::with_capacity(1 << 20, file),
            path,
            sink,
            progress,
        );
    }
    // The input counts the compressed bytes itself.
    read_nff_from(input.reader, path, sink, &crate::progress::NoProgress)
}

/// Reads NFF text from `src`; `name` is used in error messages.
pub fn read_nff_from<R: BufRead>(
    src: R,
    name: &Path,
    sink: &mut dyn SceneSink,
    progress: &dyn Progress,
) -> Result<(), Error> {
    let mut p = Parser {
        lines: Lines {
            src,
            name: name.to_path_buf(),
            line_no: 0,
            buf: Vec::with_capacity(256),
            text: String::with_capacity(256),
            peeked: false,
            bytes_since_report: 0,
        },
        view_line: None,
        verts: Vec::new(),
        norms: Vec::new(),
    };
    let r = p.run(sink, progress);
    progress.inc(p.lines.bytes_since_report);
    r
}

struct Lines<R> {
    src: R,
    name: PathBuf,
    line_no: u64,
    buf: Vec<u8>,
    /// The current line, trimmed.
    text: String,
    /// `next` returns the current line again.
    peeked: bool,
    bytes_since_report: u64,
}

impl<R: BufRead> Lines<R> {
    fn err(&self, message: impl Into<String>) -> Error {
        Error::Nff {
            file: self.name.clone(),
            line: self.line_no,
            message: message.into(),
        }
    }

    /// Advances to the next line that is neither blank nor a comment.
    /// Returns `false` at end of file.
    fn next(&mut self, progress: &dyn Progress) -> Result<bool, Error> {
        if self.peeked {
            self.peeked = false;
            return Ok(true);
        }
        loop {
            if !self.read_raw_line()? {
                return Ok(false);
            }
            if self.bytes_since_report >= 1 << 20 {
                progress.inc(self.bytes_since_report);
                self.bytes_since_report = 0;
            }
            let t = self.text.trim();
            if t.is_empty() || t.starts_with('#') {
                continue;
            }
            if t.len() != self.text.len() {
                self.text = t.to_string();
            }
            return Ok(true);
        }
    }

    /// Reads one physical line into `text`, refusing lines longer than
    /// [`MAX_LINE_BYTES`].
    fn read_raw_line(&mut self) -> Result<bool, Error> {
        self.buf.clear();
        let mut saw_any = false;
        loop {
            let avail = match self.src.fill_buf() {
                Ok(b) => b,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                Err(e) => return Err(Error::io(&self.name, e)),
            };
            if avail.is_empty() {
                break;
            }
            saw_any = true;
            let (take, done) = match avail.iter().position(|&b| b == b'\n') {
                Some(i) => (i + 1, true),
                None => (avail.len(), false),
            };
            if self.buf.len() + take > MAX_LINE_BYTES + 2 {
                self.line_no += 1;
                return Err(self.err(format!("line is longer than {MAX_LINE_BYTES} bytes")));
            }
            self.buf.extend_from_slice(&avail[..take]);
            self.src.consume(take);
            self.bytes_since_report += take as u64;
            if done {
                break;
            }
        }
        if !saw_any {
            return Ok(false);
        }
        self.line_no += 1;
        while matches!(self.buf.last(), Some(b'\n' | b'\r')) {
            self.buf.pop();
        }
        if self.buf.len() > MAX_LINE_BYTES {
            return Err(self.err(format!("line is longer than {MAX_LINE_BYTES} bytes")));
        }
        self.text.clear();
        match std::str::from_utf8(&self.buf) {
            Ok(s) => self.text.push_str(s),
            Err(_) => return Err(self.err("line is not valid UTF-8 text")),
        }
        Ok(true)
    }
}

struct Parser<R> {
    lines: Lines<R>,
    view_line: Option<u64>,
    verts: Vec<[f32; 3]>,
    norms: Vec<[f32; 3]>,
}

/// Parses the numbers of `tokens`, which must be exactly `N`.
fn numbers<'a, R: BufRead, const N: usize>(
    lines: &Lines<R>,
    tokens: impl Iterator<Item = &'a str>,
    what: &str,
) -> Result<[f64; N], Error> {
    let mut out = [0.0; N];
    let mut n = 0;
    for tok in tokens {
        if n == N {
            return Err(lines.err(format!("{what} takes {N} numbers, found more: '{tok}'")));
        }
        out[n] = number(lines, tok)?;
        n += 1;
    }
    if n < N {
        return Err(lines.err(format!("{what} needs {N} numbers, found {n}")));
    }
    Ok(out)
}

fn number<R: BufRead>(lines: &Lines<R>, tok: &str) -> Result<f64, Error> {
    let v: f64 = tok
        .parse()
        .map_err(|_| lines.err(format!("'{tok}' is not a number")))?;
    if !v.is_finite() {
        return Err(lines.err(format!("'{tok}' is not a finite number (NaN or infinity)")));
    }
    Ok(v)
}

/// Converts to `f32`, the precision of geometry and colours, refusing what
/// does not fit.
fn single<R: BufRead>(lines: &Lines<R>, v: f64) -> Result<f32, Error> {
    let f = v as f32;
    if !f.is_finite() {
        return Err(lines.err(format!("{v:e} is too large for single precision")));
    }
    Ok(f)
}

fn single3<R: BufRead>(lines: &Lines<R>, v: &[f64]) -> Result<[f32; 3], Error> {
    Ok([
        single(lines, v[0])?,
        single(lines, v[1])?,
        single(lines, v[2])?,
    ])
}

impl<R: BufRead> Parser<R> {
    fn run(&mut self, sink: &mut dyn SceneSink, progress: &dyn Progress) -> Result<(), Error> {
        while self.lines.next(progress)? {
            // The entity may read further lines (vertices, the view), which
            // replace `lines.text`; it works on its own copy of this one.
            let text = std::mem::take(&mut self.lines.text);
            self.entity(&text, sink, progress)?;
        }
        Ok(())
    }

    fn entity(
        &mut self,
        text: &str,
        sink: &mut dyn SceneSink,
        progress: &dyn Progress,
    ) -> Result<(), Error> {
        let mut toks = text.split_ascii_whitespace();
        let key = toks.next().unwrap_or("");
        match key {
            "b" => {
                let c = numbers::<_, 3>(&self.lines, toks, "background 'b'")?;
                sink.background(single3(&self.lines, &c)?)
            }
            "v" => {
                if toks.next().is_some() {
                    return Err(self.lines.err("'v' stands alone on its line"));
                }
                self.view(sink, progress)
            }
            "l" => {
                let v: Vec<&str> = toks.collect();
                let nums: Vec<f64> = v
                    .iter()
                    .map(|t| number(&self.lines, t))
                    .collect::<Result<_, _>>()?;
                let color = match nums.len() {
                    3 => None,
                    6 => Some(single3(&self.lines, &nums[3..])?),
                    n => {
                        return Err(self.lines.err(format!(
                            "light 'l' takes 3 numbers (or 6 with a colour), found {n}"
                        )));
                    }
                };
                sink.light(&Light {
                    photometric: None,
                    position: [nums[0], nums[1], nums[2]],
                    color,
                })
            }
            "f" => {
                let n = numbers::<_, 8>(&self.lines, toks, "material 'f'")?;
                let s = |i: usize| single(&self.lines, n[i]);
                sink.material(&Material {
                    pbr: None,
                    texture: None,
                    maps: crate::scene::Maps::NONE,
                    color: [s(0)?, s(1)?, s(2)?],
                    kd: s(3)?,
                    ks: s(4)?,
                    shine: s(5)?,
                    t: s(6)?,
                    ior: s(7)?,
                })
            }
            "s" => {
                self.require_view("sphere 's'")?;
                let n = numbers::<_, 4>(&self.lines, toks, "sphere 's'")?;
                let shape = Shape::Sphere(Sphere {
                    center: single3(&self.lines, &n[..3])?,
                    radius: single(&self.lines, n[3])?,
                });
                self.emit(sink, &shape)
            }
            "c" => {
                self.require_view("cone 'c'")?;
                let start = self.lines.line_no;
                let rest: Vec<&str> = toks.collect();
                let n: [f64; 8] = if rest.is_empty() {
                    // Classic two-line form: base line, then apex line.
                    let mut all = [0.0; 8];
                    for (half, what) in [(0usize, "cone base"), (4, "cone apex")] {
                        if !self.lines.next(progress)? {
                            return Err(self.truncated(start, "cone"));
                        }
                        let t = std::mem::take(&mut self.lines.text);
                        let r = numbers::<_, 4>(&self.lines, t.split_ascii_whitespace(), what);
                        self.lines.text = t;
                        all[half..half + 4].copy_from_slice(&r?);
                    }
                    all
                } else {
                    numbers::<_, 8>(&self.lines, rest.into_iter(), "cone 'c'")?
                };
                let shape = Shape::Cone(Cone {
                    base: single3(&self.lines, &n[0..3])?,
                    base_radius: single(&self.lines, n[3])?,
                    apex: single3(&self.lines, &n[4..7])?,
                    apex_radius: single(&self.lines, n[7])?,
                });
                self.emit(sink, &shape)
            }
            "p" | "pp" => {
                let patch = key == "pp";
                let what = if patch { "patch 'pp'" } else { "polygon 'p'" };
                self.require_view(what)?;
                let count = self.vertex_count(toks, what)?;
                let start = self.lines.line_no;
                self.verts.clear();
                self.norms.clear();
                for i in 0..count {
                    if !self.lines.next(progress)? {
                        return Err(Error::Nff {
                            file: self.lines.name.clone(),
                            line: self.lines.line_no,
                            message: format!(
                                "file ends inside the {what} that starts at line {start} ({i} of {count} vertices read)"
                            ),
                        });
                    }
                    let t = std::mem::take(&mut self.lines.text);
                    let r = if patch {
                        numbers::<_, 6>(
                            &self.lines,
                            t.split_ascii_whitespace(),
                            "patch vertex (x y z nx ny nz)",
                        )
                        .and_then(|n| {
                            Ok((
                                single3(&self.lines, &n[..3])?,
                                Some(single3(&self.lines, &n[3..])?),
                            ))
                        })
                    } else {
                        numbers::<_, 3>(
                            &self.lines,
                            t.split_ascii_whitespace(),
                            "polygon vertex (x y z)",
                        )
                        .and_then(|n| Ok((single3(&self.lines, &n)?, None)))
                    };
                    self.lines.text = t;
                    let (v, n) = r?;
                    self.verts.push(v);
                    if let Some(n) = n {
                        self.norms.push(n);
                    }
                }
                let verts = std::mem::take(&mut self.verts);
                let norms = std::mem::take(&mut self.norms);
                let shape = if patch {
                    Shape::Patch(Patch {
                        vertices: &verts,
                        normals: &norms,
                    })
                } else {
                    Shape::Polygon(Polygon { vertices: &verts })
                };
                let r = self.emit(sink, &shape);
                self.verts = verts;
                self.norms = norms;
                r
            }
            other => Err(self.lines.err(format!("unknown entity '{other}'"))),
        }
    }

    fn emit(&mut self, sink: &mut dyn SceneSink, shape: &Shape<'_>) -> Result<(), Error> {
        shape.validate().map_err(|m| self.lines.err(m))?;
        sink.object(shape)
    }

    fn require_view(&self, what: &str) -> Result<(), Error> {
        if self.view_line.is_none() {
            return Err(self.lines.err(format!(
                "{what} comes before the view ('v'); NFF requires the view first"
            )));
        }
        Ok(())
    }

    fn truncated(&self, start: u64, what: &str) -> Error {
        Error::Nff {
            file: self.lines.name.clone(),
            line: self.lines.line_no,
            message: format!("file ends inside the {what} that starts at line {start}"),
        }
    }

    fn vertex_count<'a>(
        &self,
        mut toks: impl Iterator<Item = &'a str>,
        what: &str,
    ) -> Result<usize, Error> {
        let tok = toks
            .next()
            .ok_or_else(|| self.lines.err(format!("{what} needs a vertex count")))?;
        if let Some(extra) = toks.next() {
            return Err(self.lines.err(format!(
                "{what} takes only a vertex count, found more: '{extra}'"
            )));
        }
        let n: u64 = tok.parse().map_err(|_| {
            self.lines
                .err(format!("vertex count '{tok}' is not a whole number"))
        })?;
        if n < 3 {
            return Err(self
                .lines
                .err(format!("{what} has {n} vertices; at least 3 are needed")));
        }
        if n > MAX_POLYGON_VERTICES as u64 {
            return Err(self.lines.err(format!(
                "{what} claims {n} vertices, more than the limit of {MAX_POLYGON_VERTICES}"
            )));
        }
        Ok(n as usize)
    }

    /// The lines after `v`: `from`, `at`, `up`, `angle`, `hither`,
    /// `resolution`, in any order; `hither` and `resolution` may be missing.
    fn view(&mut self, sink: &mut dyn SceneSink, progress: &dyn Progress) -> Result<(), Error> {
        let start = self.lines.line_no;
        if let Some(first) = self.view_line {
            return Err(self
                .lines
                .err(format!("a second view; the first is at line {first}")));
        }
        let (mut from, mut at, mut up, mut angle) = (None, None, None, None);
        let mut hither = None;
        let mut resolution = None;
        while self.lines.next(progress)? {
            let t = std::mem::take(&mut self.lines.text);
            let mut toks = t.split_ascii_whitespace();
            let key = toks.next().unwrap_or("");
            let r: Result<bool, Error> = (|| {
                match key {
                    "from" => from = Some(numbers::<_, 3>(&self.lines, toks, "'from'")?),
                    "at" => at = Some(numbers::<_, 3>(&self.lines, toks, "'at'")?),
                    "up" => up = Some(numbers::<_, 3>(&self.lines, toks, "'up'")?),
                    "angle" => angle = Some(numbers::<_, 1>(&self.lines, toks, "'angle'")?[0]),
                    "hither" => hither = Some(numbers::<_, 1>(&self.lines, toks, "'hither'")?[0]),
                    "resolution" => {
                        let r = numbers::<_, 2>(&self.lines, toks, "'resolution'")?;
                        let ok = |v: f64| (1.0..=65_536.0).contains(&v) && v.fract() == 0.0;
                        if !ok(r[0]) || !ok(r[1]) {
                            return Err(self
                                .lines
                                .err("resolution must be two whole numbers from 1 to 65536"));
                        }
                        resolution = Some([r[0] as u32, r[1] as u32]);
                    }
                    _ => return Ok(false),
                }
                Ok(true)
            })();
            self.lines.text = t;
            if !r? {
                self.lines.peeked = true;
                break;
            }
        }
        let missing = |name: &str| Error::Nff {
            file: self.lines.name.clone(),
            line: start,
            message: format!("the view that starts here has no '{name}' line"),
        };
        let view = View {
            from: from.ok_or_else(|| missing("from"))?,
            at: at.ok_or_else(|| missing("at"))?,
            up: up.ok_or_else(|| missing("up"))?,
            angle: angle.ok_or_else(|| missing("angle"))?,
            hither: hither.unwrap_or(1.0),
            resolution: resolution.unwrap_or([512, 512]),
        };
        if !(view.angle > 0.0 && view.angle < 180.0) {
            return Err(Error::Nff {
                file: self.lines.name.clone(),
                line: start,
                message: format!(
                    "view angle {} must be between 0 and 180 degrees",
                    view.angle
                ),
            });
        }
        self.view_line = Some(start);
        sink.view(&view)
    }
}
