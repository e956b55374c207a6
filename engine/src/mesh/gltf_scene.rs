//! glTF 2.0 scenes (`.gltf` with external or embedded buffers, `.glb`):
//! the default scene's node hierarchy, its triangles, its camera and its
//! point lights, mapped to NFF's model.
//!
//! - **Geometry**: every triangle primitive (also strips and fans) of
//!   every mesh a node of the scene places, with the node's world
//!   transform (TRS or matrix, composed down the hierarchy in `f64`).
//!   A primitive with normals becomes patches (smooth shading, normals by
//!   the inverse transpose), one without becomes triangles; a triangle of
//!   no area is skipped and counted. A mesh several nodes place, or that a
//!   node's `EXT_mesh_gpu_instancing` lists copies of, is a model stored
//!   once and placed by instances ([`crate::models`]) when the sink keeps
//!   models (a database does; `--flatten-instances` and other sinks get a
//!   copy per placement, placed by the same arithmetic, so both render
//!   the same).
//! - **Camera**: the first perspective camera a node places, or the one
//!   `--camera-index N` names (`--camera` overrides any part). glTF's `yfov` is vertical; NFF's angle spans the
//!   image's longer side, so the angle is widened by the camera's aspect
//!   ratio when it is wider than tall. No camera: the default view of a
//!   mesh ([`crate::scene::setup`]).
//! - **Lights** (`KHR_lights_punctual`): point, spot and directional
//!   lights as glTF means them: intensity (candela, lux), inverse-square
//!   falloff, `range` and the spot cones ([`crate::render::shade`]).
//! - **Materials** (metallic-roughness): base colour, metallic and
//!   roughness drive glTF's BRDF (Lambert + GGX, Appendix B) for direct
//!   light; for the rays a hit spawns they map to NFF's terms: specular
//!   reflection is a mirror in NFF, so a rough metal is mostly diffuse
//!   (`Ks = metallic * (1 - roughness)`, `Kd = 1 - Ks`), with Phong
//!   exponent `2 / a^2 - 2`, `a = roughness^2` (at least 1), kept for an
//!   NFF output; `KHR_materials_transmission` -> transmission, which
//!   takes its share from the diffuse; `KHR_materials_ior` -> index of
//!   refraction (1.5 by default). The emissive factor (times
//!   `KHR_materials_emissive_strength`) is added to every ray that hits
//!   the surface.
//! - **Textures**: the base colour texture (through its sampler and
//!   `KHR_texture_transform`) at the primitive's `TEXCOORD_n`, and
//!   `COLOR_0`, multiply the base colour; such primitives become textured
//!   triangles. `alphaMode: MASK` cuts the surface out where the alpha is
//!   below `alphaCutoff` (`BLEND` is rendered opaque, with a warning).
//!   The metallic-roughness texture scales the metallic (blue) and
//!   roughness (green) factors, the emissive texture the emissive colour,
//!   and the normal texture (times its `scale`) tilts the shading normal
//!   in the frame of the texture coordinates (tangents from the
//!   triangle's corners); all are read at the first texture's coordinate
//!   set. Occlusion textures are not applied (one warning).
//!   A primitive without a material is the meshes' neutral grey.
//!
//! The file is read within the memory budget ([`super::gltf_data`]): the
//! document is held, the buffers are read by offset.
//!
//! Bad input is an error that names the file and what is wrong: a missing
//! or short buffer, an accessor outside its buffer, an index past the
//! vertices, a cycle in the node graph, a file of nothing but points or
//! lines (beside triangles they are skipped with a warning).

use super::builder::NEUTRAL;
use super::gltf_data::{self, Buffers, Components, Elements, Main};
use super::{MeshOptions, MeshSummary, Warnings};
use crate::error::Error;
use crate::models::{place_normal, place_point};
use crate::progress::Progress;
use crate::scene::setup::{DEFAULT_BACKGROUND, default_lights};
use crate::scene::{Light, LightKind, Material, MeshFacts, Pbr, Photometric, SceneSink, View};
use crate::scene::{TextureBinding, TextureImage};
use crate::shapes::{Patch, Polygon, Shape, Textured, pack_color};
use crate::texture::{Filter, Sampler, UvTransform, Wrap};
use glam::{DAffine3, DMat4, DVec3};
use gltf::accessor::Dimensions;
use gltf::mesh::Mode;
use std::collections::HashMap;
use std::path::Path;

/// Reads the glTF scene at `path` into `sink`, within `opts.memory`: the
/// document is held, the buffers are read by offset
/// ([`gltf_data`]). A gzip or zstd file is first decompressed to a
/// temporary file (in `opts.spill_dir`), since its buffers are read out
/// of order.
pub fn read_gltf(
    path: &Path,
    sink: &mut dyn SceneSink,
    progress: &dyn Progress,
    opts: &MeshOptions,
) -> Result<MeshSummary, Error> {
    use crate::error::IoContext;
    use crate::input::Wrapping;
    let wrapping = Wrapping::of_head(&crate::input::raw_head(path, 4)?);
    let (file, _temp) = if wrapping == Wrapping::Plain {
        (std::fs::File::open(path).at(path)?, None)
    } else {
        let mut temp = match &opts.spill_dir {
            Some(d) => tempfile::NamedTempFile::new_in(d).at(d)?,
            None => tempfile::NamedTempFile::new().at(std::env::temp_dir())?,
        };
        let mut input = crate::input::open(path, progress)?;
        std::io::copy(&mut input.reader, temp.as_file_mut())
            .map_err(|e| crate::input::read_error(path, input.wrapping, e))?;
        let file = temp.reopen().at(temp.path())?;
        (file, Some(temp))
    };
    read_main(Main::File(file), path, path.parent(), opts, sink, progress)
}

/// Reads a glTF scene from `bytes` (`.gltf` JSON or `.glb`); external
/// buffers are looked for under `base` (none: only embedded ones, in the
/// GLB chunk or data URIs).
pub fn read_gltf_bytes(
    bytes: &[u8],
    name: &Path,
    base: Option<&Path>,
    opts: &MeshOptions,
    sink: &mut dyn SceneSink,
    progress: &dyn Progress,
) -> Result<MeshSummary, Error> {
    read_main(Main::Slice(bytes), name, base, opts, sink, progress)
}

