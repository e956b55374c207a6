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
//! - **Lights** (`KHR_lights_punctual`): a point light at its node's
//!   position, in its colour (NFF lights have no intensity or falloff:
//!   `intensity` is ignored). A spot light is taken as a point light and a
//!   directional one as a point light far along its reverse direction;
//!   each says so once. No light: the default lights of a mesh.
//! - **Materials** (metallic-roughness): base colour -> colour; metallic
//!   and roughness -> specular reflection, which is a mirror in NFF, so a
//!   rough metal is mostly diffuse (`Ks = metallic * (1 - roughness)`,
//!   `Kd = 1 - Ks`); roughness -> Phong exponent `2 / a^2 - 2` with
//!   `a = roughness^2` (at least 1); `KHR_materials_transmission` ->
//!   transmission, which takes its share from the diffuse; `KHR_materials_ior` -> index of
//!   refraction (1.5 by default). Textures are ignored, with one warning.
//!   A primitive without a material is the meshes' neutral grey.
//!
//! Bad input is an error that names the file and what is wrong: a missing
//! or short buffer, an accessor outside its buffer, an index past the
//! vertices, a cycle in the node graph, a primitive of points or lines.

use super::builder::NEUTRAL;
use super::{MeshOptions, MeshSummary, Warnings};
use crate::error::Error;
use crate::models::{place_normal, place_point};
use crate::progress::Progress;
use crate::scene::setup::{DEFAULT_BACKGROUND, default_lights};
use crate::scene::{Light, Material, MeshFacts, SceneSink, View};
use crate::shapes::{Patch, Polygon, Shape};
use glam::{DAffine3, DMat4, DVec3};
use gltf::mesh::Mode;
use std::io::Read;
use std::path::Path;

