//! Where a scene comes from: a scene file in one of the formats sray
//! reads, an object database, or an SPD generator (`spd:NAME:SIZE`).
//!
//! File formats sit behind one interface, [`SceneFormat`], listed once in
//! [`FORMATS`]; a file's format is told by its content, then by its name.
//! Any of them may be gzip- or zstd-compressed ([`crate::input`]): the
//! content is judged decompressed, the name without `.gz` or `.zst`.

use crate::error::Error;
use crate::mesh::{MeshOptions, MeshSummary};
use crate::nff::read_nff;
use crate::progress::Progress;
use crate::scene::{Material, MeshFacts, SceneSink};
use crate::sdb::Database;
use crate::spd::SpdScene;
use std::fmt;
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
    /// file and the line or byte. `opts` bounds the memory of formats that
    /// need more than a line at a time (meshes).
    fn read(
        &self,
        path: &Path,
        sink: &mut dyn SceneSink,
        progress: &dyn Progress,
        opts: &MeshOptions,
    ) -> Result<ReadSummary, Error>;
    /// Whether `read` reports progress in bytes of the file (else in
    /// objects).
    fn progress_in_bytes(&self) -> bool {
        true
    }
    /// Whether the format is a mesh: no view and no lights of its own
    /// (they come from [`crate::scene::setup`]), and nothing to render
    /// without faces.
    fn is_mesh(&self) -> bool {
        false
    }
}

/// What reading a scene file found besides the scene itself.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ReadSummary {
    /// For a mesh: its vertices, faces and what became of them.
    pub mesh: Option<MeshSummary>,
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
        _: &MeshOptions,
    ) -> Result<ReadSummary, Error> {
        read_nff(path, sink, progress)?;
        Ok(ReadSummary::default())
    }
}

/// The signature of a mesh reader: it streams the mesh into the sink
/// within `opts`' memory and reports what it found.
type MeshReader =
    fn(&Path, &mut dyn SceneSink, &dyn Progress, &MeshOptions) -> Result<MeshSummary, Error>;

/// A mesh file format: everything that tells one from another is data
/// (name, extensions, signature test, reader); what they share as scene
/// formats is written once, in the `SceneFormat` impl below.
pub struct MeshFormat {
    name: &'static str,
    extensions: &'static [&'static str],
    sniff: fn(&[u8]) -> Sniff,
    read: MeshReader,
}

impl SceneFormat for MeshFormat {
    fn name(&self) -> &'static str {
        self.name
    }
    fn extensions(&self) -> &'static [&'static str] {
        self.extensions
    }
    fn sniff(&self, head: &[u8]) -> Sniff {
        (self.sniff)(head)
    }
    fn read(
        &self,
        path: &Path,
        sink: &mut dyn SceneSink,
        progress: &dyn Progress,
        opts: &MeshOptions,
    ) -> Result<ReadSummary, Error> {
        let m = (self.read)(path, sink, progress, opts)?;
        Ok(ReadSummary { mesh: Some(m) })
    }
    fn is_mesh(&self) -> bool {
        true
    }
}

/// PLY: starts with the line `ply`.
pub static PLY: MeshFormat = MeshFormat {
    name: "ply",
    extensions: &["ply"],
    sniff: sniff_ply,
    read: crate::mesh::ply::read_ply,
};

fn sniff_ply(head: &[u8]) -> Sniff {
    if head.starts_with(b"ply\n") || head.starts_with(b"ply\r\n") {
        Sniff::Yes
    } else {
        Sniff::No
    }
}

/// Wavefront OBJ: text whose statements (`v x y z`, `vn`, `vt`, `mtllib`,
/// `usemtl`, `f a/b/c`) no NFF file has.
pub static OBJ: MeshFormat = MeshFormat {
    name: "obj",
    extensions: &["obj"],
    sniff: sniff_obj,
    read: crate::mesh::obj::read_obj,
};

fn sniff_obj(head: &[u8]) -> Sniff {
    if head.contains(&0) {
        return Sniff::No;
    }
    let number = |t: &[u8]| {
        std::str::from_utf8(t)
            .ok()
            .is_some_and(|s| s.parse::<f64>().is_ok())
    };
    for line in head.split(|&b| b == b'\n') {
        let mut w = crate::mesh::text::words(line);
        match w.next() {
            Some(b"vn" | b"vt" | b"mtllib" | b"usemtl") => return Sniff::Yes,
            Some(b"v") => {
                let rest: Vec<&[u8]> = w.collect();
                if rest.len() >= 3 && rest.iter().all(|t| number(t)) {
                    return Sniff::Yes;
                }
            }
            Some(b"f") if line.contains(&b'/') => return Sniff::Yes,
            _ => {}
        }
    }
    Sniff::Maybe
}

