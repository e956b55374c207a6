//! The depth-first tracer: the classical in-memory ray tracer over uniform
//! grids (3D-DDA, mailboxing, early termination), one ray tree at a time.
//! It is the reference the breadth-first tracer is checked against, and the
//! fast path for scenes that fit in memory.

mod lanes;
mod mailbox;
pub mod models;
mod object_grid;
mod polygon;
mod pyramid;
mod trace;
mod walk;

pub(crate) use crate::grid::nested::{Boxes, Entry, NESTED, high_first, ray_meets};
pub use object_grid::ObjectGrid;

use crate::error::Error;
use crate::grid::{DEFAULT_DENSITY, GridStat, MAX_CELLS, choose_resolution, plan_groups};
use crate::hit::PrimId;
use crate::intersect::RayQ;
use crate::intersect::{Surface, triangle};
use crate::math::Real;
use crate::objects::{ObjectStore, Slot};
use crate::progress::Progress;
use crate::render::{
    Camera, Cutouts, Frame, GridRes, RenderOptions, RenderStats, ShadeScene, epsilon,
};
use crate::scene::{Aabb, Material};
use crate::sdb::Database;
use crate::shapes::{Patch, Polygon, Prepared, Shape, ShapeKind};
use models::{Models, Placement};
use polygon::EdgeBins;
use std::time::Instant;

/// `prep` or `bins` of a record without that data.
const PLAIN: u32 = u32::MAX;

/// A scene ready for depth-first tracing, borrowing its objects from an
/// [`ObjectStore`].
pub struct DfScene<'t> {
    pub objects: &'t ObjectStore,
    /// The store's records, decoded once (faces need no decoding).
    records: Vec<Held<'t>>,
    preps: Vec<Prepared>,
    edge_bins: Vec<EdgeBins>,
    pub materials: Vec<Material>,
    /// One grid per object group; the last holds the large objects, if any.
    pub grids: Vec<ObjectGrid>,
    /// Whether a grid of more than one voxel is [`ObjectGrid::dense`]:
    /// only then may rays walk alone (see `walk::diverge`).
    has_dense: bool,
    pub shade: ShadeScene,
    pub camera: Camera,
    /// A distance far above the rounding of any hit's position (in either
    /// precision) and above the grids' margin around an object: packets of
    /// rays skip a candidate only when it lies at least this far from them.
    pub slack: f64,
    /// The boxes of each grid's blocks, grown by `slack` (by grid).
    blocks: Vec<pyramid::BlockBounds>,
    /// The models instances place, and each instance's placement (by
    /// `Held::placement`).
    pub models: Models,
    placements: Vec<Placement>,
}

/// An object held as a record, decoded.
pub struct Held<'t> {
    shape: Shape<'t>,
    bbox: Aabb,
    material: u32,
    /// Index into `preps` of its prepared test data, or `PLAIN` for
    /// objects with none worth keeping (spheres, triangles).
    prep: u32,
    /// Index into `edge_bins` of a many-sided polygon's binned edges, or
    /// `PLAIN`.
    bins: u32,
    /// Index into `placements` of an instance's, or `PLAIN`.
    placement: u32,
}

/// One object, ready to be tested: a face's corners, or a decoded record.
#[derive(Clone, Copy)]
pub enum Candidate<'a, 't> {
    /// A triangle or a triangular patch (the test is the same).
    Face {
        kind: ShapeKind,
        v: [[f32; 3]; 3],
    },
    Record(&'a Held<'t>),
    /// A model placed by an instance record.
    Instance(&'a Held<'t>, &'a Placement),
}

impl Candidate<'_, '_> {
    #[inline(always)]
    pub fn kind(&self) -> ShapeKind {
        match self {
            Candidate::Face { kind, .. } => *kind,
            Candidate::Record(h) => h.shape.kind(),
            Candidate::Instance(..) => ShapeKind::Instance,
        }
    }

    #[inline(always)]
    pub fn bbox(&self) -> Aabb {
        match self {
            Candidate::Face { v, .. } => Aabb::of_face(v),
            Candidate::Record(h) | Candidate::Instance(h, _) => h.bbox,
        }
    }