/// How the memory budget is shared while a glTF file is read (with the
/// sparse elements of a primitive's three accessors, 15/16 of it; the
/// chunk buffers, a megabyte or two, and the sink's own come on top).
struct Shares {
    /// The document, parsed, and buffers embedded in it (data URIs).
    document: u64,
    /// Pages of buffer files kept for vertices looked up by index.
    cache: u64,
    /// Each accessor's sparse elements (or the zeros of one without a
    /// view); the node placements; the copies of GPU instancing.
    lists: u64,
    /// One primitive's vertices (and normals) held, placed, while its
    /// faces are written; beyond that they are looked up by index.
    primitive: u64,
    /// One image's bytes, read to be stored with the scene.
    images: u64,
}

impl Shares {
    fn of(memory: u64) -> Shares {
        Shares {
            document: memory / 4,
            cache: memory / 8,
            lists: memory / 16,
            primitive: memory * 3 / 8,
            images: memory / 4,
        }
    }
}

fn read_main(
    main: Main<'_>,
    name: &Path,
    base: Option<&Path>,
    opts: &MeshOptions,
    sink: &mut dyn SceneSink,
    progress: &dyn Progress,
) -> Result<MeshSummary, Error> {
    let camera_index = opts.camera_index;
    let bad = |what: String| Error::Scene(format!("{}: {what}", name.display()));
    let shares = Shares::of(opts.memory);
    let (doc, mut bufs, ignored) =
        gltf_data::open(main, base, shares.document, shares.cache).map_err(&bad)?;
    let mut warnings = Warnings::default();
    for ext in ignored {
        warnings.add(
            "an extension the file requires is ignored (the shapes are read; shading may differ)",
            || ext,
        );
    }
    let scene = doc
        .default_scene()
        .or_else(|| doc.scenes().next())
        .ok_or_else(|| bad("it has no scene".into()))?;
    let mut placed = place_nodes(&scene, doc.nodes().count(), shares.lists).map_err(bad)?;
    gpu_instances(&doc, &mut placed, &mut bufs, shares.lists).map_err(&bad)?;

    // A mesh drawn by more than one placement is a model, stored once and
    // placed by instances, when the output keeps models; else (and for
    // a mesh drawn once) each placement writes its own copy.
    let mut drawn_by = vec![Vec::new(); doc.meshes().count()];
    for (i, p) in placed.iter().enumerate().filter(|(_, p)| p.draws) {
        if let Some(m) = p.node.mesh() {
            drawn_by[m.index()].push(i);
        }
    }
    let takes_models = sink.takes_models();
    let is_model = |m: &gltf::Mesh<'_>| takes_models && drawn_by[m.index()].len() > 1;
    let mesh_vertices = |m: &gltf::Mesh<'_>| -> u64 {
        m.primitives()
            .filter_map(|p| p.get(&gltf::Semantic::Positions))
            .map(|a| a.count() as u64)
            .sum()
    };

    // Bounds of every placed primitive, from its positions, read once
    // (in chunks) and placed by each of its mesh's placements.
    let mut bounds = Bounds::default();
    for mesh in doc.meshes() {
        let by = &drawn_by[mesh.index()];
        if by.is_empty() {
            continue;
        }
        for prim in mesh.primitives() {
            let Some(pos) = prim
                .get(&gltf::Semantic::Positions)
                .filter(|_| is_surface(prim.mode()))
            else {
                continue;
            };
            let e = Elements::new(&pos, &mut bufs, shares.lists).map_err(&bad)?;
            e.expect_vectors(Dimensions::Vec3, "positions", Components::Quantized)
                .map_err(&bad)?;
            e.chunks(&mut bufs, |_, raw| {
                for v in raw.chunks_exact(e.size()) {
                    let v = DVec3::from(e.decode::<3>(v).map(f64::from));
                    for &i in by {
                        bounds.add(placed[i].world.transform_point3(v));
                    }
                }
                Ok(())
            })
            .map_err(&bad)?;
        }
    }
    // The vertices the world stores (a copy's each time); a model's are
    // its own facts.
    let model_vertices: u64 = doc
        .meshes()
        .filter(is_model)
        .map(|m| mesh_vertices(&m))
        .sum();
    let vertices: u64 = doc
        .meshes()
        .filter(|m| !is_model(m))
        .map(|m| drawn_by[m.index()].len() as u64 * mesh_vertices(&m))
        .sum();

    // Camera, lights, then the mesh facts (the setup's defaults fill in
    // what the file lacks).
    if let Some(i) = camera_index {
        let cameras = doc.cameras().count();
        if i >= cameras {
            return Err(bad(format!(
                "--camera-index {i}: the file has {cameras} camera(s)"
            )));
        }
        if !placed
            .iter()
            .any(|p| p.node.camera().is_some_and(|c| c.index() == i))
        {
            return Err(bad(format!(
                "--camera-index {i}: no node of the scene places that camera"
            )));
        }
    }
    let view = camera_view(&placed, camera_index, &bounds, &mut warnings);
    let finite = |v: &[f64]| v.iter().all(|c| c.is_finite());
    if let Some(v) = &view
        && !(finite(&v.from) && finite(&v.at) && finite(&v.up) && v.angle.is_finite())
    {
        return Err(bad("the camera's transform is not finite".into()));
    }
    if let Some(v) = &view {
        sink.view(v)?;
        sink.background(DEFAULT_BACKGROUND)?;
    }
    let lights = punctual_lights(&placed, &bounds, &mut warnings);
    if let Some(l) = lights.iter().find(|l| {
        !finite(&l.position) || !l.color.unwrap_or_default().iter().all(|c| c.is_finite())
    }) {
        return Err(bad(format!("a light at {:?} is not finite", l.position)));
    }
    for l in &lights {
        sink.light(l)?;
    }
    if let (Some(v), true, Some(b)) = (&view, lights.is_empty(), bounds.get()) {
        for l in default_lights(b, v) {
            sink.light(&l)?;
        }
    }
    sink.mesh(&MeshFacts {
        vertices,
        bounds: bounds.get(),
        up: Some([0.0, 1.0, 0.0]),
    })?;

    // Progress counts the triangles written: a model's once, a copied
    // mesh's once per placement.
    let triangles_of =
        |m: &gltf::Mesh<'_>| -> u64 { m.primitives().map(|p| triangle_count(&p)).sum() };
    progress.set_unit("triangles");
    progress.set_total(
        doc.meshes()
            .map(|m| match is_model(&m) {
                true => triangles_of(&m),
                false => drawn_by[m.index()].len() as u64 * triangles_of(&m),
            })
            .sum(),
    );
    let mut summary = MeshSummary {
        vertices: vertices + model_vertices,
        ..Default::default()
    };
    let models: Vec<gltf::Mesh<'_>> = doc.meshes().filter(is_model).collect();
    let mut model_of: Vec<Option<u32>> = vec![None; drawn_by.len()];
    let mut out = Emit {
        bufs: &mut bufs,
        base,
        images: HashMap::new(),
        shares: &shares,
        sink,
        current: None,
        summary: &mut summary,
        warnings: &mut warnings,
        bad: &bad,
        progress,
    };
    for mesh in models {
        out.sink.begin_model()?;
        out.sink.mesh(&MeshFacts {
            vertices: mesh_vertices(&mesh),
            bounds: None,
            up: None,
        })?;
        out.current = None;
        out.mesh(&mesh, None, mesh.index())?;
        let model = out.sink.end_model()?;
        out.current = None;
        model_of[mesh.index()] = Some(model.index);
        out.summary.models += 1;
    }
    for p in &placed {
        let Some(mesh) = p.node.mesh().filter(|_| p.draws) else {
            continue;
        };
        let placement = DAffine3::from_mat4(p.world);
        match model_of[mesh.index()] {
            // A placement that flattens the mesh (a zero scale, often how
            // a node is hidden) places nothing: its copy would be all
            // degenerate triangles.
            Some(_) if !invertible(&placement) => {
                out.warnings.add(
                    "a placement of a shared mesh with a zero (or non-invertible) scale is skipped",
                    || format!("node {}", p.node.index()),
                );
            }
            Some(model) => {
                out.sink
                    .instance(model, &placement)
                    .map_err(|e| bad(format!("node {}: {e}", p.node.index())))?;
                out.summary.instances += 1;
            }
            None => out.mesh(&mesh, Some(&placement), p.node.index())?,
        }
    }
    warnings.report(name, progress);
    if summary.faces == 0 && summary.skipped_primitives > 0 {
        return Err(bad(format!(
            "it has no triangles, only {} primitive(s) of points or lines, which are not supported",
            summary.skipped_primitives
        )));
    }
    super::report_summary(name, &summary, progress);
    Ok(summary)
}

