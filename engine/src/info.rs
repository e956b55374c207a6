//! `sray info`: what a scene file holds.

use crate::error::{Error, IoContext};
use crate::mesh::MeshOptions;
use crate::progress::Progress;
use crate::scene::{Aabb, Light, Material, MeshFacts, SceneSink, View};
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
    /// Images the materials sample (textures).
    pub textures: u64,
    /// Bounds of all objects, in world coordinates; `null` for a scene of
    /// none.
    pub bbox_min: Option<[f32; 3]>,
    pub bbox_max: Option<[f32; 3]>,
    /// Triangles the polygons and patches make (`n - 2` for a polygon of
    /// `n` vertices).
    pub triangles: u64,
    /// A mesh's vertex table (used by faces or not); for NFF, the
    /// vertices its polygons and patches list.
    pub vertices: u64,
    pub file_bytes: u64,
    /// "none", "zstd" (a database's blocks, or a zstd-wrapped scene file)
    /// or "gzip" (a gzip-wrapped scene file).
    pub compression: &'static str,
    /// Mesh file only: faces skipped as degenerate (repeated or collinear
    /// vertices).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub degenerate_faces: Option<u64>,
    /// Object database only: uncompressed record bytes and block count.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub raw_bytes: Option<u64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub blocks: Option<u64>,
    /// Object database only: the records' size once triangle runs are
    /// expanded (what a scan decodes, and the depth-first tracer holds).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub decoded_bytes: Option<u64>,
    /// Object database only: how blocks store objects: "records" (one per
    /// object, before version 4) or "triangle runs" (consecutive
    /// triangles as shared, bit-packed vertices and one-byte indices).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub layout: Option<&'static str>,
    /// Object database only: the order of its objects: "spatial" (along a
    /// Z-order curve, each with its input id; version 6) or "input".
    #[serde(skip_serializing_if = "Option::is_none")]
    pub order: Option<&'static str>,
    /// Object database only (version 4 on): triangle runs, and the
    /// triangles they hold.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub runs: Option<u64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub run_triangles: Option<u64>,
    /// Object database only: its format version.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub version: Option<u32>,
    /// Object database only (version 3 on): occupied (cell, size class)
    /// pairs of the density summary, and the dense regions the renderers
    /// give grids of their own (none: an empty list).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub density_entries: Option<u64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub dense_regions: Option<Vec<Region>>,
    /// Object database only (version 5): the models stored once, each
    /// with the instances placing it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub models: Option<Vec<ModelInfo>>,
    /// Object database with models only: the triangles the scene renders,
    /// each instance counting its model's (`triangles` counts those
    /// stored).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub placed_triangles: Option<u64>,
}

/// A model of a database: stored once, placed by its instances.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ModelInfo {
    pub triangles: u64,
    pub vertices: u64,
    /// Bytes of the model's own database inside the file.
    pub bytes: u64,
    pub instances: u64,
}

/// The models of `db`, and the triangles its instances place (one scan
/// of the world's objects, to count each model's instances).
fn model_infos(db: &Database) -> Result<Option<(Vec<ModelInfo>, u64)>, Error> {
    if db.models().is_empty() {
        return Ok(None);
    }
    let mut instances = vec![0u64; db.models().len()];
    let mut scan = db.scan()?;
    while let Some(block) = scan.next_block()? {
        for o in block.objects() {
            if let Shape::Instance(i) = o.shape
                && let Some(n) = instances.get_mut(i.model() as usize)
            {
                *n += 1;
            }
        }
    }
    let mut out = Vec::with_capacity(instances.len());
    let mut placed = 0u64;
    for (m, &n) in instances.iter().enumerate() {
        let mdb = db.open_model(m)?;
        let (triangles, vertices) = match (mdb.triangles(), mdb.vertices()) {
            (Some(t), Some(v)) => (t, v),
            _ => scan_counts(&mdb)?,
        };
        placed = placed.saturating_add(triangles.saturating_mul(n));
        out.push(ModelInfo {
            triangles,
            vertices,
            bytes: db.models()[m].bytes,
            instances: n,
        });
    }
    Ok(Some((out, placed)))
}