/// OFF and its variants: the first word (after `#` comments) is `OFF`,
/// `COFF`, `NOFF`, ...
pub static OFF: MeshFormat = MeshFormat {
    name: "off",
    extensions: &["off", "coff", "noff"],
    sniff: sniff_off,
    read: crate::mesh::off::read_off,
};

fn sniff_off(head: &[u8]) -> Sniff {
    for line in head.split(|&b| b == b'\n') {
        let body = match line.iter().position(|&b| b == b'#') {
            Some(i) => &line[..i],
            None => line,
        };
        if let Some(w) = crate::mesh::text::words(body).next() {
            let variant = w.len() <= 8
                && w.ends_with(b"OFF")
                && w[..w.len() - 3].iter().all(|c| b"STCN4n".contains(c));
            return if variant { Sniff::Yes } else { Sniff::No };
        }
    }
    Sniff::No
}

/// glTF 2.0: a GLB file starts with `glTF`; a `.gltf` file is JSON with
/// an `asset` object.
pub static GLTF: MeshFormat = MeshFormat {
    name: "gltf",
    extensions: &["gltf", "glb"],
    sniff: sniff_gltf,
    read: crate::mesh::gltf_scene::read_gltf,
};

fn sniff_gltf(head: &[u8]) -> Sniff {
    let text = head.trim_ascii_start();
    if head.starts_with(b"glTF")
        || (text.starts_with(b"{") && head.windows(7).any(|w| w == b"\"asset\""))
    {
        Sniff::Yes
    } else {
        Sniff::No
    }
}

/// Every scene file format sray reads (object databases aside, which are
/// rendered in place rather than read as a scene stream). NFF, which has
/// no signature, comes first: of formats that only find a file plausible,
/// the first wins.
pub static FORMATS: &[&dyn SceneFormat] = &[&Nff, &PLY, &OBJ, &OFF, &GLTF];

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

/// Whether the file starts like an object database.
pub fn is_database(path: &Path) -> Result<bool, Error> {
    Ok(crate::input::raw_head(path, 8)? == crate::sdb::MAGIC)
}

/// The format of the scene file at `path`: one that recognises its
/// content; else the one its extension names (whose reader then explains
/// what is wrong with the content, if anything); else one that finds the
/// content plausible; else an error naming the formats there are.
pub fn detect_format(path: &Path) -> Result<&'static dyn SceneFormat, Error> {
    let (head, _) = crate::input::head(path, SNIFF_BYTES)?;
    let judged: Vec<(Sniff, &'static dyn SceneFormat)> =
        FORMATS.iter().map(|f| (f.sniff(&head), *f)).collect();
    if let Some((_, f)) = judged.iter().find(|(s, _)| *s == Sniff::Yes) {
        return Ok(*f);
    }
    let ext = crate::input::inner_extension(path);
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

    /// Streams the scene, in object order, into `sink` (a mesh with the
    /// default memory budget).
    pub fn stream_into(
        &self,
        sink: &mut dyn SceneSink,
        progress: &dyn Progress,
    ) -> Result<(), Error> {
        self.stream_into_with(sink, progress, &MeshOptions::default())
            .map(|_| ())
    }

    /// Streams the scene, in object order, into `sink`; a mesh within the
    /// memory of `opts`.
    pub fn stream_into_with(
        &self,
        sink: &mut dyn SceneSink,
        progress: &dyn Progress,
        opts: &MeshOptions,
    ) -> Result<ReadSummary, Error> {
        match self {
            SceneSource::File { path, format } => format.read(path, sink, progress, opts),
            SceneSource::Spd { scene, size } => {
                scene.generate(*size, sink, progress)?;
                Ok(ReadSummary::default())
            }
            SceneSource::Database(p) => {
                let db = Database::open(p)?;
                stream_database(&db, sink, progress)?;
                Ok(ReadSummary::default())
            }
        }
    }

    /// Whether the source is a mesh file (no view or lights of its own).
    pub fn is_mesh(&self) -> bool {
        matches!(self, SceneSource::File { format, .. } if format.is_mesh())
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
    sink.view(db.world_view())?;
    for l in db.world_lights() {
        sink.light(l)?;
    }
    sink.origin(db.origin())?;
    if db.is_mesh() {
        sink.mesh(&MeshFacts {
            vertices: db.vertices().unwrap_or(0),
            bounds: db.world_bounds(),
            up: None,
        })?;
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
            sink.ranked_object(&obj.shape, obj.rank)?;
        }
        progress.inc(block.object_count as u64);
    }
    Ok(())
}
