//! Shading one round (the paper's Section 2.5, Pseudocode 4): the round's
//! rays and their results are read together in ray order; misses and
//! shadow results go straight to the frame; hits gather in memory-sized
//! sets, each sorted by object id and joined with one front-to-back scan of
//! the objects, where they are shaded. The rays they spawn go to an
//! external sort that puts the next round in a fixed order.

use super::records::{HitRec, Outcome, RayKind, RayRec, SPAWN_SLOTS};
use crate::error::Error;
use crate::intersect::{RayQ, Surface};
use crate::math::Vec3;
use crate::models::{Models, Placement};
use crate::render::{RayCounts, ShadeScene, Spawn, shade, to_fixed};
use crate::scene::Material;
use crate::sdb::{Database, ObjectRef};
use crate::shapes::Shape;
use crate::spill::ExternalSorter;
use rayon::prelude::*;
use serde::Serialize;

#[derive(Clone, Debug, Default, Serialize)]
pub struct ShadeStats {
    pub hits: u64,
    pub sets: u64,
    pub db_scans: u64,
    pub db_bytes_read: u64,
    /// Blocks the joins passed over (none of their objects was hit).
    pub db_blocks_skipped: u64,
    /// Models read by the joins (when they are not held).
    pub model_reads: u64,
}

pub struct ShadeSetup<'a> {
    pub db: &'a Database,
    /// The models the database's instances place.
    pub models: &'a Models,
    /// The hit set's memory, reused from round to round.
    pub set: &'a mut Vec<HitRec>,
    /// Hits with their surfaces, waiting to be shaded in order.
    pub carried: &'a mut Vec<Carried>,
    /// Per-chunk outputs of the parallel shading, reused.
    pub outputs: &'a mut Vec<SetOutput>,
    pub radix: &'a mut crate::spill::RadixScratch,
    pub materials: &'a [Material],
    pub shade: &'a ShadeScene,
    /// Hits per set.
    pub set_cap: usize,
}

/// Next-round rays, sorted by `key`.
pub type NextRays = ExternalSorter<RayRec, u64, fn(&RayRec) -> u64>;

pub fn ray_key(r: &RayRec) -> u64 {
    r.key
}

/// Shades a run of a round's rays. `rays` yields them in id order from
/// `first`; `results` their results in the same order. Colour goes to
/// `contribute` (pixel corner, fixed-point colour).
#[allow(clippy::too_many_arguments)]
pub fn shade_round(
    setup: &mut ShadeSetup<'_>,
    pool: &rayon::ThreadPool,
    first: u64,
    rays: &mut dyn Iterator<Item = Result<RayRec, Error>>,
    results: &mut dyn FnMut() -> Result<Option<Outcome>, Error>,
    contribute: &mut dyn FnMut(u32, [i64; 3]),
    next: &mut NextRays,
    counts: &mut RayCounts,
) -> Result<ShadeStats, Error> {
    let mut st = ShadeStats::default();
    let mut set = std::mem::take(setup.set);
    set.clear();
    let mut carried = std::mem::take(setup.carried);
    carried.clear();
    for (id, ray) in (first..).zip(rays) {
        let ray = ray?;
        let out = results()?
            .ok_or_else(|| Error::Invalid(format!("no intersection result for ray {id}")))?;
        let res = out.res;
        if res.ray != id {
            return Err(Error::Invalid(format!(
                "intersection results out of order: ray {id} got the result of ray {}",
                res.ray
            )));
        }
        if ray.is_shadow() {
            if res.prim.is_none() {
                contribute(ray.corner, to_fixed(ray.payload));
            }
        } else if res.prim.is_none() {
            contribute(ray.corner, to_fixed(setup.shade.background(ray.payload[0])));
        } else {
            if ray.kind() == RayKind::Eye {
                counts.eye_hit_rays += 1;
            }
            st.hits += 1;
            if out.has_surface != 0 {
                // The surface came with the result: shade now, in ray
                // order, so the spawned rays come out in key order.
                carried.push(Carried { ray, id, out });
                if carried.len() >= setup.set_cap.clamp(1, CARRY_BATCH) {
                    shade_carried(setup, pool, &mut carried, next, contribute, counts)?;
                }
            } else {
                set.push(HitRec {
                    ray,
                    id,
                    t: res.t,
                    prim: res.prim,
                });
                if set.len() >= setup.set_cap.max(1) {
                    shade_set(setup, pool, &mut set, next, contribute, counts, &mut st)?;
                }
            }
        }
    }
    if results()?.is_some() {
        return Err(Error::Invalid("more intersection results than rays".into()));
    }
    if !carried.is_empty() {
        shade_carried(setup, pool, &mut carried, next, contribute, counts)?;
    }
    if !set.is_empty() {
        shade_set(setup, pool, &mut set, next, contribute, counts, &mut st)?;
    }
    *setup.set = set;
    *setup.carried = carried;
    Ok(st)
}