/// Whether primitives of `mode` are surfaces (triangles, strips, fans).
fn is_surface(mode: Mode) -> bool {
    matches!(
        mode,
        Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
    )
}

/// The triangles a primitive's indices (or vertices) make, by its mode.
fn triangle_count(p: &gltf::Primitive<'_>) -> u64 {
    let n = match (p.indices(), p.get(&gltf::Semantic::Positions)) {
        (Some(i), _) => i.count() as u64,
        (None, Some(v)) => v.count() as u64,
        (None, None) => 0,
    };
    match p.mode() {
        Mode::Triangles => n / 3,
        Mode::TriangleStrip | Mode::TriangleFan => n.saturating_sub(2),
        _ => 0,
    }
}

/// Writes meshes' triangles into a sink.
struct Emit<'e, 'b> {
    bufs: &'e mut Buffers<'b>,
    /// The directory of the file, where images named by a path are.
    base: Option<&'e Path>,
    /// The sink's number of each image sent, by the file's image index.
    images: HashMap<usize, u32>,
    shares: &'e Shares,
    sink: &'e mut dyn SceneSink,
    /// The material the sink has now.
    current: Option<Material>,
    summary: &'e mut MeshSummary,
    warnings: &'e mut Warnings,
    bad: &'e dyn Fn(String) -> Error,
    progress: &'e dyn Progress,
}

/// A primitive's vertices (and normals), placed: held, or read by index
/// when they do not fit in their share of memory.
enum Vertices {
    Held(Vec<[f32; 3]>, Option<Vec<[f32; 3]>>),
    ByIndex,
}

