//! `sray info`: what a scene file holds.

use crate::error::{Error, IoContext};
use crate::progress::Progress;
use crate::scene::{Aabb, Light, Material, SceneSink, View};
use crate::sdb::{Database, MAX_MATERIALS};
use crate::shapes::{KindCounts, Shape};
use crate::source::{detect_format, is_database};
use serde::Serialize;
use std::collections::HashSet;
use std::path::Path;

/// The facts `sray info` reports. Field names are the JSON keys.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SceneInfo {
    /// The scene file's format ("nff", ...), or "sdb".
    pub format: &'static str,
    pub objects: u64,
    pub counts: KindCounts,
    pub lights: u64,
    /// Distinct materials.
    pub materials: u64,
    /// Material statements (`f` lines) in the scene as written.
    pub material_statements: u64,
    /// Bounds of all objects; `null` for a scene of none.
    pub bbox_min: Option<[f32; 3]>,
    pub bbox_max: Option<[f32; 3]>,
    pub file_bytes: u64,
    /// "none" or "zstd".
    pub compression: &'static str,
    /// Object database only: uncompressed record bytes and block count.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub raw_bytes: Option<u64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub blocks: Option<u64>,
}

fn bbox_fields(b: Aabb) -> (Option<[f32; 3]>, Option<[f32; 3]>) {
    if b.is_empty() {
        (None, None)
    } else {
        (Some(b.min), Some(b.max))
    }
}

/// Reads the header of a database, or streams through an NFF file.
pub fn scene_info(path: &Path, progress: &dyn Progress) -> Result<SceneInfo, Error> {
    let file_bytes = std::fs::metadata(path).at(path)?.len();
    if is_database(path)? {
        let db = Database::open(path)?;
        let (bbox_min, bbox_max) = bbox_fields(db.bbox());
        return Ok(SceneInfo {
            format: "sdb",
            objects: db.object_count(),
            counts: db.counts(),
            lights: db.scene().lights.len() as u64,
            materials: db.scene().materials.len() as u64,
            material_statements: db.material_statements(),
            bbox_min,
            bbox_max,
            file_bytes,
            compression: db.compression().name(),
            raw_bytes: Some(db.raw_bytes()),
            blocks: Some(db.block_count()),
        });
    }
    let format = detect_format(path)?;
    let mut c = Counter::default();
    format.read(path, &mut c, progress)?;
    if !c.saw_view {
        return Err(Error::Scene(format!(
            "{}: the scene has no view ('v')",
            path.display()
        )));
    }
    let (bbox_min, bbox_max) = bbox_fields(c.bbox);
    Ok(SceneInfo {
        format: format.name(),
        objects: c.counts.total(),
        counts: c.counts,
        lights: c.lights,
        materials: c.materials.len() as u64,
        material_statements: c.statements,
        bbox_min,
        bbox_max,
        file_bytes,
        compression: "none",
        raw_bytes: None,
        blocks: None,
    })
}

/// Counts what a scene stream holds, as the database writer would store it.
#[derive(Default)]
struct Counter {
    counts: KindCounts,
    lights: u64,
    materials: HashSet<[u32; 8]>,
    statements: u64,
    any_material: bool,
    bbox: Aabb,
    saw_view: bool,
}

impl SceneSink for Counter {
    fn background(&mut self, _: [f32; 3]) -> Result<(), Error> {
        Ok(())
    }
    fn view(&mut self, _: &View) -> Result<(), Error> {
        self.saw_view = true;
        Ok(())
    }
    fn light(&mut self, _: &Light) -> Result<(), Error> {
        self.lights += 1;
        Ok(())
    }
    fn material(&mut self, m: &Material) -> Result<(), Error> {
        self.statements += 1;
        self.any_material = true;
        if self.materials.len() >= MAX_MATERIALS {
            return Err(Error::Scene(format!(
                "more than {MAX_MATERIALS} distinct materials"
            )));
        }
        self.materials.insert(m.key());
        Ok(())
    }
    fn object(&mut self, s: &Shape<'_>) -> Result<(), Error> {
        if !self.any_material {
            // The database gives objects before any `f` the default material.
            self.materials.insert(Material::DEFAULT.key());
            self.any_material = true;
        }
        self.counts.add(s.kind());
        self.bbox.union(&s.bounds());
        Ok(())
    }
}