    /// Nearest `t` in `(t_min, t_max)` at which `ray` meets the object:
    /// its kind's test, through its prepared data. A face's test is a
    /// three-vertex polygon's and a three-vertex patch's. An instance is
    /// tested through [`Models`] (this finds nothing).
    #[inline(always)]
    pub fn intersect<R: Real>(&self, s: &DfScene, ray: &RayQ<R>, t_min: R, t_max: R) -> Option<R> {
        match self {
            Candidate::Instance(..) => None,
            Candidate::Face { v, .. } => triangle::intersect(v[0], v[1], v[2], ray, t_min, t_max),
            Candidate::Record(h) => match (h.bins, &h.shape) {
                (_, shape @ Shape::Textured(_)) => {
                    let t = shape.intersect(None, &h.bbox, ray, t_min, t_max)?;
                    match s.models.cutouts() {
                        Some(c) if !c.keeps(shape, h.material, ray) => None,
                        _ => Some(t),
                    }
                }
                (PLAIN, shape) => shape.intersect(s.prep(h), &h.bbox, ray, t_min, t_max),
                (b, Shape::Polygon(p)) => {
                    s.edge_bins[b as usize].intersect(p.vertices, &h.bbox, ray, t_min, t_max)
                }
                (_, shape) => shape.intersect(s.prep(h), &h.bbox, ray, t_min, t_max),
            },
        }
    }
}

/// Memory the depth-first tracer needs for `db`, roughly: the world's
/// objects and grids, and each model's (a model that cannot be opened
/// counts nothing here; the render says what is wrong with it).
pub fn estimate_bytes(db: &Database) -> u64 {
    estimate_one(db)
        + (0..db.models().len())
            .filter_map(|m| db.open_model(m).ok())
            .map(|m| estimate_one(&m))
            .sum::<u64>()
}

fn estimate_one(db: &Database) -> u64 {
    let n = db.object_count();
    let cells = (n as f64 * DEFAULT_DENSITY).min(MAX_CELLS as f64) as u64;
    let faces = db.run_counts().run_triangles;
    // The objects; records decoded (shapes, boxes, materials); a bit per
    // voxel, a count per 64, a start per listing voxel (fewer than the
    // objects, but for tiny scenes) and about three entries per object;
    // the hierarchies of crowded voxels (rare but for dense models in
    // coarse grids: about one 32-byte node per eight objects); a mailbox
    // per thread; each object's voxels, packed, while a grid is built.
    ObjectStore::estimate_bytes(db)
        + size_of::<Held<'_>>() as u64 * (n - faces)
        + cells / 8
        + cells / 16
        + 4 * cells.min(n)
        + 12 * n
        + 4 * n
        + 4 * n * crate::sys::cpus() as u64
        + 4 * n
}

impl<'t> DfScene<'t> {
    /// Decodes the records and builds the grids (the preprocess); opens
    /// the textures with a cache sized from `memory` (see
    /// [`ShadeScene::open`]).
    pub fn new(
        db: &Database,
        objects: &'t ObjectStore,
        models: Models,
        opts: &RenderOptions,
        memory: u64,
    ) -> Result<DfScene<'t>, Error> {
        opts.validate()?;
        let n = objects.len();
        // Voxel entries tag hierarchies with the top bit of an id.
        if n >= NESTED as usize {
            return Err(Error::Invalid(format!(
                "{n} objects are more than depth-first keeps in memory (2^31 at most); \
                 render breadth-first (--mode bf)"
            )));
        }
        let mut records = Vec::with_capacity(objects.records());
        let mut preps = Vec::new();
        let mut edge_bins = Vec::new();
        let mut placements = Vec::new();
        for id in 0..n as u32 {
            let Slot::Record(r) = objects.slot(id) else {
                continue;
            };
            debug_assert_eq!(r as usize, records.len());
            let o = objects.record(r, id);
            let prep = o.shape.prepare();
            let bins = match (&o.shape, &prep) {
                (Shape::Polygon(p), Some(Prepared::Polygon(plane))) => {
                    EdgeBins::new(p.vertices, plane)
                }
                _ => None,
            };
            let mut held = Held {
                shape: o.shape,
                bbox: o.bbox,
                material: o.material,
                prep: PLAIN,
                bins: PLAIN,
                placement: PLAIN,
            };
            if let Shape::Instance(i) = &o.shape {
                if i.model() as usize >= models.len() {
                    return Err(Error::Invalid(format!(
                        "{}: object {id} places model {}, of {}",
                        db.path().display(),
                        i.model(),
                        models.len()
                    )));
                }
                held.placement = placements.len() as u32;
                placements.push(Placement::of(i));
            }
            if let Some(p) = prep {
                held.prep = preps.len() as u32;
                preps.push(p);
            }
            if let Some(b) = bins {
                held.bins = edge_bins.len() as u32;
                edge_bins.push(b);
            }
            records.push(held);
        }
        let plan = plan_groups(db.sizes(), db.density(), opts.multiple_grids);
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(trace::thread_count(opts))
            .build()
            .map_err(|e| Error::Invalid(format!("cannot start threads: {e}")))?;
        // Each object's group, worked out once (each grid's build looks
        // at every object twice), in stretches of ids, one a thread; not
        // needed where there is one grid.
        let group: Vec<u8> = if plan.bounds.len() > 1 {
            let stretches = object_grid::id_stretches(n, pool.current_num_threads());
            object_grid::per_part(&pool, stretches, |_, ids| {
                let mut group = Vec::with_capacity(ids.len());
                objects.each_bbox_in(ids, |_, b| group.push(plan.partition.group(&b) as u8));
                group
            })
            .concat()
        } else {
            Vec::new()
        };
        let mut grids = Vec::with_capacity(plan.bounds.len());
        for (g, (bounds, &count)) in plan.bounds.iter().zip(&plan.counts).enumerate() {
            let res = match (g, opts.grid_res) {
                (0, GridRes::Fixed(r)) => r,
                _ => choose_resolution(bounds, count, opts.grid_density, MAX_CELLS),
            };
            grids.push(ObjectGrid::build(
                objects,
                bounds,
                res,
                &pool,
                opts.aggregates.depth_first(),
                |id| group.is_empty() || group[id] as usize == g,
            )?);
        }
        // The first object outside its grid, if any (each grid's build
        // found its own first).
        if let Some(id) = grids.iter().filter_map(|g| g.outside).min() {
            return Err(crate::grid::outside_its_grid(db, id as u64));
        }
        let eps = epsilon(&db.bbox(), opts.precision);
        let header = db.scene();
        let slack = crate::grid::box_slack(&header.view.from, grids.iter().map(|g| &g.spec));
        let blocks = grids
            .iter()
            .map(|g| pyramid::BlockBounds::new(&g.spec, g.pyramid.height(), slack))
            .collect();
        let materials = models.material_table(&header.materials);
        let (mut shade, _) = ShadeScene::open(db, opts.max_depth, eps, memory)?;
        shade.footprint = Some(crate::render::Footprint::of(
            &header.view,
            opts.width,
            opts.height,
        ));
        let mut models = models;
        models.set_cutouts(Cutouts::new(&materials, shade.textures.clone()));
        let has_dense = grids.iter().any(|g| !g.single_cell() && g.dense());
        Ok(DfScene {
            objects,
            records,
            preps,
            edge_bins,
            materials,
            has_dense,
            grids,
            shade,
            camera: Camera::new(&header.view, opts.width, opts.height)?,
            slack,
            blocks,
            models,
            placements,
        })
    }

