//! Opening scene files, compressed or not: a file that starts with the
//! gzip or zstd magic number is decompressed on the fly, whatever its name,
//! and judged by its content and by its name without the `.gz` or `.zst`.
//! Progress counts bytes of the file as stored (compressed), so that the
//! total is known from the start.

use crate::error::{Error, IoContext};
use crate::progress::Progress;
use std::fs::File;
use std::io::{BufRead, BufReader, Read};
use std::path::Path;

/// How a file is stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Wrapping {
    Plain,
    Gzip,
    Zstd,
}

impl Wrapping {
    /// As `sray info` reports it.
    pub fn name(self) -> &'static str {
        match self {
            Wrapping::Plain => "none",
            Wrapping::Gzip => "gzip",
            Wrapping::Zstd => "zstd",
        }
    }

    /// Judges a file's first bytes.
    pub fn of_head(head: &[u8]) -> Wrapping {
        if head.starts_with(&[0x1f, 0x8b]) {
            Wrapping::Gzip
        } else if head.starts_with(&[0x28, 0xb5, 0x2f, 0xfd]) {
            Wrapping::Zstd
        } else {
            Wrapping::Plain
        }
    }
}

/// Buffer of the decompressed (or plain) stream.
const BUFFER: usize = 256 << 10;
/// Buffer between the file and a decompressor.
const RAW_BUFFER: usize = 64 << 10;

/// Bytes of memory an open [`Input`] holds at most, beside a zstd window
/// (which the compressing side chose: 8 MiB at most for levels up to 19).
pub const INPUT_BYTES: u64 = (BUFFER + RAW_BUFFER + (64 << 10)) as u64;

/// Counts the bytes read from the file into the progress, in batches.
struct Counting<'p> {
    file: File,
    progress: &'p dyn Progress,
    pending: u64,
}

impl Read for Counting<'_> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.file.read(buf)?;
        self.pending += n as u64;
        if self.pending >= 1 << 20 || n == 0 {
            self.progress.inc(self.pending);
            self.pending = 0;
        }
        Ok(n)
    }
}

impl Drop for Counting<'_> {
    fn drop(&mut self) {
        if self.pending > 0 {
            self.progress.inc(self.pending);
        }
    }
}

/// A scene file opened for reading: its content, decompressed.
pub struct Input<'p> {
    pub reader: Box<dyn BufRead + 'p>,
    pub wrapping: Wrapping,
}

/// Opens `path`, decompressing it if it is gzip or zstd data. Sets the
/// progress total to the file's size and counts bytes as they are read.
pub fn open<'p>(path: &Path, progress: &'p dyn Progress) -> Result<Input<'p>, Error> {
    let wrapping = Wrapping::of_head(&raw_head(path, 4)?);
    let file = File::open(path).at(path)?;
    progress.set_unit("bytes");
    if let Ok(meta) = file.metadata() {
        progress.set_total(meta.len());
    }
    let counting = Counting {
        file,
        progress,
        pending: 0,
    };
    Ok(Input {
        reader: wrap(counting, wrapping, path)?,
        wrapping,
    })
}

fn wrap<'p, R: Read + 'p>(
    raw: R,
    wrapping: Wrapping,
    path: &Path,
) -> Result<Box<dyn BufRead + 'p>, Error> {
    Ok(match wrapping {
        Wrapping::Plain => Box::new(BufReader::with_capacity(BUFFER, raw)),
        Wrapping::Gzip => Box::new(BufReader::with_capacity(
            BUFFER,
            flate2::bufread::MultiGzDecoder::new(BufReader::with_capacity(RAW_BUFFER, raw)),
        )),
        Wrapping::Zstd => Box::new(BufReader::with_capacity(
            BUFFER,
            zstd::stream::read::Decoder::with_buffer(BufReader::with_capacity(RAW_BUFFER, raw))
                .at(path)?,
        )),
    })
}