/// What one chunk of a shading set spawned, and its counts: on cache
/// lines of its own, as [`ChunkOut`].
#[repr(align(128))]
#[derive(Default)]
pub struct SetOutput {
    pub rays: Vec<RayRec>,
    /// Light the shaded surfaces give off (pixel corner, colour).
    pub contributions: Vec<(u32, [i64; 3])>,
    pub counts: RayCounts,
    /// Hits whose shading reads a texture, left for [`shade_textured`].
    pending: Vec<Pending>,
}

/// A hit of a shading set whose shading reads a texture: its place in
/// the set, the (texture, tile) its lookup starts in, and its surface.
#[derive(Clone, Copy, Debug)]
struct Pending {
    at: u32,
    key: u64,
    material: u32,
    surf: Surface,
}

/// What one thread's chunk of a batch gives back (see [`shade_indexed`]).
/// On cache lines of its own (two, as lines are prefetched in pairs):
/// neighbouring chunks are filled by different threads at once, and each
/// push writes the vectors' lengths and the counts here; sharing a line,
/// they would bounce between the cores at every ray (false sharing).
#[repr(align(128))]
#[derive(Default)]
pub struct ChunkOut {
    rays: Vec<RayRec>,
    contributions: Vec<(u32, [i64; 3])>,
    /// Hits without a surface, for the join, in ray order.
    joins: Vec<HitRec>,
    counts: RayCounts,
    hits: u64,
    error: Option<Error>,
}

impl ChunkOut {
    /// Bytes its buffers hold.
    pub fn bytes(&self) -> usize {
        use std::mem::size_of;
        self.rays.capacity() * size_of::<RayRec>()
            + self.contributions.capacity() * size_of::<(u32, [i64; 3])>()
            + self.joins.capacity() * size_of::<HitRec>()
    }
}