impl Emit<'_, '_> {
    /// Writes the triangles of `mesh` placed by `placement` (node `node`
    /// places it), or, without a placement, as they are in the file (a
    /// model's). A placed corner is [`place_point`] of the file's, a
    /// placed normal [`place_normal`] of the file's: exactly what an
    /// instance of the model computes, so that a copy and an instance are
    /// the same triangles. A model keeps the file's normals (a normal that
    /// is not finite as zero), to be placed by each instance.
    ///
    /// Indices are read in order, in chunks; vertices are held for the
    /// primitive if they fit in their share of the budget, else each
    /// corner's is read by index through the page cache. Both ways give
    /// the same triangles and the same errors.
    fn mesh(
        &mut self,
        mesh: &gltf::Mesh<'_>,
        placement: Option<&DAffine3>,
        node: usize,
    ) -> Result<(), Error> {
        let bad = self.bad;
        let normal_map = placement.map(|m| m.matrix3.inverse().transpose());
        let place_p = |v: [f32; 3]| match placement {
            Some(m) => place_point(m, v),
            None => v,
        };
        let place_n = |v: [f32; 3]| match &normal_map {
            // A normal that cannot be normalised (zero, or not finite) is
            // taken as none (zero).
            Some(nm) => place_normal(nm, v),
            None if v.iter().all(|c| c.is_finite()) => v,
            None => [0.0; 3],
        };
        for prim in mesh.primitives() {
            let what = || format!("mesh {} primitive {}", mesh.index(), prim.index());
            let mode = prim.mode();
            if !is_surface(mode) {
                // Points and lines (a CAD file's edges, say) have no
                // surface to hit: skipped, said once. A file of nothing
                // else is an error (see `read_main`).
                self.warnings.add(
                    "points and lines primitives are not supported and are skipped (only triangles, strips and fans)",
                    || format!("{}, {mode:?}", what()),
                );
                self.summary.skipped_primitives += 1;
                continue;
            }
            let Some(pos) = prim.get(&gltf::Semantic::Positions) else {
                self.warnings
                    .add("a primitive without positions is skipped", what);
                continue;
            };
            let colors = prim.get(&gltf::Semantic::Colors(0)).is_some();
            if fully_cut_out(&prim.material(), colors, &mut *self.warnings, &what) {
                self.summary.skipped_primitives += 1;
                continue;
            }
            let lists = self.shares.lists;
            let pos = Elements::new(&pos, self.bufs, lists).map_err(bad)?;
            pos.expect_vectors(Dimensions::Vec3, "positions", Components::Quantized)
                .map_err(bad)?;
            let count = pos.count;
            if count > u32::MAX as usize {
                return Err(bad(format!(
                    "{}: {count} vertices, more than indices can name",
                    what()
                )));
            }
            let normals = match prim.get(&gltf::Semantic::Normals) {
                Some(n) => {
                    let n = Elements::new(&n, self.bufs, lists).map_err(bad)?;
                    n.expect_vectors(Dimensions::Vec3, "normals", Components::Signed)
                        .map_err(bad)?;
                    if n.count != count {
                        return Err(bad(format!(
                            "{}: {} normals for {count} positions",
                            what(),
                            n.count
                        )));
                    }
                    Some(n)
                }
                None => None,
            };
            let indices = match prim.indices() {
                Some(a) => {
                    let e = Elements::new(&a, self.bufs, lists).map_err(bad)?;
                    e.expect_indices(&what()).map_err(bad)?;
                    Some(e)
                }
                None => None,
            };
            // A number that is not finite, in the file or once placed (a
            // transform too large for single precision), is an error
            // whether or not a face uses it.
            let not_finite = |k: usize| match placement {
                Some(_) => format!(
                    "{}: vertex {k} is not a finite point once placed by node {node}",
                    what()
                ),
                None => format!("{}: vertex {k} is not a finite point", what()),
            };
            let per_vertex = if normals.is_some() { 24 } else { 12 };
            let held = (count as u64).saturating_mul(per_vertex) <= self.shares.primitive;
            let mut points = Vec::with_capacity(if held { count } else { 0 });
            pos.chunks(self.bufs, |first, raw| {
                for (j, e) in raw.chunks_exact(pos.size()).enumerate() {
                    let p = place_p(pos.decode::<3>(e));
                    if !p.iter().all(|c| c.is_finite()) {
                        return Err(not_finite(first + j));
                    }
                    if held {
                        points.push(p);
                    }
                }
                Ok(())
            })
            .map_err(bad)?;
            let vertices = match (held, &normals) {
                (false, _) => Vertices::ByIndex,
                (true, None) => Vertices::Held(points, None),
                (true, Some(n)) => {
                    let mut ns = Vec::with_capacity(count);
                    n.chunks(self.bufs, |_, raw| {
                        ns.extend(
                            raw.chunks_exact(n.size())
                                .map(|e| place_n(n.decode::<3>(e))),
                        );
                        Ok(())
                    })
                    .map_err(bad)?;
                    Vertices::Held(points, Some(ns))
                }
            };
            let m = self.material(&prim.material())?;
            let textured = m.texture.is_some() || m.maps != crate::scene::Maps::NONE;
            let uvs = match (textured, texture_set(&prim.material())) {
                (true, Some(set)) => match prim.get(&gltf::Semantic::TexCoords(set)) {
                    Some(a) => {
                        let e = Elements::new(&a, self.bufs, lists).map_err(bad)?;
                        e.expect_vectors(
                            Dimensions::Vec2,
                            "texture coordinates",
                            Components::Quantized,
                        )
                        .map_err(bad)?;
                        Some(Corners::read(e, count, held, self.bufs, what).map_err(bad)?)
                    }
                    None => {
                        self.warnings.add(
                            "a textured material on a primitive without its texture coordinates is untextured",
                            what,
                        );
                        None
                    }
                },
                _ => None,
            };
            let colors = match prim.get(&gltf::Semantic::Colors(0)) {
                Some(a) => {
                    let e = Elements::new(&a, self.bufs, lists).map_err(bad)?;
                    let dims = if a.dimensions() == Dimensions::Vec3 {
                        Dimensions::Vec3
                    } else {
                        Dimensions::Vec4
                    };
                    e.expect_vectors(dims, "vertex colours", Components::Quantized)
                        .map_err(bad)?;
                    Some(Corners::read(e, count, held, self.bufs, what).map_err(bad)?)
                }
                None => None,
            };
            if self.current != Some(m) {
                self.sink.material(&m)?;
                self.current = Some(m);
            }
            // The faces, their indices read in order.
            let total = indices.as_ref().map_or(count, |e| e.count);
            let mut faces = Assembler::new(mode);
            let mut chunk = Vec::new();
            let mut first = 0;
            while first < total {
                let n = indices
                    .as_ref()
                    .map_or(1 << 18, Elements::per_chunk)
                    .min(total - first);
                match &indices {
                    Some(e) => e.indices(self.bufs, first, n, &mut chunk).map_err(bad)?,
                    None => {
                        chunk.clear();
                        chunk.extend(first as u32..(first + n) as u32);
                    }
                }
                for &i in &chunk {
                    if i as usize >= count {
                        return Err(bad(format!(
                            "{}: index {i} is past its {count} vertices",
                            what()
                        )));
                    }
                    let Some(t) = faces.push(i) else {
                        continue;
                    };
                    let (v, n) = match &vertices {
                        Vertices::Held(p, n) => (
                            t.map(|i| p[i as usize]),
                            n.as_ref().map(|n| t.map(|i| n[i as usize])),
                        ),
                        Vertices::ByIndex => {
                            let mut v = [[0f32; 3]; 3];
                            for (c, &i) in v.iter_mut().zip(&t) {
                                *c = place_p(pos.vec3(self.bufs, i as usize).map_err(bad)?);
                            }
                            let n = match &normals {
                                Some(ne) => {
                                    let mut n = [[0f32; 3]; 3];
                                    for (c, &i) in n.iter_mut().zip(&t) {
                                        *c = place_n(ne.vec3(self.bufs, i as usize).map_err(bad)?);
                                    }
                                    Some(n)
                                }
                                None => None,
                            };
                            (v, n)
                        }
                    };
                    self.summary.faces += 1;
                    if !super::geometry::has_area(v[0], v[1], v[2]) {
                        self.summary.degenerate += 1;
                        continue;
                    }
                    if uvs.is_some() || colors.is_some() {
                        let uv = match &uvs {
                            Some(c) => Some(c.corners::<2>(self.bufs, t).map_err(bad)?),
                            None => None,
                        };
                        let color = match &colors {
                            Some(c) => {
                                Some(c.corners::<4>(self.bufs, t).map_err(bad)?.map(pack_color))
                            }
                            None => None,
                        };
                        let none3: &[[f32; 3]] = &[];
                        self.sink.object(&Shape::Textured(Textured {
                            vertices: &v,
                            normals: n.as_ref().map_or(none3, |n| &n[..]),
                            uvs: uv.as_ref().map_or(&[][..], |u| &u[..]),
                            colors: color.as_ref().map_or(&[][..], |c| &c[..]),
                        }))?;
                        self.summary.objects += 1;
                        continue;
                    }
                    match &n {
                        Some(n) => self.sink.object(&Shape::Patch(Patch {
                            vertices: &v,
                            normals: n,
                        }))?,
                        None => self
                            .sink
                            .object(&Shape::Polygon(Polygon { vertices: &v }))?,
                    }
                    self.summary.objects += 1;
                }
                first += n;
            }
            self.progress.inc(triangle_count(&prim));
        }
        Ok(())
    }
}

