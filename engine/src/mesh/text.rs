//! Lines and numbers of the text mesh formats (OBJ, OFF, MTL, PLY's
//! header): bytes rather than strings, so that a comment in another
//! encoding is no error; every error names the file and the line.

use crate::error::{At, Error};
use crate::input::{Wrapping, read_error};
use std::io::{BufRead, ErrorKind};
use std::path::{Path, PathBuf};

/// Reads a text file line by line, counting lines, refusing overlong ones.
pub(crate) struct LineReader<R> {
    src: R,
    name: PathBuf,
    wrapping: Wrapping,
    buf: Vec<u8>,
    line: u64,
    max: usize,
    /// Bytes consumed so far (of the decompressed stream).
    pub consumed: u64,
}

impl<R: BufRead> LineReader<R> {
    pub fn new(src: R, name: &Path, wrapping: Wrapping, max: usize) -> Self {
        LineReader {
            src,
            name: name.to_path_buf(),
            wrapping,
            buf: Vec::with_capacity(256),
            line: 0,
            max,
            consumed: 0,
        }
    }

    pub fn name(&self) -> &Path {
        &self.name
    }

    /// The number of the line last read.
    pub fn line(&self) -> u64 {
        self.line
    }

    pub fn err(&self, message: impl Into<String>) -> Error {
        Error::Parse {
            file: self.name.clone(),
            at: At::Line(self.line),
            message: message.into(),
        }
    }

    pub fn into_inner(self) -> R {
        self.src
    }

    /// The next line without its end (`\n` or `\r\n`), or `None` at the
    /// end of the file. A NUL byte is an error: binary data is no text.
    pub fn next_line(&mut self) -> Result<Option<&[u8]>, Error> {
        self.buf.clear();
        let mut saw_any = false;
        loop {
            let avail = match self.src.fill_buf() {
                Ok(b) => b,
                Err(e) if e.kind() == ErrorKind::Interrupted => continue,
                Err(e) => return Err(read_error(&self.name, self.wrapping, e)),
            };
            if avail.is_empty() {
                break;
            }
            saw_any = true;
            let (take, done) = match memchr(b'\n', avail) {
                Some(i) => (i + 1, true),
                None => (avail.len(), false),
            };
            if self.buf.len() + take > self.max + 2 {
                self.line += 1;
                return Err(self.err(format!("line is longer than {} bytes", self.max)));
            }
            self.buf.extend_from_slice(&avail[..take]);
            self.src.consume(take);
            self.consumed += take as u64;
            if done {
                break;
            }
        }
        if !saw_any {
            return Ok(None);
        }
        self.line += 1;
        while matches!(self.buf.last(), Some(b'\n' | b'\r')) {
            self.buf.pop();
        }
        if self.buf.len() > self.max {
            return Err(self.err(format!("line is longer than {} bytes", self.max)));
        }
        if self.buf.contains(&0) {
            return Err(self.err("binary data (a NUL byte) in a text file"));
        }
        Ok(Some(&self.buf))
    }
}

fn memchr(b: u8, s: &[u8]) -> Option<usize> {
    s.iter().position(|&c| c == b)
}

/// The whitespace-separated words of a line.
pub(crate) fn words(line: &[u8]) -> impl Iterator<Item = &[u8]> {
    line.split(|b| b.is_ascii_whitespace())
        .filter(|t| !t.is_empty())
}

/// A word as text for messages (lossy, shortened).
pub(crate) fn shown(tok: &[u8]) -> String {
    let s = String::from_utf8_lossy(tok);
    if s.chars().count() > 40 {
        format!("{}...", s.chars().take(40).collect::<String>())
    } else {
        s.into_owned()
    }
}

/// A finite number.
pub(crate) fn real(tok: &[u8]) -> Result<f64, String> {
    let s = std::str::from_utf8(tok).map_err(|_| format!("'{}' is not a number", shown(tok)))?;
    let v: f64 = s
        .parse()
        .map_err(|_| format!("'{}' is not a number", shown(tok)))?;
    if !v.is_finite() {
        return Err(format!(
            "'{}' is not a finite number (NaN or infinity)",
            shown(tok)
        ));
    }
    Ok(v)
}