/// The first `n` bytes of the file as stored.
pub fn raw_head(path: &Path, n: usize) -> Result<Vec<u8>, Error> {
    let f = File::open(path).at(path)?;
    let mut buf = Vec::with_capacity(n);
    f.take(n as u64).read_to_end(&mut buf).at(path)?;
    Ok(buf)
}

/// The first `n` bytes of the content (decompressed), fewer if it is
/// shorter, and how the file is stored. A damaged compressed stream
/// yields what could be decompressed before the damage.
pub fn head(path: &Path, n: usize) -> Result<(Vec<u8>, Wrapping), Error> {
    let raw = raw_head(path, n)?;
    let wrapping = Wrapping::of_head(&raw);
    if wrapping == Wrapping::Plain {
        return Ok((raw, wrapping));
    }
    let file = File::open(path).at(path)?;
    let mut r = wrap(file, wrapping, path)?;
    let mut buf = vec![0u8; n];
    let mut got = 0;
    while got < n {
        match r.read(&mut buf[got..]) {
            Ok(0) | Err(_) => break,
            Ok(k) => got += k,
        }
    }
    buf.truncate(got);
    Ok((buf, wrapping))
}

/// The file name's extension, lowercase, looking through a `.gz` or
/// `.zst` suffix (`dragon.ply.gz` -> `ply`).
pub fn inner_extension(path: &Path) -> Option<String> {
    let name = path.file_name()?.to_str()?.to_ascii_lowercase();
    let name = name
        .strip_suffix(".gz")
        .or_else(|| name.strip_suffix(".zst"))
        .unwrap_or(&name);
    let (stem, ext) = name.rsplit_once('.')?;
    (!stem.is_empty()).then(|| ext.to_string())
}

/// Maps a read error of the content to an error naming the file; a
/// damaged compressed stream says so.
pub fn read_error(path: &Path, wrapping: Wrapping, e: std::io::Error) -> Error {
    if wrapping != Wrapping::Plain
        && matches!(
            e.kind(),
            std::io::ErrorKind::InvalidData
                | std::io::ErrorKind::InvalidInput
                | std::io::ErrorKind::UnexpectedEof
                | std::io::ErrorKind::Other
        )
    {
        return Error::io(
            path,
            std::io::Error::new(
                e.kind(),
                format!("the {} stream is damaged: {e}", wrapping.name()),
            ),
        );
    }
    Error::io(path, e)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    #[test]
    fn inner_extensions() {
        let e = |s: &str| inner_extension(&PathBuf::from(s));
        assert_eq!(e("a/dragon.ply.gz").as_deref(), Some("ply"));
        assert_eq!(e("x.OBJ.ZST").as_deref(), Some("obj"));
        assert_eq!(e("x.off").as_deref(), Some("off"));
        assert_eq!(e("x.gz"), None);
        assert_eq!(e("noext"), None);
        assert_eq!(e(".ply"), None);
    }

    #[test]
    fn reads_through_gzip_and_zstd() {
        use std::io::Write;
        let dir = tempfile::tempdir().unwrap();
        let text = b"ply\nformat ascii 1.0\n".repeat(1000);
        let gz = dir.path().join("a.ply.gz");
        let mut enc =
            flate2::write::GzEncoder::new(File::create(&gz).unwrap(), flate2::Compression::fast());
        enc.write_all(&text).unwrap();
        enc.finish().unwrap();
        let zs = dir.path().join("a.ply.zst");
        std::fs::write(&zs, zstd::encode_all(&text[..], 3).unwrap()).unwrap();
        for (p, w) in [(&gz, Wrapping::Gzip), (&zs, Wrapping::Zstd)] {
            let (h, wr) = head(p, 10).unwrap();
            assert_eq!((&h[..], wr), (&text[..10], w));
            let mut inp = open(p, &crate::progress::NoProgress).unwrap();
            let mut all = Vec::new();
            inp.reader.read_to_end(&mut all).unwrap();
            assert_eq!(all, text);
        }
    }
}