/// [`shade_round`] of `results.len()` rays that can be had by id, with
/// their results in memory: batches of rays are read, sorted out and
/// shaded by all threads (each chunk of a batch by one), not read one by
/// one on this thread. Colour and spawned rays are handed on in ray order
/// chunk by chunk; hits without a surface go to the join as in
/// [`shade_round`].
#[allow(clippy::too_many_arguments)]
pub fn shade_indexed(
    setup: &mut ShadeSetup<'_>,
    pool: &rayon::ThreadPool,
    first: u64,
    ray_at: &(dyn Fn(u64) -> RayRec + Sync),
    results: &[Outcome],
    chunk_outs: &mut Vec<ChunkOut>,
    contribute: &mut dyn FnMut(u32, [i64; 3]),
    next: &mut NextRays,
    counts: &mut RayCounts,
) -> Result<ShadeStats, Error> {
    let mut st = ShadeStats::default();
    let mut set = std::mem::take(setup.set);
    set.clear();
    let (materials, shade_scene) = (setup.materials, setup.shade);
    let n = results.len();
    // As many rays at once as hits are shaded at once on the other path.
    let batch = setup.set_cap.clamp(1, CARRY_BATCH);
    let chunks = pool.current_num_threads().max(1) * 4;
    let mut start = 0;
    while start < n {
        let end = (start + batch).min(n);
        let chunk = (end - start).div_ceil(chunks).max(64);
        let n_chunks = (end - start).div_ceil(chunk);
        if chunk_outs.len() < n_chunks {
            chunk_outs.resize_with(n_chunks, Default::default);
        }
        let outs = &mut chunk_outs[..n_chunks];
        pool.install(|| {
            outs.par_iter_mut().enumerate().for_each(|(k, out)| {
                out.rays.clear();
                out.contributions.clear();
                out.joins.clear();
                out.counts = RayCounts::default();
                out.hits = 0;
                out.error = None;
                let lo = start + k * chunk;
                let hi = (lo + chunk).min(end);
                for (i, res_out) in (lo..hi).zip(&results[lo..hi]) {
                    let id = first + i as u64;
                    let ray = ray_at(i as u64);
                    let res = res_out.res;
                    if res.ray != id {
                        out.error = Some(Error::Invalid(format!(
                            "intersection results out of order: ray {id} got the result of ray {}",
                            res.ray
                        )));
                        return;
                    }
                    if ray.is_shadow() {
                        if res.prim.is_none() {
                            out.contributions.push((ray.corner, to_fixed(ray.payload)));
                        }
                    } else if res.prim.is_none() {
                        let bg = shade_scene.background(ray.payload[0]);
                        out.contributions.push((ray.corner, to_fixed(bg)));
                    } else {
                        if ray.kind() == RayKind::Eye {
                            out.counts.eye_hit_rays += 1;
                        }
                        out.hits += 1;
                        if res_out.has_surface != 0 {
                            let h = Carried {
                                ray,
                                id,
                                out: *res_out,
                            };
                            shade_one_carried(
                                materials,
                                shade_scene,
                                &h,
                                &mut out.rays,
                                &mut out.contributions,
                                &mut out.counts,
                            );
                        } else {
                            out.joins.push(HitRec {
                                ray,
                                id,
                                t: res.t,
                                prim: res.prim,
                            });
                        }
                    }
                }
            })
        });
        let mut parts: Vec<&[RayRec]> = Vec::with_capacity(n_chunks);
        for out in chunk_outs[..n_chunks].iter_mut() {
            if let Some(e) = out.error.take() {
                return Err(e);
            }
            *counts += out.counts;
            st.hits += out.hits;
            for &(corner, c) in &out.contributions {
                contribute(corner, c);
            }
            parts.push(&out.rays);
        }
        pool.install(|| next.extend_from_slices(&parts))?;
        for out in chunk_outs[..n_chunks].iter() {
            for h in &out.joins {
                set.push(*h);
                if set.len() >= setup.set_cap.max(1) {
                    shade_set(setup, pool, &mut set, next, contribute, counts, &mut st)?;
                }
            }
        }
        start = end;
    }
    if !set.is_empty() {
        shade_set(setup, pool, &mut set, next, contribute, counts, &mut st)?;
    }
    *setup.set = set;
    Ok(st)
}

/// Most hits shaded together when their surfaces came with them. Such a
/// batch needs no pass over the objects, so nothing is gained by making it
/// as large as the budget allows; a small one stays in cache and spares
/// the page faults of a buffer the size of the round.
const CARRY_BATCH: usize = 1 << 14;

/// A hit whose surface came with its result.
#[derive(Clone, Copy, Debug)]
pub struct Carried {
    ray: RayRec,
    id: u64,
    out: Outcome,
}

/// Shades `items` with `shade_one` in parallel chunks (four a thread),
/// each into an output of its own, whose light and rays are then handed
/// on in chunk order.
fn shade_in_chunks<T: Sync>(
    setup: &mut ShadeSetup<'_>,
    pool: &rayon::ThreadPool,
    items: &[T],
    next: &mut NextRays,
    contribute: &mut dyn FnMut(u32, [i64; 3]),
    counts: &mut RayCounts,
    shade_one: impl Fn(&T, &mut SetOutput) + Sync,
) -> Result<(), Error> {
    let chunks = pool.current_num_threads().max(1) * 4;
    let chunk = items.len().div_ceil(chunks).max(64);
    let n_chunks = items.len().div_ceil(chunk);
    if setup.outputs.len() < n_chunks {
        setup.outputs.resize_with(n_chunks, Default::default);
    }
    let outputs = &mut setup.outputs[..n_chunks];
    pool.install(|| {
        items
            .par_chunks(chunk)
            .zip(outputs.par_iter_mut())
            .for_each(|(part, o)| {
                o.rays.clear();
                o.contributions.clear();
                o.counts = RayCounts::default();
                for item in part {
                    shade_one(item, o);
                }
            })
    });
    let parts = gather(&setup.outputs[..n_chunks], contribute, counts);
    pool.install(|| next.extend_from_slices(&parts))?;
    Ok(())
}