/// A dense region of a database (see [`crate::grid::Partition`]).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Region {
    pub objects: u64,
    pub bbox_min: [f32; 3],
    pub bbox_max: [f32; 3],
}

/// The dense regions the renderers would plan for `db`, if it has a
/// density summary.
fn dense_regions(db: &Database) -> Option<Vec<Region>> {
    let d = db.density()?;
    let plan = crate::grid::plan_groups(db.sizes(), Some(d), true);
    let r = plan.partition.regions.as_ref().map_or(0, |r| r.count());
    Some(
        (1..=r)
            .map(|g| {
                let (min, max) = bbox_fields(plan.bounds[g], db.origin());
                Region {
                    objects: plan.counts[g],
                    bbox_min: min.unwrap_or([0.0; 3]),
                    bbox_max: max.unwrap_or([0.0; 3]),
                }
            })
            .collect(),
    )
}

/// Bounds in world coordinates: `b` relative to `origin`.
fn bbox_fields(b: Aabb, origin: [f64; 3]) -> (Option<[f32; 3]>, Option<[f32; 3]>) {
    if b.is_empty() {
        (None, None)
    } else {
        let w = |p: [f32; 3]| std::array::from_fn(|i| (p[i] as f64 + origin[i]) as f32);
        (Some(w(b.min)), Some(w(b.max)))
    }
}

/// Triangles and listed vertices of a database, by a scan (for files
/// written before the header recorded them).
fn scan_counts(db: &Database) -> Result<(u64, u64), Error> {
    let (mut t, mut v) = (0, 0);
    let mut scan = db.scan()?;
    while let Some(block) = scan.next_block()? {
        for o in block.objects() {
            let n = o.shape.triangles();
            if n > 0 {
                t += n;
                v += o.shape.listed_vertices();
            }
        }
    }
    Ok((t, v))
}

/// Reads the header of a database, or streams through a scene file (a
/// mesh with the default memory budget).
pub fn scene_info(path: &Path, progress: &dyn Progress) -> Result<SceneInfo, Error> {
    scene_info_with(path, progress, &MeshOptions::default())
}

/// The groups of objects of the database at `path` that the
/// breadth-first tracer holds as aggregates in the grids it plans by
/// default, and the objects they hold: one scan of the whole file.
#[derive(Clone, Copy, Debug, Default, serde::Serialize)]
pub struct AggregateInfo {
    pub aggregates: u64,
    pub aggregate_objects: u64,
}

/// Counts a database's aggregates ([`AggregateInfo`]).
pub fn aggregate_info(path: &Path, progress: &dyn Progress) -> Result<AggregateInfo, Error> {
    use crate::grid::aggregate;
    let db = Database::open(path)?;
    let (specs, partition) =
        crate::bf::plan_grids(&db, &crate::render::RenderOptions::default(), 1 << 30);
    let spec = |g: usize| specs.get(g);
    let mut placed = [(0, None); aggregate::SIZE];
    let mut found = AggregateInfo::default();
    let mut scan = db.scan()?;
    progress.set_total(db.object_count());
    while let Some(block) = scan.next_block()? {
        aggregate::each_group(&block, |group, bounds| {
            if !aggregate::may_be(spec(partition.group(&group[0].bbox)), bounds) {
                return;
            }
            aggregate::place(group, &partition, spec, &mut placed);
            if aggregate::of_grids(group, &placed[..group.len()], bounds, spec).is_some() {
                found.aggregates += 1;
                found.aggregate_objects += group.len() as u64;
            }
        });
        progress.inc(block.object_count as u64);
    }
    Ok(found)
}

