//! Models placed by instances: triangles stored once, tested for every
//! placement.
//!
//! A version 5 database stores each model once (a database of its own
//! inside the file) and places it by instance records
//! ([`crate::shapes::Instance`]). Both tracers hold the models in memory
//! with a grid each, in the model's coordinates, and test a ray against an
//! instance here: the ray is taken into the model's coordinates to walk
//! the model's grid, and each triangle it finds is placed (its corners
//! mapped to the world exactly as a copy of the model would have been
//! written, `f32` of the `f64` product) and tested against the world ray.
//! So an instance gives the same hits, bit for bit, as the copy it stands
//! for, and both tracers, which call the same code, the same as each
//! other.
//!
//! The model's grid lists each triangle by its box grown by a margin
//! (`pad`, written with the model: four times the rounding of a placed
//! corner, in the model's units, plus a millionth of the model's size)
//! that covers how far placing the corners in `f32` moves them: a
//! triangle the world ray hits is listed in every voxel of the model's
//! grid that the walk of the mapped ray crosses near the hit, and the
//! walk's early exit (the nearest hit lies before the voxel's far side)
//! cannot pass over a nearer one.

use super::{Boxes, Entry, NESTED, ObjectGrid, high_first, ray_meets};
use crate::error::Error;
use crate::grid::{DEFAULT_DENSITY, Dda, MAX_CELLS, choose_resolution};
use crate::intersect::{Ray, RayQ, Surface, triangle};
use crate::math::{Real, Vec3};
use crate::objects::{ObjectStore, Slot};
use crate::progress::Progress;
use crate::render::Cutouts;
use crate::scene::{Aabb, Material};
use crate::sdb::Database;
use crate::shapes::{Instance, KindCounts, Patch, Polygon, Shape, ShapeKind, Textured};
use glam::{DAffine3, DMat3, DVec3};
use std::sync::Arc;

/// How a model is placed: the transform, its inverse (to walk the
/// model's grid) and the map of normals.
#[derive(Clone, Copy, Debug)]
pub struct Placement {
    pub model: u32,
    m: DAffine3,
    inv: DAffine3,
    normal: DMat3,
}

impl Placement {
    pub fn new(model: u32, m: DAffine3) -> Placement {
        Placement {
            model,
            m,
            inv: m.inverse(),
            normal: m.matrix3.inverse().transpose(),
        }
    }

    /// The placement an instance record holds (validated when read).
    pub fn of(i: &Instance<'_>) -> Placement {
        Placement::new(i.model(), i.transform())
    }

    /// A model's corner, placed: `f32` of the `f64` product. Copies of a
    /// model (a glTF mesh written once per node) are placed by this same
    /// function, so an instance and a copy have the same corners.
    #[inline(always)]
    pub fn point(&self, v: [f32; 3]) -> [f32; 3] {
        place_point(&self.m, v)
    }

    /// A model's normal, placed: the inverse transpose, made unit length
    /// (zero if it cannot be).
    #[inline]
    pub fn normal(&self, n: [f32; 3]) -> [f32; 3] {
        place_normal(&self.normal, n)
    }
}

/// `f32` of `m` applied to `v` in `f64`, summed in a fixed order.
#[inline(always)]
pub fn place_point(m: &DAffine3, v: [f32; 3]) -> [f32; 3] {
    let (x, y, z) = (v[0] as f64, v[1] as f64, v[2] as f64);
    let a = m.matrix3;
    let t = m.translation;
    [
        (a.x_axis.x * x + a.y_axis.x * y + a.z_axis.x * z + t.x) as f32,
        (a.x_axis.y * x + a.y_axis.y * y + a.z_axis.y * z + t.y) as f32,
        (a.x_axis.z * x + a.y_axis.z * y + a.z_axis.z * z + t.z) as f32,
    ]
}

/// A normal mapped by `normal_map` (a transform's inverse transpose) and
/// made unit length, or zero if it cannot be.
#[inline]
pub fn place_normal(normal_map: &DMat3, n: [f32; 3]) -> [f32; 3] {
    (*normal_map * DVec3::from(n.map(f64::from)))
        .try_normalize()
        .unwrap_or(DVec3::ZERO)
        .to_array()
        .map(|c| c as f32)
}

