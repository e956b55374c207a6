//! The depth-first tracer: the classical in-memory ray tracer over uniform
//! grids (3D-DDA, mailboxing, early termination), one ray tree at a time.
//! It is the reference the breadth-first tracer is checked against, and the
//! fast path for scenes that fit in memory.

mod lanes;
mod nested;
mod object_grid;
mod packet;
mod polygon;
mod single;
mod trace;

pub use object_grid::ObjectGrid;

use crate::error::Error;
use crate::grid::{DEFAULT_DENSITY, GridStat, MAX_CELLS, choose_resolution, plan_groups};
use crate::intersect::RayQ;
use crate::math::Real;
use crate::objects::ObjectTable;
use crate::progress::Progress;
use crate::render::{Camera, Frame, GridRes, RenderOptions, RenderStats, ShadeScene, epsilon};
use crate::scene::{Aabb, Material};
use crate::sdb::Database;
use crate::shapes::{Prepared, Shape};
use polygon::EdgeBins;
use std::time::Instant;

/// `prep_of` entry of objects without prepared data.
const PLAIN: u32 = u32::MAX;

/// A scene ready for depth-first tracing, borrowing its objects' geometry
/// from an [`ObjectTable`].
pub struct DfScene<'t> {
    /// Each object's shape, decoded once.
    pub shapes: Vec<Shape<'t>>,
    pub bboxes: Vec<Aabb>,
    /// Index into `preps` of each object's prepared test data, or
    /// `PLAIN` for objects with none worth keeping (spheres, triangles).
    pub prep_of: Vec<u32>,
    pub preps: Vec<Prepared>,
    /// Index into `edge_bins` of each many-sided polygon's binned edges,
    /// or `PLAIN`.
    pub bins_of: Vec<u32>,
    pub edge_bins: Vec<EdgeBins>,
    pub material_of: Vec<u32>,
    pub materials: Vec<Material>,
    /// One grid per object group; the last holds the large objects, if any.
    pub grids: Vec<ObjectGrid>,
    pub shade: ShadeScene,
    pub camera: Camera,
    /// A distance far above the rounding of any hit's position (in either
    /// precision) and above the grids' margin around an object: packets of
    /// rays skip a candidate only when it lies at least this far from them.
    pub slack: f64,
    pub tune: Tune,
}

/// Knobs of the packet tracer. The defaults were chosen by instruction
/// counts (callgrind) over the seven SPD scenes; any values give the same
/// images.
#[derive(Clone, Copy, Debug)]
pub struct Tune {
    /// Side of a block of eye rays traced as one packet (at most
    /// `PACKET_SIDE`).
    pub eye_side: usize,
    /// Fewest rays worth walking as a packet.
    pub min_packet: u32,
    /// A packet walks together if the voxels it covers per slab are at
    /// most `worth` times the voxels its rays would visit one by one.
    pub worth: f64,
    /// Lanes are culled per candidate when the lines pass within `apex`
    /// voxels of one point.
    pub apex: f64,
    /// Whether shadow rays, and rays spawned at hits, may go in packets.
    pub shadow_packets: bool,
    pub spawn_packets: bool,
}

impl Default for Tune {
    fn default() -> Tune {
        Tune {
            eye_side: lanes::PACKET_SIDE,
            min_packet: 3,
            worth: 0.5,
            apex: 0.25,
            shadow_packets: true,
            spawn_packets: true,
        }
    }
}