    /// Prepared test data of a record, if any was kept.
    #[inline(always)]
    fn prep(&self, h: &Held) -> Option<&Prepared> {
        match h.prep {
            PLAIN => None,
            i => Some(&self.preps[i as usize]),
        }
    }

    /// A many-sided polygon's binned edges, if it has them.
    #[inline(always)]
    fn bins(&self, h: &Held) -> Option<&EdgeBins> {
        match h.bins {
            PLAIN => None,
            i => Some(&self.edge_bins[i as usize]),
        }
    }

    /// Number of objects.
    pub fn len(&self) -> usize {
        self.objects.len()
    }

    pub fn is_empty(&self) -> bool {
        self.objects.is_empty()
    }

    /// Object `id`, ready to be tested.
    #[inline(always)]
    pub fn candidate(&self, id: u32) -> Candidate<'_, 't> {
        match self.objects.slot(id) {
            Slot::Face(f) => Candidate::Face {
                kind: if f.patch {
                    ShapeKind::Patch
                } else {
                    ShapeKind::Polygon
                },
                v: self.objects.positions(&f),
            },
            Slot::Record(r) => self.record_candidate(r),
        }
    }

    /// Record `r` (of [`Slot::Record`]) as a candidate.
    #[inline(always)]
    pub fn record_candidate(&self, r: u32) -> Candidate<'_, 't> {
        let h = &self.records[r as usize];
        match h.placement {
            PLAIN => Candidate::Record(h),
            p => Candidate::Instance(h, &self.placements[p as usize]),
        }
    }