/// One model: its triangles and grid.
pub struct Model {
    objects: ObjectStore,
    grid: ObjectGrid,
    /// Its first material in the render's table (see
    /// [`Models::materials`]).
    material_base: u32,
    /// Margin around each triangle's box in the grid, in model units.
    pad: f64,
    /// The render's alpha-mask cut-outs, if any material has one.
    cutouts: Option<Arc<Cutouts>>,
}

/// A model's triangles' boxes, grown by its margin.
struct Padded<'a> {
    objects: &'a ObjectStore,
    pad: f32,
}

impl Boxes for Padded<'_> {
    fn count(&self) -> usize {
        self.objects.len()
    }

    fn bbox(&self, id: u32) -> Aabb {
        self.grow(self.objects.bbox(id))
    }

    fn each_in(&self, ids: std::ops::Range<u32>, mut f: impl FnMut(u32, Aabb)) {
        self.objects.each_bbox_in(ids, |id, b| f(id, self.grow(b)))
    }
}

impl Padded<'_> {
    fn grow(&self, b: Aabb) -> Aabb {
        Aabb {
            min: b.min.map(|c| (c - self.pad).next_down()),
            max: b.max.map(|c| (c + self.pad).next_up()),
        }
    }
}

/// The models of a database: each held in memory ([`Models::load`]), or
/// known by its materials and read when needed ([`Models::open`],
/// [`Models::read_model`]).
#[derive(Default)]
pub struct Models {
    list: Vec<Option<Model>>,
    /// Each model's first material in the render's table.
    bases: Vec<u32>,
    /// The models' materials, after the world's in the render's table:
    /// a model's material `k` is entry `material_base + k` there.
    materials: Vec<Material>,
    /// Threads that build a model's grid when it is read (the render's
    /// `--threads`).
    threads: usize,
    /// Whether a model's grid holds crowded groups as aggregates (the
    /// depth-first tracer's setting: a model's grid is its structure).
    aggregates: bool,
    /// Each model's triangles, from its header.
    triangles: Vec<u64>,
    /// The render's alpha-mask cut-outs ([`Models::set_cutouts`]).
    cutouts: Option<Arc<Cutouts>>,
}

impl Models {
    /// Reads and indexes every model of `db` (none for a database
    /// without models), building each grid on `threads` threads, with
    /// aggregates if `aggregates`.
    pub fn load(
        db: &Database,
        threads: usize,
        aggregates: bool,
        progress: &dyn Progress,
    ) -> Result<Models, Error> {
        let mut models = Models::open(db, threads, aggregates)?;
        for m in 0..models.len() {
            progress.set_message(&format!("loading model {} of {}", m + 1, models.len()));
            models.list[m] = Some(models.read_model(db, m, progress)?);
        }
        Ok(models)
    }

    /// The models of `db` by their materials alone: none is read. A
    /// model read later builds its grid on `threads` threads, with
    /// aggregates if `aggregates`.
    pub fn open(db: &Database, threads: usize, aggregates: bool) -> Result<Models, Error> {
        let n = db.models().len();
        let mut models = Models {
            list: (0..n).map(|_| None).collect(),
            bases: Vec::with_capacity(n),
            materials: Vec::new(),
            threads: threads.max(1),
            aggregates,
            triangles: Vec::with_capacity(n),
            cutouts: None,
        };
        let world_materials = db.scene().materials.len();
        for m in 0..n {
            let mdb = db.open_model(m)?;
            let base = u32::try_from(world_materials + models.materials.len())
                .ok()
                .filter(|&b| b as usize + mdb.scene().materials.len() <= u32::MAX as usize)
                .ok_or_else(|| bad_model(db, m, "too many materials".into()))?;
            models.bases.push(base);
            models.triangles.push(mdb.object_count());
            models.materials.extend_from_slice(&mdb.scene().materials);
        }
        Ok(models)
    }