/// Triangles from a primitive's indices, one index at a time: a list's
/// threes, a strip's (every other one reversed to keep its winding) or
/// a fan's.
struct Assembler {
    mode: Mode,
    seen: usize,
    a: u32,
    b: u32,
}

impl Assembler {
    fn new(mode: Mode) -> Assembler {
        Assembler {
            mode,
            seen: 0,
            a: 0,
            b: 0,
        }
    }

    /// The triangle index `i` completes, if any.
    fn push(&mut self, i: u32) -> Option<[u32; 3]> {
        let k = self.seen;
        self.seen += 1;
        match self.mode {
            Mode::Triangles => match k % 3 {
                0 => {
                    self.a = i;
                    None
                }
                1 => {
                    self.b = i;
                    None
                }
                _ => Some([self.a, self.b, i]),
            },
            Mode::TriangleStrip => {
                let t = match k {
                    0 | 1 => None,
                    _ if k % 2 == 1 => Some([self.b, self.a, i]),
                    _ => Some([self.a, self.b, i]),
                };
                self.a = self.b;
                self.b = i;
                t
            }
            _ => match k {
                0 => {
                    self.a = i;
                    None
                }
                1 => {
                    self.b = i;
                    None
                }
                _ => {
                    let t = [self.a, self.b, i];
                    self.b = i;
                    Some(t)
                }
            },
        }
    }
}

/// Whether `m` maps no direction to zero (it can be inverted, finitely).
fn invertible(m: &DAffine3) -> bool {
    let det = m.matrix3.determinant();
    det.is_finite() && det != 0.0 && m.inverse().to_cols_array().iter().all(|c| c.is_finite())
}

/// A node of the scene with its world transform.
struct Placed<'a> {
    node: gltf::Node<'a>,
    world: DMat4,
    /// Whether it draws the node's mesh (not if the node's
    /// `EXT_mesh_gpu_instancing` copies draw it instead).
    draws: bool,
    /// Whether it is the node itself, whose camera and light count (not
    /// one of those copies).
    original: bool,
}

/// Every node under the scene's roots, in depth-first order, with its
/// world transform; a node reached again below itself is a cycle.
fn place_nodes<'a>(
    scene: &gltf::Scene<'a>,
    nodes: usize,
    budget: u64,
) -> Result<Vec<Placed<'a>>, String> {
    // A node may be the child of several (no cycle, but a graph whose
    // placements double at each level): the placements are counted.
    let most = (budget / std::mem::size_of::<Placed<'_>>() as u64).max(1) as usize;
    let mut out = Vec::new();
    let mut on_path = vec![false; nodes];
    // Entries to visit: a node and its parent's transform, or the end of a
    // node's subtree (to take it off the path).
    enum Step<'a> {
        Enter(gltf::Node<'a>, DMat4),
        Leave(usize),
    }
    let mut stack: Vec<Step<'a>> = scene
        .nodes()
        .map(|n| Step::Enter(n, DMat4::IDENTITY))
        .collect();
    stack.reverse();
    while let Some(step) = stack.pop() {
        let (node, parent) = match step {
            Step::Leave(i) => {
                on_path[i] = false;
                continue;
            }
            Step::Enter(n, p) => (n, p),
        };
        let i = node.index();
        if on_path[i] {
            return Err(format!("the node graph has a cycle through node {i}"));
        }
        on_path[i] = true;
        let local = DMat4::from_cols_array_2d(&node.transform().matrix().map(|c| c.map(f64::from)));
        let world = parent * local;
        stack.push(Step::Leave(i));
        let first = stack.len();
        stack.extend(node.children().map(|c| Step::Enter(c, world)));
        stack[first..].reverse();
        if out.len() >= most {
            return Err(format!(
                "the node graph places more than {most} nodes (children shared by several \
                 parents?), more than the memory budget's share for them (raise --memory)"
            ));
        }
        out.push(Placed {
            node,
            world,
            draws: true,
            original: true,
        });
    }
    Ok(out)
}

