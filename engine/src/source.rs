//! Where a scene comes from: an NFF file, an object database, or an SPD
//! generator (`spd:NAME:SIZE`).

use crate::error::{Error, IoContext};
use crate::nff::read_nff;
use crate::progress::Progress;
use crate::scene::{Material, SceneSink};
use crate::sdb::Database;
use crate::spd::SpdScene;
use std::fmt;
use std::io::Read;
use std::path::{Path, PathBuf};

#[derive(Clone, Debug, PartialEq, Eq)]
pub enum SceneSource {
    Nff(PathBuf),
    Database(PathBuf),
    Spd { scene: SpdScene, size: u32 },
}

impl fmt::Display for SceneSource {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SceneSource::Nff(p) | SceneSource::Database(p) => write!(f, "{}", p.display()),
            SceneSource::Spd { scene, size } => write!(f, "spd:{scene}:{size}"),
        }
    }
}

/// Whether the file starts like an object database.
pub fn is_database(path: &Path) -> Result<bool, Error> {
    let mut f = std::fs::File::open(path).at(path)?;
    let mut magic = [0u8; 8];
    let mut n = 0;
    while n < 8 {
        match f.read(&mut magic[n..]).at(path)? {
            0 => break,
            k => n += k,
        }
    }
    Ok(n == 8 && magic == *b"SRAYSDB\0")
}

impl SceneSource {
    /// `spd:NAME[:SIZE]`, or a path to an `.nff` or `.sdb` file (told apart
    /// by content, not by name).
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
            Ok(SceneSource::Database(path))
        } else {
            Ok(SceneSource::Nff(path))
        }
    }

    /// Streams the scene, in object order, into `sink`.
    pub fn stream_into(
        &self,
        sink: &mut dyn SceneSink,
        progress: &dyn Progress,
    ) -> Result<(), Error> {
        match self {
            SceneSource::Nff(p) => read_nff(p, sink, progress),
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