/// Shades hits whose surfaces came with them, in parallel chunks whose
/// outputs are appended in order: the spawned rays stay in key order.
fn shade_carried(
    setup: &mut ShadeSetup<'_>,
    pool: &rayon::ThreadPool,
    carried: &mut Vec<Carried>,
    next: &mut NextRays,
    contribute: &mut dyn FnMut(u32, [i64; 3]),
    counts: &mut RayCounts,
) -> Result<(), Error> {
    let (materials, shade_scene) = (setup.materials, setup.shade);
    shade_in_chunks(setup, pool, carried, next, contribute, counts, |h, o| {
        shade_one_carried(
            materials,
            shade_scene,
            h,
            &mut o.rays,
            &mut o.contributions,
            &mut o.counts,
        )
    })?;
    carried.clear();
    Ok(())
}

/// The chunks' spawned rays, in order, after adding their counts to
/// `counts` and handing their light on to `contribute`.
fn gather<'o>(
    outputs: &'o [SetOutput],
    contribute: &mut dyn FnMut(u32, [i64; 3]),
    counts: &mut RayCounts,
) -> Vec<&'o [RayRec]> {
    let mut parts: Vec<&[RayRec]> = Vec::with_capacity(outputs.len());
    for o in outputs {
        *counts += o.counts;
        for &(corner, c) in &o.contributions {
            contribute(corner, c);
        }
        parts.push(&o.rays);
    }
    parts
}

/// Shades one hit whose surface came with it.
fn shade_one_carried(
    materials: &[Material],
    shade_scene: &ShadeScene,
    h: &Carried,
    out: &mut Vec<RayRec>,
    emitted: &mut Vec<(u32, [i64; 3])>,
    c: &mut RayCounts,
) {
    let r = &h.ray;
    let (o, d) = (Vec3::from_array(r.o), Vec3::from_array(r.d));
    // The point as a primitive's `surface` computes it.
    let p = RayQ::from_vec3(o, d).at(h.out.res.t).into();
    let surf = Surface {
        p,
        ng: Vec3::from_array(h.out.ng),
        ns: Vec3::from_array(h.out.ns),
        // A hit with attributes is never carried (see `offer`).
        attrs: crate::intersect::Attrs::NONE,
    };
    let mat = &materials[h.out.material as usize];
    shade_surface(shade_scene, r, h.id, &surf, mat, out, emitted, c);
}