/// Replaces each placed node that has `EXT_mesh_gpu_instancing` by the
/// copies of its mesh the extension lists: the node's transform times each
/// copy's translation, rotation and scale (each attribute optional;
/// floats, or a rotation of normalized signed bytes or shorts). The node
/// itself stays, for its camera and light, without its mesh being drawn.
/// The placements are held: refused beyond `budget` bytes.
fn gpu_instances<'a>(
    doc: &'a gltf::Document,
    placed: &mut Vec<Placed<'a>>,
    bufs: &mut Buffers<'_>,
    budget: u64,
) -> Result<(), String> {
    let mut out = Vec::with_capacity(placed.len());
    for p in placed.drain(..) {
        let ext = p.node.extension_value("EXT_mesh_gpu_instancing");
        let Some(attrs) = ext
            .and_then(|e| e.get("attributes"))
            .and_then(|a| a.as_object())
        else {
            out.push(p);
            continue;
        };
        let node = p.node.index();
        let mut accessor = |name: &str, dims: Dimensions| -> Result<Option<Elements>, String> {
            let Some(v) = attrs.get(name) else {
                return Ok(None);
            };
            let a = v
                .as_u64()
                .and_then(|i| doc.accessors().nth(i as usize))
                .ok_or_else(|| {
                    format!("node {node}: EXT_mesh_gpu_instancing {name} names no accessor")
                })?;
            let e = Elements::new(&a, bufs, budget)?;
            let of = match name {
                "ROTATION" => Components::Signed,
                _ => Components::Floats,
            };
            e.expect_vectors(dims, &format!("EXT_mesh_gpu_instancing {name}"), of)
                .map_err(|m| format!("node {node}: {m}"))?;
            Ok(Some(e))
        };
        let t = accessor("TRANSLATION", Dimensions::Vec3)?;
        let r = accessor("ROTATION", Dimensions::Vec4)?;
        let sc = accessor("SCALE", Dimensions::Vec3)?;
        let counts: Vec<usize> = [&t, &r, &sc]
            .iter()
            .filter_map(|a| a.as_ref().map(|a| a.count))
            .collect();
        let n = counts.first().copied().unwrap_or(0);
        if counts.iter().any(|&c| c != n) {
            return Err(format!(
                "node {node}: EXT_mesh_gpu_instancing attributes of different counts {counts:?}"
            ));
        }
        // The placements, and the attributes read for them (40 bytes a
        // copy at most).
        let held = ((out.len() as u64).saturating_add(n as u64))
            .saturating_mul(std::mem::size_of::<Placed<'_>>() as u64 + 40);
        if held > budget {
            return Err(format!(
                "node {node}: EXT_mesh_gpu_instancing places {n} copies, {} with the other \
                 placements, more than the {} of the memory budget they may take (raise --memory)",
                crate::units::fmt_bytes(held),
                crate::units::fmt_bytes(budget)
            ));
        }
        let ts = t.map(|e| e.floats::<3>(bufs)).transpose()?;
        let ss = sc.map(|e| e.floats::<3>(bufs)).transpose()?;
        let rs = r.map(|e| e.floats::<4>(bufs)).transpose()?;
        for k in 0..n {
            let tr = ts
                .as_ref()
                .map_or(DVec3::ZERO, |v| DVec3::from(v[k].map(f64::from)));
            let sv = ss
                .as_ref()
                .map_or(DVec3::ONE, |v| DVec3::from(v[k].map(f64::from)));
            let q = rs.as_ref().map_or(glam::DQuat::IDENTITY, |v| {
                let [x, y, z, w] = v[k].map(f64::from);
                glam::DQuat::from_xyzw(x, y, z, w).normalize()
            });
            out.push(Placed {
                node: p.node.clone(),
                world: p.world * DMat4::from_scale_rotation_translation(sv, q, tr),
                draws: true,
                original: false,
            });
        }
        // The node stays for its camera and light; its mesh is drawn only
        // by the copies.
        out.push(Placed { draws: false, ..p });
    }
    *placed = out;
    Ok(())
}

/// The box of points, in `f64`.
#[derive(Default)]
struct Bounds(Option<(DVec3, DVec3)>);

impl Bounds {
    fn add(&mut self, p: DVec3) {
        self.0 = Some(match self.0 {
            None => (p, p),
            Some((lo, hi)) => (lo.min(p), hi.max(p)),
        });
    }

    fn get(&self) -> Option<([f64; 3], [f64; 3])> {
        self.0.map(|(lo, hi)| (lo.to_array(), hi.to_array()))
    }

    fn centre_and_size(&self) -> (DVec3, f64) {
        match self.0 {
            Some((lo, hi)) => ((lo + hi) / 2.0, (hi - lo).length().max(1e-30)),
            None => (DVec3::ZERO, 1.0),
        }
    }
}

/// The NFF material of a glTF one (see the module documentation).
/// Whether material `m` cuts its whole surface out: `alphaMode: MASK`
/// without a base colour texture, its base colour's alpha below the
/// cut-off (one alpha over the whole surface, so the primitive is not
/// there at all; `COLOR_0` can only lower it). Where only the vertex
/// colours' alpha (`colors`) would cut, nothing is cut (said once).
fn fully_cut_out(
    m: &gltf::Material<'_>,
    colors: bool,
    warnings: &mut Warnings,
    what: &dyn Fn() -> String,
) -> bool {
    let pbr = m.pbr_metallic_roughness();
    if m.alpha_mode() != gltf::material::AlphaMode::Mask || pbr.base_color_texture().is_some() {
        return false;
    }
    let cut = pbr.base_color_factor()[3] < m.alpha_cutoff().unwrap_or(0.5);
    if !cut && colors {
        warnings.add(
            "alphaMode MASK without a base colour texture cuts by the base colour's alpha only (COLOR_0's alpha is not read)",
            what,
        );
    }
    cut
}

/// The texture coordinate set the textures of `m` read, if it has any:
/// its base colour texture's, else its first other map's
/// (`KHR_texture_transform` may name another). Every map of a material is
/// read at one set (see [`Emit::material`]).
fn texture_set(m: &gltf::Material<'_>) -> Option<u32> {
    let set = |info: gltf::texture::Info<'_>| {
        info.texture_transform()
            .and_then(|t| t.tex_coord())
            .unwrap_or(info.tex_coord())
    };
    let pbr = m.pbr_metallic_roughness();
    pbr.base_color_texture()
        .map(set)
        .or_else(|| pbr.metallic_roughness_texture().map(set))
        .or_else(|| m.emissive_texture().map(set))
        .or_else(|| m.normal_texture().map(|n| n.tex_coord()))
}