/// As [`scene_info`], a mesh within the memory of `opts`.
pub fn scene_info_with(
    path: &Path,
    progress: &dyn Progress,
    opts: &MeshOptions,
) -> Result<SceneInfo, Error> {
    let file_bytes = std::fs::metadata(path).at(path)?.len();
    if is_database(path)? {
        let db = Database::open(path)?;
        let (bbox_min, bbox_max) = bbox_fields(db.bbox(), db.origin());
        let (mut triangles, mut vertices) = match (db.triangles(), db.vertices()) {
            (Some(t), Some(v)) => (t, v),
            _ => scan_counts(&db)?,
        };
        let models = model_infos(&db)?;
        if let Some((m, _)) = &models {
            // Stored: the world's and each model's once.
            triangles += m.iter().map(|m| m.triangles).sum::<u64>();
            vertices += m.iter().map(|m| m.vertices).sum::<u64>();
        }
        return Ok(SceneInfo {
            format: "sdb",
            objects: db.object_count(),
            counts: db.counts(),
            lights: db.scene().lights.len() as u64,
            materials: db.scene().materials.len() as u64,
            material_statements: db.material_statements(),
            textures: db.scene().textures.len() as u64,
            bbox_min,
            bbox_max,
            triangles,
            vertices,
            file_bytes,
            compression: db.compression().name(),
            degenerate_faces: None,
            raw_bytes: Some(db.raw_bytes()),
            blocks: Some(db.block_count()),
            decoded_bytes: Some(db.decoded_bytes()),
            layout: Some(if db.has_runs() {
                "triangle runs"
            } else {
                "records"
            }),
            order: Some(if db.is_spatial() { "spatial" } else { "input" }),
            runs: db.has_runs().then(|| db.run_counts().runs),
            run_triangles: db.has_runs().then(|| db.run_counts().run_triangles),
            version: Some(db.version()),
            density_entries: db.density().map(|d| d.entries.len() as u64),
            dense_regions: dense_regions(&db),
            placed_triangles: models
                .as_ref()
                .map(|(_, p)| (triangles - models_stored(&models)).saturating_add(*p)),
            models: models.map(|(m, _)| m),
        });
    }
    let format = detect_format(path)?;
    let (_, wrapping) = crate::input::head(path, 4)?;
    let mut c = Counter::default();
    let summary = format.read(path, &mut c, progress, opts)?;
    if !c.saw_view && !format.is_mesh() {
        return Err(Error::Scene(format!(
            "{}: the scene has no view ('v')",
            path.display()
        )));
    }
    let (bbox_min, bbox_max) = bbox_fields(c.bbox, c.origin);
    Ok(SceneInfo {
        format: format.name(),
        objects: c.counts.total(),
        counts: c.counts,
        lights: c.lights,
        materials: c.materials.len() as u64,
        material_statements: c.statements,
        textures: c.textures,
        bbox_min,
        bbox_max,
        triangles: c.triangles,
        vertices: c.mesh_vertices.unwrap_or(c.listed_vertices),
        file_bytes,
        compression: wrapping.name(),
        degenerate_faces: summary.mesh.map(|m| m.degenerate),
        raw_bytes: None,
        decoded_bytes: None,
        layout: None,
        order: None,
        runs: None,
        run_triangles: None,
        blocks: None,
        version: None,
        density_entries: None,
        dense_regions: None,
        models: None,
        placed_triangles: None,
    })
}

/// Triangles the models store.
fn models_stored(models: &Option<(Vec<ModelInfo>, u64)>) -> u64 {
    models
        .as_ref()
        .map_or(0, |(m, _)| m.iter().map(|m| m.triangles).sum())
}

/// Counts what a scene stream holds, as the database writer would store it.
#[derive(Default)]
struct Counter {
    counts: KindCounts,
    lights: u64,
    materials: HashSet<crate::scene::MaterialKey>,
    textures: u64,
    statements: u64,
    any_material: bool,
    bbox: Aabb,
    saw_view: bool,
    origin: [f64; 3],
    triangles: u64,
    listed_vertices: u64,
    mesh_vertices: Option<u64>,
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
        let t = s.triangles();
        if t > 0 {
            self.triangles += t;
            self.listed_vertices += s.listed_vertices();
        }
        Ok(())
    }
    fn origin(&mut self, origin: [f64; 3]) -> Result<(), Error> {
        self.origin = origin;
        Ok(())
    }
    fn mesh(&mut self, facts: &MeshFacts) -> Result<(), Error> {
        self.mesh_vertices = Some(self.mesh_vertices.unwrap_or(0) + facts.vertices);
        Ok(())
    }
    fn texture(&mut self, _: &crate::scene::TextureImage) -> Result<u32, Error> {
        self.textures += 1;
        Ok(self.textures as u32 - 1)
    }
}
