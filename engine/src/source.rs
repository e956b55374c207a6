//! Where a scene comes from: a scene file in one of the formats sray
//! reads, an object database, or an SPD generator (`spd:NAME:SIZE`).
//!
//! File formats sit behind one interface, [`SceneFormat`], listed once in
//! [`FORMATS`]; a file's format is told by its content, then by its name.

use crate::error::{Error, IoContext};
use crate::nff::read_nff;
use crate::progress::Progress;
use crate::scene::{Material, SceneSink};
use crate::sdb::Database;
use crate::spd::SpdScene;
use std::fmt;
use std::io::Read;
use std::path::{Path, PathBuf};

/// How sure a format is that a file's first bytes are its own.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Sniff {
    No,
    /// Could be (e.g. any text for NFF, which has no magic).
    Maybe,
    /// A signature of the format.
    Yes,
}

/// A scene file format: how to recognise a file of it and how to stream
/// one into a [`SceneSink`].
pub trait SceneFormat: Sync {
    /// Short name, as `sray info` reports it.
    fn name(&self) -> &'static str;
    /// File name extensions, lowercase, without the dot.
    fn extensions(&self) -> &'static [&'static str];
    /// Judges the first bytes of a file (up to [`SNIFF_BYTES`]).
    fn sniff(&self, head: &[u8]) -> Sniff;
    /// Streams the scene into `sink`, in object order; errors name the
    /// file and the line or byte.
    fn read(
        &self,
        path: &Path,
        sink: &mut dyn SceneSink,
        progress: &dyn Progress,
    ) -> Result<(), Error>;
    /// Whether `read` reports progress in bytes of the file (else in
    /// objects).
    fn progress_in_bytes(&self) -> bool {
        true
    }
}

/// Bytes of a file's start that formats judge it by.
pub const SNIFF_BYTES: usize = 4096;

/// NFF: text, no magic; any text file might be one.
pub struct Nff;

impl SceneFormat for Nff {
    fn name(&self) -> &'static str {
        "nff"
    }
    fn extensions(&self) -> &'static [&'static str] {
        &["nff"]
    }
    /// Text (no NUL bytes) may be NFF; nothing marks it as surely NFF.
    fn sniff(&self, head: &[u8]) -> Sniff {
        if head.contains(&0) {
            Sniff::No
        } else {
            Sniff::Maybe
        }
    }
    fn read(
        &self,
        path: &Path,
        sink: &mut dyn SceneSink,
        progress: &dyn Progress,
    ) -> Result<(), Error> {
        read_nff(path, sink, progress)
    }
}

/// Every scene file format sray reads (object databases aside, which are
/// rendered in place rather than read as a scene stream).
pub static FORMATS: &[&dyn SceneFormat] = &[&Nff];

/// Where a scene comes from.
#[derive(Clone)]
pub enum SceneSource {
    /// A scene file, read by its format.
    File {
        path: PathBuf,
        format: &'static dyn SceneFormat,
    },
    /// An object database, read in place.
    Database(PathBuf),
    /// An SPD generator.
    Spd { scene: SpdScene, size: u32 },
}

impl fmt::Debug for SceneSource {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SceneSource::File { path, format } => {
                write!(f, "File({}, {})", path.display(), format.name())
            }
            other => write!(f, "{other}"),
        }
    }
}

impl PartialEq for SceneSource {
    fn eq(&self, o: &Self) -> bool {
        match (self, o) {
            (
                SceneSource::File { path, format },
                SceneSource::File {
                    path: p2,
                    format: f2,
                },
            ) => path == p2 && format.name() == f2.name(),
            (SceneSource::Database(a), SceneSource::Database(b)) => a == b,
            (
                SceneSource::Spd { scene, size },
                SceneSource::Spd {
                    scene: s2,
                    size: z2,
                },
            ) => scene == s2 && size == z2,
            _ => false,
        }
    }
}

impl fmt::Display for SceneSource {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SceneSource::File { path, .. } | SceneSource::Database(path) => {
                write!(f, "{}", path.display())
            }
            SceneSource::Spd { scene, size } => write!(f, "spd:{scene}:{size}"),
        }
    }
}

/// The first bytes of a file (fewer if it is shorter).
fn head(path: &Path, n: usize) -> Result<Vec<u8>, Error> {
    let f = std::fs::File::open(path).at(path)?;
    let mut buf = Vec::with_capacity(n);
    f.take(n as u64).read_to_end(&mut buf).at(path)?;
    Ok(buf)
}