/// A primitive's per-vertex attribute (texture coordinates, colours):
/// held when its vertices are, else read by index.
struct Corners {
    elements: Elements,
    held: Option<Vec<[f32; 4]>>,
    dims: usize,
}

impl Corners {
    fn read(
        elements: Elements,
        count: usize,
        held: bool,
        bufs: &mut Buffers<'_>,
        what: impl Fn() -> String,
    ) -> Result<Corners, String> {
        if elements.count != count {
            return Err(format!(
                "{}: accessor {} has {} elements for {count} positions",
                what(),
                elements.index(),
                elements.count
            ));
        }
        let dims = elements.components();
        let held = held.then(|| elements.floats_padded(bufs)).transpose()?;
        Ok(Corners {
            elements,
            held,
            dims,
        })
    }

    /// The attribute at the three corners `t`, as `D` numbers (a colour
    /// without alpha gets alpha 1).
    fn corners<const D: usize>(
        &self,
        bufs: &mut Buffers<'_>,
        t: [u32; 3],
    ) -> Result<[[f32; D]; 3], String> {
        let mut out = [[0f32; D]; 3];
        for (o, &i) in out.iter_mut().zip(&t) {
            let v = match &self.held {
                Some(h) => h[i as usize],
                None => self.elements.padded(bufs, i as usize)?,
            };
            for (k, x) in o.iter_mut().enumerate() {
                *x = if k < self.dims { v[k] } else { 1.0 };
                if !x.is_finite() {
                    return Err(format!(
                        "vertex {i} has a texture coordinate or colour that is not a finite number"
                    ));
                }
            }
        }
        Ok(out)
    }
}

impl Emit<'_, '_> {
    /// The sray material of glTF material `m`, its textures sent to the
    /// sink (once per image) and bound: base colour, metallic-roughness,
    /// emissive and normal maps.
    fn material(&mut self, m: &gltf::Material<'_>) -> Result<Material, Error> {
        let mut out = material(m, self.warnings);
        let set = texture_set(m);
        let pbr = m.pbr_metallic_roughness();
        let mut sets = Vec::new();
        if let Some(info) = pbr.base_color_texture() {
            let alpha = pbr.base_color_factor()[3];
            let cutoff = match m.alpha_mode() {
                gltf::material::AlphaMode::Mask => m.alpha_cutoff().unwrap_or(0.5),
                gltf::material::AlphaMode::Blend => {
                    self.warnings.add(
                        "alphaMode BLEND is rendered opaque (MASK cut-outs are honoured)",
                        || format!("material {}", m.index().unwrap_or(0)),
                    );
                    0.0
                }
                gltf::material::AlphaMode::Opaque => 0.0,
            };
            sets.push(info_set(&info));
            out.texture = Some(self.bind(info.texture(), transform(&info), cutoff, alpha)?);
        }
        if let Some(info) = pbr.metallic_roughness_texture() {
            sets.push(info_set(&info));
            out.maps.metallic_roughness =
                Some(self.bind(info.texture(), transform(&info), 0.0, 1.0)?);
        }
        if let Some(info) = m.emissive_texture() {
            sets.push(info_set(&info));
            out.maps.emissive = Some(self.bind(info.texture(), transform(&info), 0.0, 1.0)?);
        }
        if let Some(n) = m.normal_texture() {
            sets.push(n.tex_coord());
            // glTF's normal scale rides in the binding's alpha.
            out.maps.normal =
                Some(self.bind(n.texture(), UvTransform::default(), 0.0, n.scale())?);
        }
        if sets.iter().any(|&s| Some(s) != set) {
            self.warnings.add(
                "textures of one material read different texture coordinate sets: all are read at the first's",
                || format!("material {}", m.index().unwrap_or(0)),
            );
        }
        Ok(out)
    }

    /// Binds texture `tex`: its image sent to the sink once, its sampler.
    fn bind(
        &mut self,
        tex: gltf::Texture<'_>,
        transform: UvTransform,
        cutoff: f32,
        alpha: f32,
    ) -> Result<TextureBinding, Error> {
        let image = tex.source();
        let idx = match self.images.get(&image.index()) {
            Some(&i) => i,
            None => {
                let bytes =
                    gltf_data::image_bytes(&image, self.bufs, self.base, self.shares.images)
                        .map_err(self.bad)?;
                let name = format!("image {}", image.index());
                // Checked now, so that a render does not fail on it.
                let what = (self.bad)(name.clone()).to_string();
                crate::texture::decode_rgba8(&bytes, &what)?;
                let i = self.sink.texture(&TextureImage::encoded(what, bytes))?;
                self.images.insert(image.index(), i);
                i
            }
        };
        let smp = tex.sampler();
        let sampler = Sampler {
            wrap_s: Wrap::from_gltf(smp.wrap_s().as_gl_enum()),
            wrap_t: Wrap::from_gltf(smp.wrap_t().as_gl_enum()),
            filter: Filter::from_gltf(smp.mag_filter().map(|f| f.as_gl_enum())),
        };
        Ok(TextureBinding {
            image: idx,
            sampler,
            transform,
            cutoff,
            alpha,
        })
    }
}

/// The texture coordinate set a texture reference reads.
fn info_set(info: &gltf::texture::Info<'_>) -> u32 {
    info.texture_transform()
        .and_then(|t| t.tex_coord())
        .unwrap_or(info.tex_coord())
}

/// A texture reference's `KHR_texture_transform`.
fn transform(info: &gltf::texture::Info<'_>) -> UvTransform {
    info.texture_transform()
        .map_or(UvTransform::default(), |t| UvTransform {
            offset: t.offset(),
            rotation: t.rotation(),
            scale: t.scale(),
        })
}