/// Reads the glTF scene at `path` into `sink`.
pub fn read_gltf(
    path: &Path,
    sink: &mut dyn SceneSink,
    progress: &dyn Progress,
    opts: &MeshOptions,
) -> Result<MeshSummary, Error> {
    // Progress is the file's bytes: the document and a GLB's buffer are
    // read whole before anything is emitted (external buffers are read by
    // the gltf crate, unreported).
    let mut bytes = Vec::new();
    crate::input::open(path, progress)?
        .reader
        .read_to_end(&mut bytes)
        .map_err(|e| Error::Scene(format!("{}: {e}", path.display())))?;
    read_gltf_bytes(&bytes, path, path.parent(), opts, sink, progress)
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
    let camera_index = opts.camera_index;
    let bad = |what: String| Error::Scene(format!("{}: {what}", name.display()));
    let invalid = |e: gltf::Error| bad(format!("not a valid glTF file: {e}"));
    let gltf = gltf::Gltf::from_slice_without_validation(bytes).map_err(invalid)?;
    let blob = gltf.blob;
    // gltf-json 1.4.1's validation indexes a primitive's POSITION accessor
    // before checking that it exists (a panic on a bad file): check that
    // first, then validate.
    let json = gltf.document.into_json();
    for (m, mesh) in json.meshes.iter().enumerate() {
        for (k, prim) in mesh.primitives.iter().enumerate() {
            for a in prim.attributes.values() {
                if a.value() >= json.accessors.len() {
                    return Err(bad(format!(
                        "mesh {m} primitive {k}: an attribute names accessor {}, of {}",
                        a.value(),
                        json.accessors.len()
                    )));
                }
            }
        }
    }
    let doc = gltf::Document::from_json(json).map_err(invalid)?;
    // The gltf crate unwraps the percent-decoding of a relative buffer URI
    // (a panic on an escape that is not UTF-8): check it first.
    for b in doc.buffers() {
        if let gltf::buffer::Source::Uri(u) = b.source()
            && !u.contains(':')
            && !percent_decodes_to_utf8(u)
        {
            return Err(bad(format!(
                "buffer {}: its URI is not UTF-8 once decoded",
                b.index()
            )));
        }
    }
    // A glTF file is read whole, with its buffers: refused, before the
    // buffers are read, if they would take more than the budget. (Meshes
    // in other formats are read within it, spilling to disk.)
    let buffer_bytes: u64 = doc.buffers().map(|b| b.length() as u64).sum();
    let need = bytes.len() as u64 + buffer_bytes;
    if need > opts.memory {
        return Err(bad(format!(
            "its document and buffers take {}, more than the memory budget of {}; \
             a glTF file is read whole (raise --memory)",
            crate::units::fmt_bytes(need),
            crate::units::fmt_bytes(opts.memory)
        )));
    }
    let buffers = gltf::import_buffers(&doc, base, blob)
        .map_err(|e| bad(format!("cannot load its buffers: {e}")))?;
    let scene = doc
        .default_scene()
        .or_else(|| doc.scenes().next())
        .ok_or_else(|| bad("it has no scene".into()))?;
    let mut placed = place_nodes(&scene, doc.nodes().count()).map_err(bad)?;
    let mut warnings = Warnings::default();
    let get = |b: gltf::Buffer<'_>| buffers.get(b.index()).map(|d| &d.0[..]);
    gpu_instances(&doc, &mut placed, &buffers, get).map_err(&bad)?;

    // A mesh drawn by more than one placement is a model, stored once and
    // placed by instances, when the output keeps models; else (and for
    // a mesh drawn once) each placement writes its own copy.
    let mut uses = vec![0usize; doc.meshes().count()];
    for p in placed.iter().filter(|p| p.draws) {
        if let Some(m) = p.node.mesh() {
            uses[m.index()] += 1;
        }
    }
    let takes_models = sink.takes_models();
    let is_model = |m: &gltf::Mesh<'_>| takes_models && uses[m.index()] > 1;
    let mesh_vertices = |m: &gltf::Mesh<'_>| -> u64 {
        m.primitives()
            .filter_map(|p| p.get(&gltf::Semantic::Positions))
            .map(|a| a.count() as u64)
            .sum()
    };

    // Bounds of every placed primitive, from its positions.
    let mut bounds = Bounds::default();
    // The vertices the world stores (a copy's each time); a model's are
    // its own facts.
    let model_vertices: u64 = doc
        .meshes()
        .filter(is_model)
        .map(|m| mesh_vertices(&m))
        .sum();
    let mut vertices = 0u64;
    for p in &placed {
        if let Some(mesh) = p.node.mesh().filter(|_| p.draws) {
            if !is_model(&mesh) {
                vertices += mesh_vertices(&mesh);
            }
            for prim in mesh.primitives() {
                let Some(pos) = prim.get(&gltf::Semantic::Positions) else {
                    continue;
                };
                check_accessor(&pos, &buffers).map_err(&bad)?;
                check_vec3(&pos).map_err(&bad)?;
                let reader = prim.reader(get);
                for v in reader.read_positions().into_iter().flatten() {
                    bounds.add(p.world.transform_point3(DVec3::from(v.map(f64::from))));
                }
            }
        }
    }

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

    let mut summary = MeshSummary {
        vertices: vertices + model_vertices,
        ..Default::default()
    };
    let models: Vec<gltf::Mesh<'_>> = doc.meshes().filter(is_model).collect();
    let mut model_of: Vec<Option<u32>> = vec![None; uses.len()];
    let mut out = Emit {
        buffers: &buffers,
        sink,
        current: None,
        summary: &mut summary,
        warnings: &mut warnings,
        bad: &bad,
    };
    {
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
    super::report_summary(name, &summary, progress);
    Ok(summary)
}

/// Whether `%XX` escapes in `uri` decode to UTF-8.
fn percent_decodes_to_utf8(uri: &str) -> bool {
    let b = uri.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        let hex = |c: u8| (c as char).to_digit(16);
        match (
            b[i],
            b.get(i + 1).copied().and_then(hex),
            b.get(i + 2).copied().and_then(hex),
        ) {
            (b'%', Some(h), Some(l)) => {
                out.push((h * 16 + l) as u8);
                i += 3;
            }
            (c, ..) => {
                out.push(c);
                i += 1;
            }
        }
    }
    std::str::from_utf8(&out).is_ok()
}

/// Writes meshes' triangles into a sink.
struct Emit<'e, 'b> {
    buffers: &'b [gltf::buffer::Data],
    sink: &'e mut dyn SceneSink,
    /// The material the sink has now.
    current: Option<Material>,
    summary: &'e mut MeshSummary,
    warnings: &'e mut Warnings,
    bad: &'e dyn Fn(String) -> Error,
}