/// Whether the file starts like an object database.
pub fn is_database(path: &Path) -> Result<bool, Error> {
    Ok(head(path, 8)? == crate::sdb::MAGIC)
}

/// The format of the scene file at `path`: one that recognises its
/// content; else the one its extension names (whose reader then explains
/// what is wrong with the content, if anything); else one that finds the
/// content plausible; else an error naming the formats there are.
pub fn detect_format(path: &Path) -> Result<&'static dyn SceneFormat, Error> {
    let head = head(path, SNIFF_BYTES)?;
    let judged: Vec<(Sniff, &'static dyn SceneFormat)> =
        FORMATS.iter().map(|f| (f.sniff(&head), *f)).collect();
    if let Some((_, f)) = judged.iter().find(|(s, _)| *s == Sniff::Yes) {
        return Ok(*f);
    }
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase());
    if let Some(ext) = &ext
        && let Some(f) = FORMATS
            .iter()
            .find(|f| f.extensions().contains(&ext.as_str()))
    {
        return Ok(*f);
    }
    if let Some((_, f)) = judged.iter().find(|(s, _)| *s == Sniff::Maybe) {
        return Ok(*f);
    }
    let names: Vec<&str> = FORMATS.iter().map(|f| f.name()).collect();
    Err(Error::Scene(format!(
        "{}: not a scene file sray reads (formats: {}, and sray object databases)",
        path.display(),
        names.join(", ")
    )))
}

impl SceneSource {
    /// An NFF file.
    pub fn nff(path: impl Into<PathBuf>) -> SceneSource {
        SceneSource::File {
            path: path.into(),
            format: &Nff,
        }
    }

    /// `spd:NAME[:SIZE]`, or a path to a scene file or an object database
    /// (told apart by content first, then by name).
    pub fn parse(s: &str) -> Result<SceneSource, Error> {
        if let Some(rest) = s.strip_prefix("spd:") {
            let (name, size) = match rest.split_once(':') {
                Some((n, z)) => (n, Some(z)),
                None => (rest, None),
            };
            let scene: SpdScene = name.parse().map_err(Error::Invalid)?;
            let size = match size {
                None => scene.default_size(),
                Some(z) => z.parse().map_err(|_| {
                    Error::Invalid(format!("SPD size factor '{z}' is not a whole number"))
                })?,
            };
            let max = scene.max_size();
            if size == 0 || size > max {
                return Err(Error::Invalid(format!(
                    "{scene} size factor {size} is out of range 1..={max}"
                )));
            }
            return Ok(SceneSource::Spd { scene, size });
        }
        let path = PathBuf::from(s);
        if is_database(&path)? {
            return Ok(SceneSource::Database(path));
        }
        let format = detect_format(&path)?;
        Ok(SceneSource::File { path, format })
    }

    /// Streams the scene, in object order, into `sink`.
    pub fn stream_into(
        &self,
        sink: &mut dyn SceneSink,
        progress: &dyn Progress,
    ) -> Result<(), Error> {
        match self {
            SceneSource::File { path, format } => format.read(path, sink, progress),
            SceneSource::Spd { scene, size } => scene.generate(*size, sink, progress),
            SceneSource::Database(p) => {
                let db = Database::open(p)?;
                stream_database(&db, sink, progress)
            }
        }
    }
}

/// Replays a database as a scene stream: header first, then objects with a
/// material statement wherever the material changes.
pub fn stream_database(
    db: &Database,
    sink: &mut dyn SceneSink,
    progress: &dyn Progress,
) -> Result<(), Error> {
    let scene = db.scene();
    progress.set_total(db.object_count());
    sink.background(scene.background)?;
    sink.view(&scene.view)?;
    for l in &scene.lights {
        sink.light(l)?;
    }
    let mut current: Option<u32> = None;
    let mut scan = db.scan()?;
    while let Some(block) = scan.next_block()? {
        for obj in block.objects() {
            if current != Some(obj.material) {
                let m: &Material = &scene.materials[obj.material as usize];
                sink.material(m)?;
                current = Some(obj.material);
            }
            sink.object(&obj.shape)?;
        }
        progress.inc(block.object_count as u64);
    }
    Ok(())
}