fn material(m: &gltf::Material<'_>, warnings: &mut Warnings) -> Material {
    if m.index().is_none() {
        return NEUTRAL;
    }
    let pbr = m.pbr_metallic_roughness();
    if m.occlusion_texture().is_some() {
        warnings.add(
            "occlusion textures are not applied (direct light has no ambient term to occlude)",
            || format!("material {}", m.index().unwrap_or(0)),
        );
    }
    let [r, g, b, _] = pbr.base_color_factor();
    let metallic = pbr.metallic_factor().clamp(0.0, 1.0);
    let roughness = pbr.roughness_factor().clamp(0.0, 1.0);
    let a = roughness.powi(2).max(1e-3);
    let t = m
        .transmission()
        .map_or(0.0, |t| t.transmission_factor().clamp(0.0, 1.0));
    // NFF's specular term is a mirror: a rough metal is mostly diffuse.
    let ks = metallic * (1.0 - roughness);
    Material {
        color: [r, g, b],
        kd: (1.0 - ks) * (1.0 - t),
        ks,
        shine: (2.0 / (a * a) - 2.0).clamp(1.0, 10_000.0),
        t,
        ior: m.ior().unwrap_or(1.5),
        pbr: Some(Pbr {
            metallic,
            roughness,
            emissive: m
                .emissive_factor()
                .map(|e| e * m.emissive_strength().unwrap_or(1.0)),
        }),
        texture: None,
        maps: crate::scene::Maps::NONE,
    }
}

/// The view of the first perspective camera the scene places (or of
/// camera `index`).
fn camera_view(
    placed: &[Placed<'_>],
    index: Option<usize>,
    bounds: &Bounds,
    warnings: &mut Warnings,
) -> Option<View> {
    for p in placed.iter().filter(|p| p.original) {
        let Some(cam) = p.node.camera() else {
            continue;
        };
        if index.is_some_and(|i| i != cam.index()) {
            continue;
        }
        let gltf::camera::Projection::Perspective(persp) = cam.projection() else {
            warnings.add(
                "an orthographic camera is not supported (the default view is used)",
                || format!("camera {}", cam.index()),
            );
            continue;
        };
        let from = p.world.transform_point3(DVec3::ZERO);
        let fwd = p.world.transform_vector3(DVec3::NEG_Z).try_normalize()?;
        let up = p.world.transform_vector3(DVec3::Y).try_normalize()?;
        let half =
            (persp.yfov() as f64 / 2.0).tan() * persp.aspect_ratio().unwrap_or(1.0).max(1.0) as f64;
        let (_, size) = bounds.centre_and_size();
        return Some(View {
            from: from.to_array(),
            at: (from + fwd).to_array(),
            up: up.to_array(),
            angle: (2.0 * half.atan()).to_degrees(),
            hither: (persp.znear() as f64).min(1e-3 * size),
            resolution: [512, 512],
        });
    }
    None
}

/// The scene's `KHR_lights_punctual` lights as NFF point lights.
fn punctual_lights(placed: &[Placed<'_>], bounds: &Bounds, warnings: &mut Warnings) -> Vec<Light> {
    use gltf::khr_lights_punctual::Kind;
    let (centre, size) = bounds.centre_and_size();
    let mut out = Vec::new();
    for p in placed.iter().filter(|p| p.original) {
        let Some(l) = p.node.light() else {
            continue;
        };
        let at = p.world.transform_point3(DVec3::ZERO);
        let dir = p
            .world
            .transform_vector3(DVec3::NEG_Z)
            .try_normalize()
            .unwrap_or(DVec3::NEG_Y);
        let (kind, position, inner_cone, outer_cone) = match l.kind() {
            Kind::Point => (LightKind::Point, at, 0.0, 0.0),
            Kind::Spot {
                inner_cone_angle,
                outer_cone_angle,
            } => {
                let outer = outer_cone_angle.clamp(0.0, std::f32::consts::FRAC_PI_2);
                (
                    LightKind::Spot,
                    at,
                    inner_cone_angle.clamp(0.0, outer),
                    outer,
                )
            }
            // Placed far along its reverse direction for whatever wants
            // a position (an NFF output); shading uses its direction.
            Kind::Directional => (
                LightKind::Directional,
                centre - dir * 100.0 * size,
                0.0,
                0.0,
            ),
        };
        let mut intensity = l.intensity();
        if !(intensity.is_finite() && intensity >= 0.0) {
            warnings.add(
                "a light's intensity is not a finite non-negative number (1 is used)",
                || format!("light {}", l.index()),
            );
            intensity = 1.0;
        }
        out.push(Light {
            position: position.to_array(),
            color: Some(l.color()),
            photometric: Some(Photometric {
                kind,
                intensity,
                range: l.range().filter(|r| r.is_finite() && *r > 0.0),
                inner_cone,
                outer_cone,
                direction: dir.to_array(),
            }),
        });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The triangles of whole index lists, as glTF defines them.
    fn reference(mode: Mode, idx: &[u32]) -> Vec<[u32; 3]> {
        let n = idx.len();
        match mode {
            Mode::Triangles => idx.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect(),
            Mode::TriangleStrip => (0..n.saturating_sub(2))
                .map(|k| match k % 2 {
                    1 => [idx[k + 1], idx[k], idx[k + 2]],
                    _ => [idx[k], idx[k + 1], idx[k + 2]],
                })
                .collect(),
            _ => (0..n.saturating_sub(2))
                .map(|k| [idx[0], idx[k + 1], idx[k + 2]])
                .collect(),
        }
    }

    #[test]
    fn assembled_triangles_are_the_lists_strips_and_fans_of_the_spec() {
        for mode in [Mode::Triangles, Mode::TriangleStrip, Mode::TriangleFan] {
            for n in 0..12u32 {
                let idx: Vec<u32> = (0..n).map(|i| 100 + i * 7 % 11).collect();
                let mut a = Assembler::new(mode);
                let got: Vec<[u32; 3]> = idx.iter().filter_map(|&i| a.push(i)).collect();
                assert_eq!(got, reference(mode, &idx), "{mode:?}, {n} indices");
            }
        }
    }
}