    /// The surface of primitive `prim` at `ray`'s hit at `t`, and its
    /// material: an object's, or a placed model's triangle's.
    pub fn surface_of(
        &self,
        prim: PrimId,
        ray: &RayQ<f64>,
        t: f64,
    ) -> Option<(Surface, &Material)> {
        match prim.instance_parts() {
            None => Some(self.surface(prim.object_index()?, ray, t)),
            Some((i, p)) => match self.candidate(i) {
                Candidate::Instance(_, pl) => {
                    let (surface, m) = self.models.surface(pl, p, ray, t)?;
                    Some((surface, self.materials.get(m as usize)?))
                }
                _ => None,
            },
        }
    }

    /// The surface of object `id` at `ray`'s hit at `t`, and its material.
    pub fn surface(&self, id: u32, ray: &RayQ<f64>, t: f64) -> (Surface, &Material) {
        let (surface, material) = match self.objects.slot(id) {
            Slot::Face(f) => {
                let vertices = self.objects.positions(&f);
                let shape = if f.patch {
                    let normals = self.objects.normals(&f);
                    Shape::Patch(Patch {
                        vertices: &vertices,
                        normals: &normals,
                    })
                    .surface(ray, t)
                } else {
                    Shape::Polygon(Polygon {
                        vertices: &vertices,
                    })
                    .surface(ray, t)
                };
                (shape, f.material)
            }
            Slot::Record(r) => {
                let h = &self.records[r as usize];
                (h.shape.surface(ray, t), h.material)
            }
        };
        (surface, &self.materials[material as usize])
    }

    pub fn grid_stats(&self) -> Vec<GridStat> {
        self.grids
            .iter()
            .map(|g| GridStat {
                objects: g.objects,
                resolution: g.spec.res,
                lo: g.spec.lo,
                hi: g.spec.hi,
                nested_voxels: g.nested_voxels,
                nested_objects: g.nested_entries,
                aggregates: g.aggregates,
            })
            .collect()
    }
}

/// A depth-first render: the frame and the statistics.
pub struct DfOutput {
    pub frame: Frame,
    pub stats: RenderStats,
}

/// Memory a depth-first render's texture tiles may take when no budget
/// is given ([`render`]).
pub const TEXTURE_MEMORY: u64 = 256 << 20;

/// Renders `db` depth-first.
pub fn render(
    db: &Database,
    opts: &RenderOptions,
    progress: &dyn Progress,
) -> Result<DfOutput, Error> {
    render_within(db, opts, TEXTURE_MEMORY, progress)
}