/// Sorts a set of hits by object and shades it in one scan of the objects.
fn shade_set(
    setup: &mut ShadeSetup<'_>,
    pool: &rayon::ThreadPool,
    set: &mut Vec<HitRec>,
    next: &mut NextRays,
    contribute: &mut dyn FnMut(u32, [i64; 3]),
    counts: &mut RayCounts,
    st: &mut ShadeStats,
) -> Result<(), Error> {
    // Hits arrive in ray order; a stable sort by object (an instance's
    // hits by the instance record) keeps that order within each object.
    let key = |h: &HitRec| h.prim.world_index() as u64;
    crate::spill::radix_sort_by_key(set, key, setup.radix);
    st.sets += 1;
    let mut scan = setup.db.scan()?;
    let mut at = 0;
    // Hits on instances of models not held: shaded once the world's
    // objects are done, each model read once for the set.
    let mut deferred: Vec<(u32, Placement)> = Vec::new();
    // Hits whose shading reads a texture: shaded after the scan, in the
    // order of the tiles they read.
    let mut pending: Vec<Pending> = Vec::new();
    while at < set.len() {
        // A block holding none of the hit objects is passed over unread.
        if let Some(end) = scan.next_block_end()
            && key(&set[at]) >= end
            && scan.skip_block()?
        {
            continue;
        }
        let Some(block) = scan.next_block()? else {
            break;
        };
        let first = block.first_object;
        let end = first + block.object_count as u64;
        let stop = at + set[at..].partition_point(|h| key(h) < end);
        if stop == at {
            continue;
        }
        let objects: Vec<ObjectRef<'_>> = block.objects().collect();
        let objs = &objects;
        // A hit names an instance's triangle exactly when its object is an
        // instance, and a triangle its model has: a hit from elsewhere (a
        // worker's results) that does not is an error, not a pixel left
        // unshaded.
        for h in &set[at..stop] {
            let k = key(h);
            let bad = match (&objs[(k - first) as usize].shape, h.prim.instance_parts()) {
                (Shape::Instance(i), Some((_, p))) => {
                    let n = setup.models.triangles(i.model());
                    (u64::from(p) >= n).then(|| {
                        format!("names triangle {p} of model {}, which has {n}", i.model())
                    })
                }
                (Shape::Instance(_), None) => Some("names no triangle of the instance".into()),
                (_, Some((_, p))) => Some(format!(
                    "names triangle {p} of an object that is not an instance"
                )),
                (_, None) => None,
            };
            if let Some(why) = bad {
                return Err(Error::Invalid(format!("a hit on object {k} {why}")));
            }
        }
        if !setup.models.all_held() {
            for (k, h) in set[at..stop].iter().enumerate() {
                if let (Shape::Instance(i), Some(_)) = (
                    &objs[(key(h) - first) as usize].shape,
                    h.prim.instance_parts(),
                ) {
                    deferred.push(((at + k) as u32, Placement::of(i)));
                }
            }
        }
        let (materials, shade_scene, models) = (setup.materials, setup.shade, setup.models);
        let chunks = pool.current_num_threads().max(1) * 4;
        let chunk = (stop - at).div_ceil(chunks).max(64);
        let n_chunks = (stop - at).div_ceil(chunk);
        if setup.outputs.len() < n_chunks {
            setup.outputs.resize_with(n_chunks, Default::default);
        }
        let outputs = &mut setup.outputs[..n_chunks];
        pool.install(|| {
            set[at..stop]
                .par_chunks(chunk)
                .zip(outputs.par_iter_mut())
                .enumerate()
                .for_each(|(c, (hits, o))| {
                    o.rays.clear();
                    o.contributions.clear();
                    o.pending.clear();
                    o.counts = RayCounts::default();
                    for (k, h) in hits.iter().enumerate() {
                        let obj = &objs[(key(h) - first) as usize];
                        let Some((surf, material)) = surface_of(models, h, obj) else {
                            continue;
                        };
                        let mat = &materials[material as usize];
                        if let Some((image, tile)) = shade_scene.tile_key(mat, &surf) {
                            o.pending.push(Pending {
                                at: (at + c * chunk + k) as u32,
                                key: (image as u64) << 32 | tile as u64,
                                material,
                                surf,
                            });
                            continue;
                        }
                        shade_surface(
                            shade_scene,
                            &h.ray,
                            h.id,
                            &surf,
                            mat,
                            &mut o.rays,
                            &mut o.contributions,
                            &mut o.counts,
                        );
                    }
                })
        });
        for o in &mut setup.outputs[..n_chunks] {
            pending.append(&mut o.pending);
        }
        let parts = gather(&setup.outputs[..n_chunks], contribute, counts);
        pool.install(|| next.extend_from_slices(&parts))?;
        at = stop;
    }
    if !pending.is_empty() {
        shade_textured(setup, pool, set, &mut pending, next, contribute, counts)?;
    }
    st.db_scans += 1;
    st.db_bytes_read += scan.stats().bytes_read;
    st.db_blocks_skipped += scan.stats().blocks_skipped;
    if !deferred.is_empty() {
        shade_deferred(setup, set, &mut deferred, next, contribute, counts, st)?;
    }
    set.clear();
    Ok(())
}

/// Shades the hits on instances whose models are not held, reading each
/// model once, in file order.
fn shade_deferred(
    setup: &mut ShadeSetup<'_>,
    set: &[HitRec],
    deferred: &mut [(u32, Placement)],
    next: &mut NextRays,
    contribute: &mut dyn FnMut(u32, [i64; 3]),
    counts: &mut RayCounts,
    st: &mut ShadeStats,
) -> Result<(), Error> {
    deferred.sort_by_key(|(k, pl)| (pl.model, *k));
    let mut rays = Vec::new();
    let mut emitted = Vec::new();
    let mut from = 0;
    while from < deferred.len() {
        let m = deferred[from].1.model;
        let to = from + deferred[from..].partition_point(|(_, pl)| pl.model == m);
        let model = setup
            .models
            .read_model(setup.db, m as usize, &crate::progress::NoProgress)?;
        st.model_reads += 1;
        for (k, pl) in &deferred[from..to] {
            let h = &set[*k as usize];
            let Some((_, p)) = h.prim.instance_parts() else {
                continue;
            };
            let r = &h.ray;
            let ray = RayQ::from_vec3(Vec3::from_array(r.o), Vec3::from_array(r.d));
            if let Some((surf, material)) = model.surface(pl, p, &ray, h.t) {
                let mat = &setup.materials[material as usize];
                shade_surface(
                    setup.shade,
                    r,
                    h.id,
                    &surf,
                    mat,
                    &mut rays,
                    &mut emitted,
                    counts,
                );
            }
        }
        from = to;
    }
    for (corner, c) in emitted {
        contribute(corner, c);
    }
    next.extend_from_slices(&[&rays])?;
    Ok(())
}