    /// Reads model `m` of `db` and builds its grid.
    pub fn read_model(
        &self,
        db: &Database,
        m: usize,
        progress: &dyn Progress,
    ) -> Result<Model, Error> {
        let mdb = db.open_model(m)?;
        let objects = ObjectStore::load(&mdb, progress)?;
        if objects.len() >= NESTED as usize {
            return Err(bad_model(
                db,
                m,
                format!("{} triangles are too many for one model", objects.len()),
            ));
        }
        for id in 0..objects.len() as u32 {
            if corners_of(&objects, id).is_none() {
                return Err(bad_model(db, m, format!("object {id} is not a triangle")));
            }
        }
        let pad = db.models()[m].pad;
        let padded = Padded {
            objects: &objects,
            pad: pad as f32,
        };
        let mut bounds = Aabb::EMPTY;
        padded.each(&mut |_, b| bounds.union(&b));
        // No voxel narrower than four margins: a margin is the rounding
        // of a placed corner, which for a model placed far from the
        // origin (or scaled down) may be a sizeable part of it, and
        // boxes grown by several voxels each would multiply the entries.
        let mut res = choose_resolution(&bounds, objects.len() as u64, DEFAULT_DENSITY, MAX_CELLS);
        for (i, r) in res.iter_mut().enumerate() {
            let side = (bounds.max[i] - bounds.min[i]) as f64;
            let most = (side / (4.0 * pad)).floor().clamp(1.0, u32::MAX as f64) as u32;
            *r = (*r).min(most).max(1);
        }
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(self.threads)
            .build()
            .map_err(|e| Error::Invalid(format!("cannot start threads: {e}")))?;
        let grid = ObjectGrid::build(&padded, &bounds, res, &pool, self.aggregates, |_| true)?;
        Ok(Model {
            objects,
            grid,
            material_base: self.bases[m],
            pad,
            cutouts: self.cutouts.clone(),
        })
    }

    /// Sets the render's alpha-mask cut-outs (see
    /// [`crate::render::Cutouts`]), for the models held and those read
    /// later.
    pub fn set_cutouts(&mut self, c: Option<Arc<Cutouts>>) {
        for m in self.list.iter_mut().flatten() {
            m.cutouts = c.clone();
        }
        self.cutouts = c;
    }

    /// The render's alpha-mask cut-outs, if any material has one.
    pub fn cutouts(&self) -> Option<&Cutouts> {
        self.cutouts.as_deref()
    }

    /// The models' materials, to follow the world's in the render's
    /// table (the indices [`Models::surface`] gives refer to it).
    pub fn materials(&self) -> &[Material] {
        &self.materials
    }

    /// The world's materials followed by the models'.
    pub fn material_table(&self, world: &[Material]) -> Vec<Material> {
        let mut all = world.to_vec();
        all.extend_from_slice(&self.materials);
        all
    }

    /// Bytes each model of `db` takes once loaded, about (from their
    /// headers, before reading them): its triangles and its grid.
    pub fn estimate_each(db: &Database) -> Vec<u64> {
        (0..db.models().len())
            .map(|m| {
                db.open_model(m).map_or(0, |m| {
                    ObjectStore::estimate_bytes(&m) + 24 * m.object_count()
                })
            })
            .collect()
    }

    /// Bytes all the models of `db` take once loaded, about.
    pub fn estimate_bytes(db: &Database) -> u64 {
        Self::estimate_each(db).iter().sum()
    }

    pub fn is_empty(&self) -> bool {
        self.list.is_empty()
    }

    pub fn len(&self) -> usize {
        self.list.len()
    }

    /// The triangles of model `m` (0 for a model the file lacks).
    pub fn triangles(&self, m: u32) -> u64 {
        self.triangles.get(m as usize).copied().unwrap_or(0)
    }

    /// Whether every model is in memory.
    pub fn all_held(&self) -> bool {
        self.list.iter().all(Option::is_some)
    }

    /// Bytes held: the models' triangles and grids, and their materials.
    pub fn bytes(&self) -> u64 {
        self.list.iter().flatten().map(Model::bytes).sum::<u64>() + 32 * self.materials.len() as u64
    }

    /// The model `pl` places, if it is held.
    #[inline(always)]
    fn model(&self, pl: &Placement) -> Option<&Model> {
        self.list.get(pl.model as usize)?.as_ref()
    }

    /// See [`Model::nearest`]; nothing if the model is not held.
    #[inline]
    pub fn nearest<R: Real>(
        &self,
        pl: &Placement,
        ray: Ray<'_, R>,
        tests: &mut KindCounts,
    ) -> Option<(R, u32)> {
        self.model(pl)?.nearest(pl, ray, tests)
    }

    /// See [`Model::blocks`]; `false` if the model is not held.
    #[inline]
    pub fn blocks<R: Real>(&self, pl: &Placement, ray: Ray<'_, R>, tests: &mut KindCounts) -> bool {
        self.model(pl).is_some_and(|m| m.blocks(pl, ray, tests))
    }

    /// See [`Model::surface`]; nothing if the model is not held.
    pub fn surface(
        &self,
        pl: &Placement,
        prim: u32,
        ray: &RayQ<f64>,
        t: f64,
    ) -> Option<(Surface, u32)> {
        self.model(pl)?.surface(pl, prim, ray, t)
    }
}