/// Memory the depth-first tracer needs for `db`, roughly.
pub fn estimate_bytes(db: &Database) -> u64 {
    let n = db.object_count();
    let cells = (n as f64 * DEFAULT_DENSITY).min(MAX_CELLS as f64) as u64;
    // Records and offsets; decoded shapes, boxes and materials; voxel
    // starts and about two voxel entries per object; if voxels are
    // crowded, their hierarchies (about one 32-byte node per two objects);
    // a mailbox per thread.
    ObjectTable::estimate_bytes(db)
        + (std::mem::size_of::<Shape<'_>>() + std::mem::size_of::<Aabb>() + 8) as u64 * n
        + 4 * cells
        + 8 * n
        + 16 * n
        + 4 * n * crate::sys::cpus() as u64
}

impl<'t> DfScene<'t> {
    /// Decodes the objects and builds the grids (the preprocess).
    pub fn new(
        db: &Database,
        objects: &'t ObjectTable,
        opts: &RenderOptions,
    ) -> Result<DfScene<'t>, Error> {
        opts.validate()?;
        let n = objects.len();
        // Voxel entries tag hierarchies with the top bit of an id.
        if n >= nested::NESTED as usize {
            return Err(Error::Invalid(format!(
                "{n} objects are more than depth-first keeps in memory (2^31 at most); \
                 render breadth-first (--mode bf)"
            )));
        }
        let mut shapes = Vec::with_capacity(n);
        let mut bboxes = Vec::with_capacity(n);
        let mut material_of = Vec::with_capacity(n);
        let mut prep_of = Vec::with_capacity(n);
        let mut preps = Vec::new();
        let mut bins_of = Vec::with_capacity(n);
        let mut edge_bins = Vec::new();
        for id in 0..n as u32 {
            let o = objects.get(id);
            shapes.push(o.shape);
            bboxes.push(o.bbox);
            material_of.push(o.material);
            let prep = o.shape.prepare();
            let bins = match (&o.shape, &prep) {
                (Shape::Polygon(p), Some(Prepared::Polygon(plane))) => {
                    EdgeBins::new(p.vertices, plane)
                }
                _ => None,
            };
            match prep {
                None => prep_of.push(PLAIN),
                Some(p) => {
                    prep_of.push(preps.len() as u32);
                    preps.push(p);
                }
            }
            match bins {
                None => bins_of.push(PLAIN),
                Some(b) => {
                    bins_of.push(edge_bins.len() as u32);
                    edge_bins.push(b);
                }
            }
        }
        let plan = plan_groups(db.sizes(), db.density(), opts.multiple_grids);
        // Each object's group, worked out once (each grid's build looks
        // at every object twice).
        let group: Vec<u8> = bboxes
            .iter()
            .map(|b| plan.partition.group(b) as u8)
            .collect();
        let mut grids = Vec::with_capacity(plan.bounds.len());
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(trace::thread_count(opts))
            .build()
            .map_err(|e| Error::Invalid(format!("cannot start threads: {e}")))?;
        for (g, (bounds, &count)) in plan.bounds.iter().zip(&plan.counts).enumerate() {
            let res = match (g, opts.grid_res) {
                (0, GridRes::Fixed(r)) => r,
                _ => choose_resolution(bounds, count, opts.grid_density, MAX_CELLS),
            };
            grids.push(ObjectGrid::build(&bboxes, bounds, res, &pool, |id| {
                group[id] as usize == g
            })?);
        }
        for (id, b) in bboxes.iter().enumerate() {
            if !grids[group[id] as usize].spec.holds(b) {
                return Err(crate::grid::outside_its_grid(db, id as u64));
            }
        }
        let eps = epsilon(&db.bbox(), opts.precision);
        // Single precision rounds a position to about 6e-8 of its size;
        // the grids' margin is 1e-6 of a voxel. Eye rays start at the eye,
        // which may lie far outside the grids: their hits are rounded
        // relative to the eye's distance from the origin too.
        let header = db.scene();
        let mut scale: f64 = header
            .view
            .from
            .iter()
            .fold(0.0, |m, c| m.max(2.0 * c.abs()));
        for g in &grids {
            for i in 0..3 {
                scale = scale
                    .max(g.spec.hi[i] - g.spec.lo[i])
                    .max(g.spec.lo[i].abs())
                    .max(g.spec.hi[i].abs());
            }
        }
        let slack = 1e-5 * scale;
        Ok(DfScene {
            shapes,
            bboxes,
            prep_of,
            preps,
            bins_of,
            edge_bins,
            material_of,
            materials: header.materials.clone(),
            grids,
            shade: ShadeScene::new(header, opts.max_depth, eps),
            camera: Camera::new(&header.view, opts.width, opts.height)?,
            slack,
            tune: Tune::default(),
        })
    }

    /// Prepared test data of object `id`, if any was kept.
    #[inline(always)]
    pub fn prep(&self, id: u32) -> Option<&Prepared> {
        match self.prep_of[id as usize] {
            PLAIN => None,
            i => Some(&self.preps[i as usize]),
        }
    }

    /// Nearest `t` in `(t_min, t_max)` at which `ray` meets object `id`:
    /// the object's kind's test, through its prepared data.
    #[inline(always)]
    pub fn intersect<R: Real>(&self, id: u32, ray: &RayQ<R>, t_min: R, t_max: R) -> Option<R> {
        let i = id as usize;
        match (self.bins_of[i], &self.shapes[i]) {
            (PLAIN, shape) => shape.intersect(self.prep(id), &self.bboxes[i], ray, t_min, t_max),
            (b, Shape::Polygon(p)) => {
                self.edge_bins[b as usize].intersect(p.vertices, &self.bboxes[i], ray, t_min, t_max)
            }
            (_, shape) => shape.intersect(self.prep(id), &self.bboxes[i], ray, t_min, t_max),
        }
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
            })
            .collect()
    }
}

/// A depth-first render: the frame and the statistics.
pub struct DfOutput {
    pub frame: Frame,
    pub stats: RenderStats,
}

/// Renders `db` depth-first.
pub fn render(
    db: &Database,
    opts: &RenderOptions,
    progress: &dyn Progress,
) -> Result<DfOutput, Error> {
    let t0 = Instant::now();
    progress.set_message("loading objects, building grids");
    let objects = ObjectTable::load(db, progress)?;
    let scene = DfScene::new(db, &objects, opts)?;
    let preprocess = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let (frame, rays, tests, intersect) = trace::render(&scene, opts, progress)?;
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
        let mut x: u64 = 7;
        let mut next = || {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (x >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
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
        let path = dir.join("crowd.sdb");
        let mut w = DbWriter::create(&path, Compression::None).unwrap();
        read_nff_from(s.as_bytes(), Path::new("crowd.nff"), &mut w, &NoProgress).unwrap();
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
        let objects = ObjectTable::load(&db, &NoProgress).unwrap();
        for precision in [Precision::Double, Precision::Single] {
            let opts = RenderOptions {
                width: 32,
                height: 32,
                max_depth: 2,
                threads: 1,
                precision,
                ..Default::default()
            };
            let plain = DfScene::new(&db, &objects, &opts).unwrap();
            let (want, ..) = trace::render(&plain, &opts, &NoProgress).unwrap();
            let mut s = DfScene::new(&db, &objects, &opts).unwrap();
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
            let one = ObjectGrid::build(&s.bboxes, &all, [1, 1, 1], &pool, |_| true).unwrap();
            assert!(one.single_cell() && one.nested_voxels == 1);
            s.grids.push(one);
            let (got, ..) = trace::render(&s, &opts, &NoProgress).unwrap();
            assert!(
                want.to_rgb8() == got.to_rgb8(),
                "{precision:?}: images differ"
            );
        }
    }
}