/// The surface of a hit found by the join and its material's index: from
/// the object (or, for an instance, from its model's primitive, placed);
/// `None` for an instance whose model is not held (shaded later, see
/// [`shade_deferred`]).
fn surface_of(models: &Models, h: &HitRec, obj: &ObjectRef<'_>) -> Option<(Surface, u32)> {
    let r = &h.ray;
    let ray = RayQ::from_vec3(Vec3::from_array(r.o), Vec3::from_array(r.d));
    match (&obj.shape, h.prim.instance_parts()) {
        // A model not held, or a primitive past its model, which results
        // checked against the database do not name: `None`.
        (Shape::Instance(i), Some((_, p))) => models.surface(&Placement::of(i), p, &ray, h.t),
        _ => Some((obj.shape.surface(&ray, h.t), obj.material)),
    }
}

/// Shades the hits of a set whose shading reads a texture, sorted by the
/// (texture, tile) their lookups start in (Eisenacher et al.'s sorted
/// deferred shading, the paper's sorted join carried on to the texture
/// tiles): a texture far larger than the tile cache is read nearly once
/// per set, tile after tile, instead of at random. Colour sums and the
/// next round's sort do not depend on the order, so neither does the
/// image.
fn shade_textured(
    setup: &mut ShadeSetup<'_>,
    pool: &rayon::ThreadPool,
    set: &[HitRec],
    pending: &mut Vec<Pending>,
    next: &mut NextRays,
    contribute: &mut dyn FnMut(u32, [i64; 3]),
    counts: &mut RayCounts,
) -> Result<(), Error> {
    pending.sort_unstable_by_key(|p| (p.key, p.at));
    let (materials, shade_scene) = (setup.materials, setup.shade);
    // Chunks in tile order: each thread reads its own run of tiles.
    shade_in_chunks(setup, pool, pending, next, contribute, counts, |p, o| {
        let h = &set[p.at as usize];
        shade_surface(
            shade_scene,
            &h.ray,
            h.id,
            &p.surf,
            &materials[p.material as usize],
            &mut o.rays,
            &mut o.contributions,
            &mut o.counts,
        );
    })?;
    pending.clear();
    Ok(())
}

/// Shades ray `id` of the round, `r`, at surface `surf` of material `mat`
/// with the shared shading code, writing the rays it spawns.
fn shade_surface(
    shade_scene: &ShadeScene,
    r: &RayRec,
    id: u64,
    surf: &Surface,
    mat: &Material,
    out: &mut Vec<RayRec>,
    emitted: &mut Vec<(u32, [i64; 3])>,
    c: &mut RayCounts,
) {
    let d = Vec3::from_array(r.d);
    let lights = shade_scene.lights.len() as u64;
    let base = id * SPAWN_SLOTS;
    let p = surf.p.to_array();
    shade(
        shade_scene,
        d,
        r.depth,
        r.payload[0],
        surf,
        mat,
        &mut |s| match s {
            Spawn::Shadow {
                light,
                dir,
                dist,
                color,
            } => {
                c.shadow_rays += 1;
                out.push(RayRec {
                    o: p,
                    d: dir.to_array(),
                    t_max: dist,
                    key: base + light as u64,
                    payload: color,
                    corner: r.corner,
                    depth: r.depth,
                    kind: RayKind::Shadow as u8,
                    _pad: [0; 6],
                });
            }
            Spawn::Reflect { dir, weight } => {
                c.reflect_rays += 1;
                out.push(RayRec {
                    o: p,
                    d: dir.to_array(),
                    t_max: f64::INFINITY,
                    key: base + lights,
                    payload: [weight, 0.0, 0.0],
                    corner: r.corner,
                    depth: r.depth + 1,
                    kind: RayKind::Reflect as u8,
                    _pad: [0; 6],
                });
            }
            Spawn::Emit { color } => emitted.push((r.corner, to_fixed(color))),
            Spawn::Refract { dir, weight } => {
                c.refract_rays += 1;
                out.push(RayRec {
                    o: p,
                    d: dir.to_array(),
                    t_max: f64::INFINITY,
                    key: base + lights + 1,
                    payload: [weight, 0.0, 0.0],
                    corner: r.corner,
                    depth: r.depth + 1,
                    kind: RayKind::Refract as u8,
                    _pad: [0; 6],
                });
            }
        },
    );
}