/// An error in model `m` of `db`.
fn bad_model(db: &Database, m: usize, message: String) -> Error {
    Error::Database {
        file: db.path().to_path_buf(),
        location: format!("model {m}"),
        message,
    }
}

impl Model {
    /// Bytes held: triangles and grid.
    pub fn bytes(&self) -> u64 {
        self.objects.bytes() + self.grid.bytes()
    }

    /// The nearest hit of `ray` on this model placed by `pl`: its distance
    /// and the primitive, ties to the smaller primitive. Each triangle
    /// tested counts in `tests` by its kind.
    #[inline]
    pub fn nearest<R: Real>(
        &self,
        pl: &Placement,
        ray: Ray<'_, R>,
        tests: &mut KindCounts,
    ) -> Option<(R, u32)> {
        let Ray {
            q,
            o,
            d,
            t_min,
            t_max,
        } = ray;
        let mut best: Option<(R, u32)> = None;
        let mut upper = t_max;
        self.walk(pl, o, d, t_min.to_f64(), t_max.to_f64(), &mut |id| {
            if let Some(t) = self.test(pl, id, q, t_min, upper, tests) {
                let wins = match best {
                    None => true,
                    Some((bt, bid)) => t < bt || (t == bt && id < bid),
                };
                if wins {
                    best = Some((t, id));
                    upper = t.next_up();
                }
            }
            // Keep walking while the best hit may lie beyond this voxel.
            Walk::Go(best.map(|(t, _)| t.to_f64()))
        });
        best
    }

    /// Whether this model placed by `pl` blocks `ray` anywhere in its
    /// interval.
    #[inline]
    pub fn blocks<R: Real>(&self, pl: &Placement, ray: Ray<'_, R>, tests: &mut KindCounts) -> bool {
        let Ray {
            q,
            o,
            d,
            t_min,
            t_max,
        } = ray;
        let mut hit = false;
        self.walk(pl, o, d, t_min.to_f64(), t_max.to_f64(), &mut |id| {
            if self.test(pl, id, q, t_min, t_max, tests).is_some() {
                hit = true;
                Walk::Stop
            } else {
                Walk::Go(None)
            }
        });
        hit
    }

    /// The surface of primitive `prim` of this model placed by `pl` where
    /// `ray` meets it at `t`, and its material's index in the render's
    /// table (see [`Models::materials`]): the surface of the copy of that
    /// triangle the placement stands for.
    pub fn surface(
        &self,
        pl: &Placement,
        prim: u32,
        ray: &RayQ<f64>,
        t: f64,
    ) -> Option<(Surface, u32)> {
        if prim as usize >= self.objects.len() {
            return None;
        }
        let tri = corners_of(&self.objects, prim)?;
        let v = tri.v.map(|p| pl.point(p));
        let n = tri.n.map(|n| n.map(|x| pl.normal(x)));
        let surface = match (&n, tri.attrs) {
            (_, Some((uvs, colors))) => Shape::Textured(Textured {
                vertices: &v,
                normals: n.as_ref().map_or(&[][..], |n| &n[..]),
                uvs,
                colors,
            })
            .surface(ray, t),
            (Some(n), None) => Shape::Patch(Patch {
                vertices: &v,
                normals: n,
            })
            .surface(ray, t),
            (None, None) => Shape::Polygon(Polygon { vertices: &v }).surface(ray, t),
        };
        Some((surface, self.material_base + tri.material))
    }
}

/// What a walk's visitor says after each triangle: stop, or go on with
/// the best hit so far (if any), before which the walk may end.
enum Walk {
    Stop,
    Go(Option<f64>),
}