/// Renders `db` depth-first within a budget of `memory` bytes: the
/// objects are held whole (the caller chose this tracer because they
/// fit), the textures' tiles read through a cache sized from it.
pub fn render_within(
    db: &Database,
    opts: &RenderOptions,
    memory: u64,
    progress: &dyn Progress,
) -> Result<DfOutput, Error> {
    let t0 = Instant::now();
    progress.set_message("loading objects, building grids");
    let objects = ObjectStore::load(db, progress)?;
    let models = Models::load(
        db,
        trace::thread_count(opts),
        opts.aggregates.depth_first(),
        progress,
    )?;
    let scene = DfScene::new(db, &objects, models, opts, memory)?;
    let preprocess = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let (frame, rays, tests, intersect) = trace::render(&scene, opts, progress)?;
    // A texture tile that could not be read gave zero texels: no image.
    if let Some(e) = scene.shade.texture_error() {
        return Err(e);
    }
    let trace_seconds = t1.elapsed().as_secs_f64();
    let grids = scene.grid_stats();
    let stats = RenderStats {
        mode: "df".into(),
        objects: db.object_count(),
        width: opts.width,
        height: opts.height,
        depth: opts.max_depth,
        threads: trace::thread_count(opts),
        precision: format!("{:?}", opts.precision).to_lowercase(),
        simd: Some(crate::simd::Isa::choose(opts.simd)?.name().into()),
        epsilon: scene.shade.eps,
        rays,
        intersection_tests: tests.total(),
        intersection_tests_by_kind: tests,
        grid_res: grids[0].resolution,
        grids,
        preprocess_seconds: preprocess,
        trace_seconds,
        intersect_seconds: opts.profile.then_some(intersect),
        shade_seconds: opts.profile.then_some((trace_seconds - intersect).max(0.0)),
        peak_rss_bytes: crate::sys::peak_rss_bytes(),
        textures: scene.shade.tile_reads(),
        ..Default::default()
    };
    Ok(DfOutput { frame, stats })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nff::read_nff_from;
    use crate::progress::NoProgress;
    use crate::render::Precision;
    use crate::sdb::{Compression, DbWriter};
    use std::fmt::Write;
    use std::path::Path;

    /// A small crowd of triangles and spheres on a floor, seen close up.
    fn crowd(dir: &Path) -> Database {
        let mut s = String::from(
            "v\nfrom 1.2 1.0 1.6\nat 0 0.3 0\nup 0 1 0\nangle 40\nhither 0.001\n\
             resolution 32 32\nb 0.1 0.1 0.2\nl 3 8 4 1 1 1\n\
             f 0.6 0.6 0.6 1 0 0 0 1\np 4\n-3 0 -3\n-3 0 3\n3 0 3\n3 0 -3\n\
             f 0.9 0.3 0.2 0.6 0.4 20 0 1\n",
        );
        let mut next = numbers(7);
        for _ in 0..400 {
            let c = [next(), next() + 0.5, next()];
            s.push_str("p 3\n");
            for _ in 0..3 {
                let v: Vec<f64> = c.iter().map(|c| c + 0.15 * next()).collect();
                writeln!(s, "{} {} {}", v[0], v[1], v[2]).unwrap();
            }
        }
        for _ in 0..100 {
            writeln!(s, "s {} 0.05 {} 0.05", 4.0 * next(), 4.0 * next()).unwrap();
        }
        database(dir, "crowd", &s)
    }

    /// Reproducible numbers in [-0.5, 0.5).
    fn numbers(seed: u64) -> impl FnMut() -> f64 {
        let mut x = seed;
        move || {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (x >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        }
    }

    /// The database `name.sdb` in `dir` of the NFF text `nff`.
    fn database(dir: &Path, name: &str, nff: &str) -> Database {
        let path = dir.join(format!("{name}.sdb"));
        let mut w = DbWriter::create(&path, Compression::None).unwrap();
        read_nff_from(
            nff.as_bytes(),
            Path::new(&format!("{name}.nff")),
            &mut w,
            &NoProgress,
        )
        .unwrap();
        w.finish().unwrap();
        Database::open(&path).unwrap()
    }

    /// A grid of one voxel listing every object besides the usual grids:
    /// its hierarchy is what the packets' single-voxel paths walk (no
    /// automatic grid of one voxel is crowded: huge objects get one only
    /// when they are a handful). Objects found twice are tested once, and
    /// the nearest hit does not depend on the order, so the image must not
    /// change.
    #[test]
    fn a_crowded_grid_of_one_voxel_gives_the_same_image() {
        let dir = tempfile::tempdir().unwrap();
        let db = crowd(dir.path());
        let objects = ObjectStore::load(&db, &NoProgress).unwrap();
        for precision in [Precision::Double, Precision::Single] {
            let opts = RenderOptions {
                width: 32,
                height: 32,
                max_depth: 2,
                threads: 1,
                precision,
                ..Default::default()
            };
            let plain =
                DfScene::new(&db, &objects, Models::default(), &opts, TEXTURE_MEMORY).unwrap();
            let (want, ..) = trace::render(&plain, &opts, &NoProgress).unwrap();
            let mut s =
                DfScene::new(&db, &objects, Models::default(), &opts, TEXTURE_MEMORY).unwrap();
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(1)
                .build()
                .unwrap();
            let all = s.grids.iter().fold(Aabb::EMPTY, |mut b, g| {
                b.union(&Aabb {
                    min: g.spec.lo.map(|c| c as f32),
                    max: g.spec.hi.map(|c| c as f32),
                });
                b
            });
            let one = ObjectGrid::build(&objects, &all, [1, 1, 1], &pool, false, |_| true).unwrap();
            assert!(one.single_cell() && one.nested_voxels == 1);
            s.grids.push(one);
            let (got, ..) = trace::render(&s, &opts, &NoProgress).unwrap();
            assert!(
                want.to_rgb8() == got.to_rgb8(),
                "{precision:?}: images differ"
            );
        }
    }

    /// Mirror spheres packed in a box: a dense grid (most voxels list
    /// something), whose reflected rays scatter, so that groups of them
    /// walk alone voxel by voxel (`walk::diverge`). The image and the ray
    /// counts must be the breadth-first tracer's, which walks each ray by
    /// itself, in both precisions and at one and two threads.
    #[test]
    fn lone_walks_in_a_dense_grid_give_the_breadth_first_image() {
        let dir = tempfile::tempdir().unwrap();
        let mut s = String::from(
            "v\nfrom 2.2 1.6 2.6\nat 0 0 0\nup 0 1 0\nangle 35\nhither 0.001\n\
             resolution 40 40\nb 0.1 0.1 0.2\nl 3 8 4 1 1 1\nl -4 6 5 0.6 0.6 0.6\n\
             f 0.8 0.8 0.8 0.3 0.7 20 0 1\n",
        );
        let mut next = numbers(11);
        for _ in 0..1500 {
            let c = [next(), next(), next()];
            writeln!(
                s,
                "s {} {} {} {}",
                c[0],
                c[1],
                c[2],
                0.02 + 0.03 * (next() + 0.5)
            )
            .unwrap();
        }
        let db = database(dir.path(), "mirrors", &s);
        let objects = ObjectStore::load(&db, &NoProgress).unwrap();
        for precision in [Precision::Double, Precision::Single] {
            for threads in [1, 2] {
                let opts = RenderOptions {
                    width: 40,
                    height: 40,
                    max_depth: 4,
                    threads,
                    precision,
                    ..Default::default()
                };
                let scene =
                    DfScene::new(&db, &objects, Models::default(), &opts, TEXTURE_MEMORY).unwrap();
                assert!(scene.grids[0].dense(), "the test needs a dense grid");
                let (frame, rays, ..) = trace::render(&scene, &opts, &NoProgress).unwrap();
                assert!(rays.reflect_rays > 500, "{rays:?}");
                let bf = crate::bf::BfOptions {
                    memory: 1 << 30,
                    store: crate::bf::StoreNumber::Adaptive,
                    spill_dir: None,
                    shading: crate::bf::Shading::Carry,
                    models: Default::default(),
                };
                let want = crate::bf::render(&db, &opts, &bf, &NoProgress).unwrap();
                assert!(
                    want.frame.to_rgb8() == frame.to_rgb8(),
                    "{precision:?}, {threads} threads: images differ"
                );
                assert_eq!(want.stats.rays, rays, "{precision:?}, {threads} threads");
            }
        }
    }
}