/// A whole number.
pub(crate) fn integer(tok: &[u8]) -> Result<i64, String> {
    let s =
        std::str::from_utf8(tok).map_err(|_| format!("'{}' is not a whole number", shown(tok)))?;
    s.parse()
        .map_err(|_| format!("'{}' is not a whole number", shown(tok)))
}

/// Largest coordinate accepted: the geometry is kept in `f32` relative to
/// the model's centre, which this leaves room for.
pub(crate) const MAX_COORD: f64 = 1e37;

/// A vertex coordinate: finite and within single precision's range.
pub(crate) fn coordinate(v: f64) -> Result<f64, String> {
    if !v.is_finite() {
        return Err("a coordinate is not finite (NaN or infinity)".into());
    }
    if v.abs() > MAX_COORD {
        return Err(format!(
            "coordinate {v:e} is beyond the range sray keeps geometry in (|x| <= 1e37)"
        ));
    }
    Ok(v)
}

/// A normal or colour component, as `f32`.
pub(crate) fn component(v: f64, what: &str) -> Result<f32, String> {
    let f = v as f32;
    if !v.is_finite() || !f.is_finite() {
        return Err(format!(
            "a {what} component is not finite (NaN or infinity)"
        ));
    }
    Ok(f)
}

/// Finds an up axis declared in a comment: `up z`, `up_axis: -y`,
/// `up-axis = Z`, `Z_UP`, `z-up`, `+Y up` (any case). `None` if the
/// comment declares none.
pub(crate) fn declared_up(comment: &[u8]) -> Option<[f64; 3]> {
    let text = String::from_utf8_lossy(comment).to_ascii_lowercase();
    let axis = |w: &str| -> Option<[f64; 3]> {
        let (sign, a) = match w.strip_prefix('-') {
            Some(a) => (-1.0, a),
            None => (1.0, w.strip_prefix('+').unwrap_or(w)),
        };
        match a {
            "x" => Some([sign, 0.0, 0.0]),
            "y" => Some([0.0, sign, 0.0]),
            "z" => Some([0.0, 0.0, sign]),
            _ => None,
        }
    };
    let ws: Vec<&str> = text
        .split(|c: char| c.is_whitespace() || c == ':' || c == '=' || c == ',')
        .filter(|w| !w.is_empty())
        .collect();
    for (i, w) in ws.iter().enumerate() {
        // "up z", "up_axis z", "upaxis: z", "up-axis = z", "up direction z"
        if matches!(*w, "up" | "up_axis" | "upaxis" | "up-axis" | "up_direction")
            && let Some(a) = ws.get(i + 1).and_then(|n| axis(n))
        {
            return Some(a);
        }
        // "z_up", "z-up", "zup", "+z_up", "y up"
        for suffix in ["_up", "-up", "up"] {
            if let Some(a) = w.strip_suffix(suffix).and_then(axis) {
                return Some(a);
            }
        }
        if ws.get(i + 1) == Some(&"up")
            && let Some(a) = axis(w)
        {
            return Some(a);
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn up_axes_in_comments() {
        let u = |s: &str| declared_up(s.as_bytes());
        assert_eq!(u("up z"), Some([0.0, 0.0, 1.0]));
        assert_eq!(u("Up_Axis: -Y"), Some([0.0, -1.0, 0.0]));
        assert_eq!(u("exported Z_UP by tool"), Some([0.0, 0.0, 1.0]));
        assert_eq!(u("coordinates: z-up, metres"), Some([0.0, 0.0, 1.0]));
        assert_eq!(u("+x up"), Some([1.0, 0.0, 0.0]));
        assert_eq!(u("generated by ply_writer"), None);
        assert_eq!(u("VCGLIB generated"), None);
        assert_eq!(u("set up the scene"), None);
        assert_eq!(u("lookup"), None);
    }

    #[test]
    fn numbers() {
        assert_eq!(real(b"1e-5"), Ok(1e-5));
        assert!(real(b"nan").is_err());
        assert!(real(b"inf").is_err());
        assert!(real(b"1e400").is_err());
        assert!(real(b"x").is_err());
        assert_eq!(integer(b"-3"), Ok(-3));
        assert!(integer(b"3.0").is_err());
        assert!(coordinate(1e38).is_err());
    }
}