impl Model {
    /// Walks the model's grid along the ray mapped into the model's
    /// coordinates, giving `f` each triangle listed in the voxels crossed
    /// (a triangle may come more than once), nearest voxels first.
    #[inline]
    fn walk(
        &self,
        pl: &Placement,
        o: Vec3,
        d: Vec3,
        t_min: f64,
        t_max: f64,
        f: &mut impl FnMut(u32) -> Walk,
    ) {
        let om = pl.inv.transform_point3(o);
        let dm = pl.inv.transform_vector3(d);
        let inv = Vec3::new(1.0 / dm.x, 1.0 / dm.y, 1.0 / dm.z);
        let g = &self.grid;
        let hf = high_first(dm);
        let mut best: Option<f64> = None;
        let mut stop = false;
        let mut visit = |cell: usize, best: &mut Option<f64>, stop: &mut bool| {
            g.visit(cell, hf, (), &mut |e| match e {
                Entry::Box(b, ()) => {
                    ray_meets(om, inv, t_min, best.unwrap_or(t_max), b, self.pad).then_some(())
                }
                Entry::Object(id, ()) => match f(id) {
                    Walk::Stop => {
                        *stop = true;
                        None
                    }
                    Walk::Go(b) => {
                        *best = b;
                        Some(())
                    }
                },
            });
        };
        if g.single_cell() {
            visit(0, &mut best, &mut stop);
            return;
        }
        let Some(mut w) = Dda::start(&g.spec, om, dm, inv, t_min, t_max) else {
            return;
        };
        loop {
            visit(w.index, &mut best, &mut stop);
            if stop || best.is_some_and(|b| b < w.t_exit()) || !w.advance() {
                break;
            }
        }
    }

    /// Tests triangle `id`, placed, against the world ray.
    #[inline(always)]
    fn test<R: Real>(
        &self,
        pl: &Placement,
        id: u32,
        q: &RayQ<R>,
        t_min: R,
        t_max: R,
        tests: &mut KindCounts,
    ) -> Option<R> {
        let (v, kind, masked) = match self.objects.slot(id) {
            Slot::Face(f) => (
                self.objects.positions(&f),
                if f.patch {
                    ShapeKind::Patch
                } else {
                    ShapeKind::Polygon
                },
                None,
            ),
            Slot::Record(_) => {
                let tri = corners_of(&self.objects, id)?;
                let kind = match (tri.attrs, tri.n) {
                    (Some(_), _) => ShapeKind::Textured,
                    (None, Some(_)) => ShapeKind::Patch,
                    (None, None) => ShapeKind::Polygon,
                };
                let masked = match (&self.cutouts, tri.attrs) {
                    (Some(c), Some(a)) => Some((c, a, tri.material)),
                    _ => None,
                };
                (tri.v, kind, masked)
            }
        };
        tests.add(kind);
        let placed = v.map(|p| pl.point(p));
        let [a, b, c] = placed;
        let t = triangle::intersect(a, b, c, q, t_min, t_max)?;
        // A cut-out sees the placed triangle, as it sees its copy.
        if let Some((cut, (uvs, colors), material)) = masked {
            let shape = Shape::Textured(Textured {
                vertices: &placed,
                normals: &[],
                uvs,
                colors,
            });
            if !cut.keeps(&shape, self.material_base + material, q) {
                return None;
            }
        }
        Some(t)
    }
}

/// Three corners (or normals) of a triangle.
type Corners = [[f32; 3]; 3];

/// A textured triangle's texture coordinates and packed colours (see
/// [`Textured`]), borrowed from its record.
type CornerAttrs<'a> = (&'a [[f32; 2]], &'a [[u32; 2]]);

/// A model triangle: its corners, its normals (a patch's, or a textured
/// triangle's if it has them), a textured triangle's texture coordinates
/// and colours (borrowed from the record), and its material.
struct Tri<'a> {
    v: Corners,
    n: Option<Corners>,
    attrs: Option<CornerAttrs<'a>>,
    material: u32,
}

/// Model triangle `id`; `None` if the object is not a triangle.
fn corners_of(objects: &ObjectStore, id: u32) -> Option<Tri<'_>> {
    let three = |v: &[[f32; 3]]| [v[0], v[1], v[2]];
    match objects.slot(id) {
        Slot::Face(f) => Some(Tri {
            v: objects.positions(&f),
            n: f.patch.then(|| objects.normals(&f)),
            attrs: None,
            material: f.material,
        }),
        Slot::Record(r) => {
            let o = objects.record(r, id);
            let (v, n, attrs) = match o.shape {
                Shape::Polygon(p) if p.vertices.len() == 3 => (three(p.vertices), None, None),
                Shape::Patch(p) if p.vertices.len() == 3 => {
                    (three(p.vertices), Some(three(p.normals)), None)
                }
                Shape::Textured(t) => (
                    three(t.vertices),
                    (!t.normals.is_empty()).then(|| three(t.normals)),
                    Some((t.uvs, t.colors)),
                ),
                _ => return None,
            };
            Some(Tri {
                v,
                n,
                attrs,
                material: o.material,
            })
        }
    }
}
