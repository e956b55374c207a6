//! The one error type of the engine, naming the file, scene or option it
//! is about.

use std::path::{Path, PathBuf};

/// Every failure the engine reports. Each names what it is about: the file
/// and line of bad NFF input, the file and block of a bad object database.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("{}: {err}", path.display())]
    Io { path: PathBuf, err: std::io::Error },

    #[error("{}:{line}: {message}", file.display())]
    Nff {
        file: PathBuf,
        line: u64,
        message: String,
    },

    /// Malformed input in a mesh file (PLY, OBJ, OFF, MTL): where in the
    /// file, a line of text or a byte of binary data.
    #[error("{}:{at}: {message}", file.display())]
    Parse {
        file: PathBuf,
        at: At,
        message: String,
    },

    #[error("{}: {location}: {message}", file.display())]
    Database {
        file: PathBuf,
        /// "header", "tables", or "block N (byte offset M)".
        location: String,
        message: String,
    },

    /// A scene that is well-formed text but not a renderable scene.
    #[error("{0}")]
    Scene(String),

    /// Options that cannot work together, or values out of range.
    #[error("{0}")]
    Invalid(String),

    /// Work stopped by request (Ctrl-C, a cancelled job).
    #[error("cancelled")]
    Cancelled,
}

/// Where in a file: a line (text) or a byte offset (binary data, counted
/// in the decompressed stream of a `.gz` or `.zst` file).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum At {
    Line(u64),
    Byte(u64),
}

impl std::fmt::Display for At {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            At::Line(n) => write!(f, "{n}"),
            At::Byte(n) => write!(f, " byte {n}"),
        }
    }
}

impl Error {
    pub fn io(path: impl AsRef<Path>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.as_ref().to_path_buf(),
            err: source,
        }
    }
}

/// Attaches a path to an `io::Result`.
pub trait IoContext<T> {
    fn at(self, path: impl AsRef<Path>) -> Result<T, Error>;
}

impl<T> IoContext<T> for std::io::Result<T> {
    fn at(self, path: impl AsRef<Path>) -> Result<T, Error> {
        self.map_err(|e| Error::io(path, e))
    }
}