impl Emit<'_, '_> {
    /// Writes the triangles of `mesh` placed by `placement` (node `node`
    /// places it), or, without a placement, as they are in the file (a
    /// model's). A placed corner is [`place_point`] of the file's, a
    /// placed normal [`place_normal`] of the file's: exactly what an
    /// instance of the model computes, so that a copy and an instance are
    /// the same triangles. A model keeps the file's normals (a normal that
    /// is not finite as zero), to be placed by each instance.
    fn mesh(
        &mut self,
        mesh: &gltf::Mesh<'_>,
        placement: Option<&DAffine3>,
        node: usize,
    ) -> Result<(), Error> {
        let bad = self.bad;
        let buffers = self.buffers;
        let get = |b: gltf::Buffer<'_>| buffers.get(b.index()).map(|d| &d.0[..]);
        let normal_map = placement.map(|m| m.matrix3.inverse().transpose());
        for prim in mesh.primitives() {
            let what = || format!("mesh {} primitive {}", mesh.index(), prim.index());
            let mode = prim.mode();
            if !matches!(
                mode,
                Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
            ) {
                return Err(bad(format!(
                    "{}: {mode:?} primitives are not supported (only triangles, strips and fans)",
                    what()
                )));
            }
            let Some(pos) = prim.get(&gltf::Semantic::Positions) else {
                self.warnings
                    .add("a primitive without positions is skipped", what);
                continue;
            };
            let reader = prim.reader(get);
            let positions: Vec<[f32; 3]> = reader
                .read_positions()
                .ok_or_else(|| bad(format!("{}: positions cannot be read", what())))?
                .map(|v| match placement {
                    Some(m) => place_point(m, v),
                    None => v,
                })
                .collect();
            // A number that is not finite, in the file or once placed (a
            // transform too large for single precision).
            if let Some(k) = positions
                .iter()
                .position(|v| !v.iter().all(|c| c.is_finite()))
            {
                return Err(bad(match placement {
                    Some(_) => format!(
                        "{}: vertex {k} is not a finite point once placed by node {node}",
                        what()
                    ),
                    None => format!("{}: vertex {k} is not a finite point", what()),
                }));
            }
            let normals: Option<Vec<[f32; 3]>> = match prim.get(&gltf::Semantic::Normals) {
                Some(n) => {
                    check_accessor(&n, buffers).map_err(bad)?;
                    check_vec3(&n).map_err(bad)?;
                    if n.count() != pos.count() {
                        return Err(bad(format!(
                            "{}: {} normals for {} positions",
                            what(),
                            n.count(),
                            pos.count()
                        )));
                    }
                    reader.read_normals().map(|it| {
                        it.map(|v| match &normal_map {
                            // A normal that cannot be normalised (zero, or
                            // not finite) is taken as none (zero).
                            Some(nm) => place_normal(nm, v),
                            None if v.iter().all(|c| c.is_finite()) => v,
                            None => [0.0; 3],
                        })
                        .collect()
                    })
                }
                None => None,
            };
            let indices: Vec<u32> = match prim.indices() {
                Some(a) => {
                    check_accessor(&a, buffers).map_err(bad)?;
                    use gltf::accessor::DataType::{U8, U16, U32};
                    if a.dimensions() != gltf::accessor::Dimensions::Scalar
                        || !matches!(a.data_type(), U8 | U16 | U32)
                    {
                        return Err(bad(format!(
                            "{}: indices (accessor {}) must be unsigned integers",
                            what(),
                            a.index()
                        )));
                    }
                    let read = reader
                        .read_indices()
                        .ok_or_else(|| bad(format!("{}: indices cannot be read", what())))?;
                    let v: Vec<u32> = read.into_u32().collect();
                    if let Some(&i) = v.iter().find(|&&i| i as usize >= positions.len()) {
                        return Err(bad(format!(
                            "{}: index {i} is past its {} vertices",
                            what(),
                            positions.len()
                        )));
                    }
                    v
                }
                None => (0..positions.len() as u32).collect(),
            };
            let m = material(&prim.material(), self.warnings);
            if self.current != Some(m) {
                self.sink.material(&m)?;
                self.current = Some(m);
            }
            for t in triangles(mode, &indices) {
                self.summary.faces += 1;
                let v = t.map(|i| positions[i as usize]);
                if !super::geometry::has_area(v[0], v[1], v[2]) {
                    self.summary.degenerate += 1;
                    continue;
                }
                match &normals {
                    Some(n) => {
                        let n = t.map(|i| n[i as usize]);
                        self.sink.object(&Shape::Patch(Patch {
                            vertices: &v,
                            normals: &n,
                        }))?
                    }
                    None => self
                        .sink
                        .object(&Shape::Polygon(Polygon { vertices: &v }))?,
                }
                self.summary.objects += 1;
            }
        }
        Ok(())
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
fn place_nodes<'a>(scene: &gltf::Scene<'a>, nodes: usize) -> Result<Vec<Placed<'a>>, String> {
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
/// copy's translation, rotation and scale (each attribute optional; floats
/// only). The node itself stays, for its camera and light, without its
/// mesh being drawn.
fn gpu_instances<'a, 's>(
    doc: &'a gltf::Document,
    placed: &mut Vec<Placed<'a>>,
    buffers: &[gltf::buffer::Data],
    get: impl Clone + Fn(gltf::Buffer<'a>) -> Option<&'s [u8]>,
) -> Result<(), String> {
    use gltf::accessor::{DataType, Dimensions, Iter};
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
        let accessor =
            |name: &str, dims: Dimensions| -> Result<Option<gltf::Accessor<'a>>, String> {
                let Some(v) = attrs.get(name) else {
                    return Ok(None);
                };
                let a = v
                    .as_u64()
                    .and_then(|i| doc.accessors().nth(i as usize))
                    .ok_or_else(|| {
                        format!("node {node}: EXT_mesh_gpu_instancing {name} names no accessor")
                    })?;
                if a.data_type() != DataType::F32 || a.dimensions() != dims || a.normalized() {
                    return Err(format!(
                        "node {node}: EXT_mesh_gpu_instancing {name} must be {dims:?} of floats"
                    ));
                }
                check_accessor(&a, buffers)?;
                Ok(Some(a))
            };
        let t = accessor("TRANSLATION", Dimensions::Vec3)?;
        let r = accessor("ROTATION", Dimensions::Vec4)?;
        let sc = accessor("SCALE", Dimensions::Vec3)?;
        let counts: Vec<usize> = [&t, &r, &sc]
            .iter()
            .filter_map(|a| a.as_ref().map(|a| a.count()))
            .collect();
        let n = counts.first().copied().unwrap_or(0);
        if counts.iter().any(|&c| c != n) {
            return Err(format!(
                "node {node}: EXT_mesh_gpu_instancing attributes of different counts {counts:?}"
            ));
        }
        let read3 = |a: &Option<gltf::Accessor<'a>>| -> Result<Option<Vec<[f32; 3]>>, String> {
            a.clone()
                .map(|a| {
                    Iter::<[f32; 3]>::new(a, get.clone())
                        .map(|it| it.collect())
                        .ok_or_else(|| {
                            format!("node {node}: an instancing attribute cannot be read")
                        })
                })
                .transpose()
        };
        let ts = read3(&t)?;
        let ss = read3(&sc)?;
        let rs: Option<Vec<[f32; 4]>> = r
            .map(|a| {
                Iter::<[f32; 4]>::new(a, get.clone())
                    .map(|it| it.collect())
                    .ok_or_else(|| format!("node {node}: ROTATION cannot be read"))
            })
            .transpose()?;
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

/// Checks that an accessor lies within its buffer view and the view within
/// its buffer, so that reading it cannot go past the data.
fn check_accessor(a: &gltf::Accessor<'_>, buffers: &[gltf::buffer::Data]) -> Result<(), String> {
    let sparse = a.sparse();
    if let Some(sp) = &sparse {
        // A sparse accessor: a base (its buffer view, or zeros without
        // one) with `count` elements replaced at the listed indices.
        let n = sp.count();
        if n == 0 || n > a.count() {
            return Err(format!(
                "accessor {}: {n} sparse elements for {} elements",
                a.index(),
                a.count()
            ));
        }
        let idx = sp.indices();
        check_range(
            &idx.view(),
            buffers,
            idx.offset(),
            n,
            idx.index_type().size(),
            &format!("accessor {} sparse indices", a.index()),
        )?;
        let vals = sp.values();
        check_range(
            &vals.view(),
            buffers,
            vals.offset(),
            n,
            a.size(),
            &format!("accessor {} sparse values", a.index()),
        )?;
    }
    let Some(view) = a.view() else {
        if sparse.is_some() && a.count() > 0 {
            return Ok(());
        }
        return Err(format!("accessor {} has no buffer view", a.index()));
    };
    check_range(
        &view,
        buffers,
        a.offset(),
        a.count(),
        a.size(),
        &format!("accessor {} ({} elements)", a.index(), a.count()),
    )
}

/// Checks that `count` elements of `size` bytes from byte `offset` of
/// buffer view `view` (at its stride) lie within the view, and the view
/// within its buffer.
fn check_range(
    view: &gltf::buffer::View<'_>,
    buffers: &[gltf::buffer::Data],
    offset: usize,
    count: usize,
    size: usize,
    what: &str,
) -> Result<(), String> {
    let data = buffers.get(view.buffer().index()).map_or(0, |d| d.0.len());
    let view_end = view.offset().checked_add(view.length());
    if view_end.is_none_or(|e| e > data) {
        return Err(format!(
            "buffer view {} ends past its buffer's {data} bytes",
            view.index()
        ));
    }
    let stride = view.stride().unwrap_or(size).max(size);
    let end = match count {
        0 => Some(0),
        n => (n - 1)
            .checked_mul(stride)
            .and_then(|x| x.checked_add(offset))
            .and_then(|x| x.checked_add(size)),
    };
    if end.is_none_or(|e| e > view.length()) {
        return Err(format!(
            "{what} ends past its buffer view's {} bytes",
            view.length()
        ));
    }
    Ok(())
}

/// Checks that an accessor holds three floats per element, as positions
/// and normals must.
fn check_vec3(a: &gltf::Accessor<'_>) -> Result<(), String> {
    if a.dimensions() != gltf::accessor::Dimensions::Vec3
        || a.data_type() != gltf::accessor::DataType::F32
    {
        return Err(format!(
            "accessor {}: positions and normals must be three floats each",
            a.index()
        ));
    }
    Ok(())
}

/// The triangles of a primitive's indices.
fn triangles(mode: Mode, idx: &[u32]) -> impl Iterator<Item = [u32; 3]> + '_ {
    let n = idx.len();
    let count = match mode {
        Mode::Triangles => n / 3,
        _ => n.saturating_sub(2),
    };
    (0..count).map(move |k| match mode {
        Mode::Triangles => [idx[3 * k], idx[3 * k + 1], idx[3 * k + 2]],
        // Every other triangle of a strip is reversed to keep its winding.
        Mode::TriangleStrip if k % 2 == 1 => [idx[k + 1], idx[k], idx[k + 2]],
        Mode::TriangleStrip => [idx[k], idx[k + 1], idx[k + 2]],
        _ => [idx[0], idx[k + 1], idx[k + 2]],
    })
}

/// The NFF material of a glTF one (see the module documentation).
fn material(m: &gltf::Material<'_>, warnings: &mut Warnings) -> Material {
    if m.index().is_none() {
        return NEUTRAL;
    }
    let pbr = m.pbr_metallic_roughness();
    if pbr.base_color_texture().is_some()
        || pbr.metallic_roughness_texture().is_some()
        || m.normal_texture().is_some()
        || m.emissive_texture().is_some()
    {
        warnings.add("textures are ignored", || {
            format!("material {}", m.index().unwrap_or(0))
        });
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
        let position = match l.kind() {
            Kind::Point => at,
            Kind::Spot { .. } => {
                warnings.add("spot lights are taken as point lights", || {
                    format!("light {}", l.index())
                });
                at
            }
            Kind::Directional => {
                warnings.add(
                    "directional lights are taken as point lights far along their reverse direction",
                    || format!("light {}", l.index()),
                );
                let dir = p
                    .world
                    .transform_vector3(DVec3::NEG_Z)
                    .try_normalize()
                    .unwrap_or(DVec3::NEG_Y);
                centre - dir * 100.0 * size
            }
        };
        out.push(Light {
            position: position.to_array(),
            color: Some(l.color()),
        });
    }
    out
}
