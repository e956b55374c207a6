"""Renders one textured file with Blender's Cycles as sray would see it.

    blender -b --factory-startup -t 1 --python render_blender.py -- SETUP.json

SETUP.json (written by compare.py) holds, in the FILE's own coordinates:
  file, out (PNG), width, height, samples,
  camera: null (use the glTF file's own camera) or {from, at, up, fov},
  lights: null (use the glTF file's own KHR_lights_punctual lights) or a
          list of {position, color}: sray's default NFF point lights,
  background: [r, g, b], lambert: true for OBJ/PLY (NFF's model).

What is matched to sray (see README.md):
  - coordinates: Blender's glTF and OBJ importers turn +y-up into +z-up,
    (x, y, z) -> (x, -z, y); the PLY importer keeps coordinates, so the PLY
    object is turned the same way here; cameras and lights given in the
    file's coordinates are mapped likewise;
  - sray's default lights are NFF point lights: no fall-off with distance,
    white Lambert radiance = colour x cos. A Cycles point light of power P
    through a Light Falloff node's Constant output gives P/(4 pi^2) x cos
    (measured), so P = 4 pi^2 x colour. glTF materials under them: sray
    takes the colour as illuminance pi x I, the same thing;
  - the file's glTF punctual lights are imported in 'COMPAT' units
    (W = 4 pi x cd), which makes Cycles' radiance base/pi x cd/d^2, sray's;
  - direct light only (max_bounces 0; transparent bounces allowed for
    alpha cut-outs), hard shadows (radius 0), no denoising;
  - linear output: view transform 'Standard', display device 'None'
    (sray writes linear values, no gamma);
  - the background colour for camera rays only (no world lighting);
  - OBJ and PLY: NFF's model is Lambert with colour Kd x texture and no
    highlight for illum 2, so their material becomes a Diffuse BSDF
    (roughness 0 = Lambert) of image x Kd.
"""
import json
import math
import os
import sys

import bpy
import numpy
from mathutils import Vector

# Blender 3.4's glTF importer uses numpy.bool, which Debian 12's numpy 1.24
# no longer has (it was an alias of bool).
if not hasattr(numpy, "bool") or numpy.bool is not bool:
    try:
        numpy.bool
    except AttributeError:
        numpy.bool = bool

cfg = json.load(open(sys.argv[sys.argv.index("--") + 1]))
path = cfg["file"]
ext = path.lower().rsplit(".", 1)[-1]

bpy.ops.wm.read_factory_settings(use_empty=True)
sc = bpy.context.scene


def to_blender(p):
    x, y, z = p
    return Vector((x, -z, y))


# --- import -------------------------------------------------------------
if ext in ("glb", "gltf"):
    bpy.ops.import_scene.gltf(filepath=path, convert_lighting_mode="COMPAT")
elif ext == "obj":
    bpy.ops.wm.obj_import(filepath=path, forward_axis="NEGATIVE_Z", up_axis="Y")
elif ext == "ply":
    bpy.ops.import_mesh.ply(filepath=path)
    for o in bpy.context.selected_objects:
        o.rotation_euler = (math.radians(90), 0, 0)
else:
    raise SystemExit(f"unknown file type {path}")
bpy.context.view_layer.update()
meshes = [o for o in sc.objects if o.type == "MESH"]
print("IMPORTED", len(meshes), "meshes", sum(len(o.data.polygons) for o in meshes), "faces")


def lambert(obj, image, kd=(1, 1, 1)):
    m = bpy.data.materials.new("nff_lambert")
    m.use_nodes = True
    nt = m.node_tree
    for n in list(nt.nodes):
        if n.type != "OUTPUT_MATERIAL":
            nt.nodes.remove(n)
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = image
    tex.interpolation = "Linear"
    if cfg.get("flip_v"):
        # The negative control: the texture upside down (v -> 1 - v).
        uvn = nt.nodes.new("ShaderNodeTexCoord")
        mp = nt.nodes.new("ShaderNodeMapping")
        mp.inputs["Location"].default_value = (0, 1, 0)
        mp.inputs["Scale"].default_value = (1, -1, 1)
        nt.links.new(uvn.outputs["UV"], mp.inputs["Vector"])
        nt.links.new(mp.outputs["Vector"], tex.inputs["Vector"])
    mul = nt.nodes.new("ShaderNodeMixRGB")
    mul.blend_type = "MULTIPLY"
    mul.inputs["Fac"].default_value = 1.0
    mul.inputs["Color2"].default_value = (*kd, 1)
    d = nt.nodes.new("ShaderNodeBsdfDiffuse")
    d.inputs["Roughness"].default_value = 0.0
    nt.links.new(tex.outputs["Color"], mul.inputs["Color1"])
    nt.links.new(mul.outputs["Color"], d.inputs["Color"])
    nt.links.new(d.outputs[0], nt.nodes["Material Output"].inputs[0])
    obj.data.materials.clear()
    obj.data.materials.append(m)


if cfg.get("lambert"):
    for o in meshes:
        img, kd = None, (1, 1, 1)
        for slot in o.material_slots:
            if slot.material and slot.material.node_tree:
                for n in slot.material.node_tree.nodes:
                    if n.type == "TEX_IMAGE" and n.image:
                        img = n.image
                    if n.type == "BSDF_PRINCIPLED" and not n.inputs["Base Color"].is_linked:
                        kd = tuple(n.inputs["Base Color"].default_value[:3])
        if img is None and cfg.get("texture"):
            img = bpy.data.images.load(cfg["texture"])
        if img is None:
            raise SystemExit("no texture image found for " + o.name)
        # The PLY importer names its UV layer; make sure the texture uses it.
        lambert(o, img, kd)

# glTF alpha MASK: Cycles ignores the material's blend mode and treats alpha
# as coverage; make it a hard cut-off at alphaCutoff like sray's.
for m in bpy.data.materials:
    if m.blend_method == "CLIP" and m.node_tree:
        nt = m.node_tree
        for n in nt.nodes:
            if n.type == "BSDF_PRINCIPLED" and n.inputs["Alpha"].is_linked:
                src = n.inputs["Alpha"].links[0].from_socket
                cmp_ = nt.nodes.new("ShaderNodeMath")
                cmp_.operation = "GREATER_THAN"  # alpha >= cutoff (equality has measure 0)
                cmp_.inputs[1].default_value = m.alpha_threshold
                nt.links.new(src, cmp_.inputs[0])
                nt.links.new(cmp_.outputs[0], n.inputs["Alpha"])
                print("MASK", m.name, "cutoff", m.alpha_threshold)

# Diagnostic (compare.py --diag): glTF materials' Principled BSDF replaced
# by a Lambert Diffuse BSDF of the same base colour, to see how much of a
# difference is Principled's diffuse model.
if cfg.get("principled_to_lambert"):
    for m in bpy.data.materials:
        if not m.node_tree:
            continue
        nt = m.node_tree
        for n in list(nt.nodes):
            if n.type != "BSDF_PRINCIPLED":
                continue
            d = nt.nodes.new("ShaderNodeBsdfDiffuse")
            d.inputs["Roughness"].default_value = 0.0
            bc = n.inputs["Base Color"]
            if bc.is_linked:
                nt.links.new(bc.links[0].from_socket, d.inputs["Color"])
            else:
                d.inputs["Color"].default_value = bc.default_value
            if n.inputs["Alpha"].is_linked:
                # keep the cut-out: mix with a transparent BSDF by alpha
                tr = nt.nodes.new("ShaderNodeBsdfTransparent")
                mx = nt.nodes.new("ShaderNodeMixShader")
                nt.links.new(n.inputs["Alpha"].links[0].from_socket, mx.inputs["Fac"])
                nt.links.new(tr.outputs[0], mx.inputs[1])
                nt.links.new(d.outputs[0], mx.inputs[2])
                out = mx.outputs[0]
            else:
                out = d.outputs[0]
            for l in list(n.outputs[0].links):
                nt.links.new(out, l.to_socket)
            nt.nodes.remove(n)

# --- camera ---------------------------------------------------------------
if cfg["camera"] is None:
    cams = [o for o in sc.objects if o.type == "CAMERA"]
    if not cams:
        raise SystemExit("the file has no camera and none was given")
    sc.camera = cams[0]
else:
    c = cfg["camera"]
    cd = bpy.data.cameras.new("sray_view")
    cd.sensor_fit = "AUTO"  # the angle spans the longer side, as sray's
    cd.angle = math.radians(c["fov"])
    cd.clip_start = 1e-4
    co = bpy.data.objects.new("sray_view", cd)
    sc.collection.objects.link(co)
    f, a, u = to_blender(c["from"]), to_blender(c["at"]), to_blender(c["up"])
    fwd = (a - f).normalized()
    right = fwd.cross(u).normalized()
    upv = right.cross(fwd)
    from mathutils import Matrix
    m = Matrix((right, upv, -fwd)).transposed()
    co.matrix_world = Matrix.Translation(f) @ m.to_4x4()
    sc.camera = co

# --- lights ---------------------------------------------------------------
if cfg["lights"] is not None:
    for o in [o for o in sc.objects if o.type == "LIGHT"]:
        bpy.data.objects.remove(o)
    for i, l in enumerate(cfg["lights"]):
        ld = bpy.data.lights.new(f"nff{i}", "POINT")
        ld.shadow_soft_size = 0.0
        ld.color = l["color"]
        ld.energy = 4 * math.pi ** 2  # times the colour: NFF's I
        ld.use_nodes = True
        t = ld.node_tree
        em = [n for n in t.nodes if n.type == "EMISSION"][0]
        fo = t.nodes.new("ShaderNodeLightFalloff")
        fo.inputs["Strength"].default_value = 1.0
        t.links.new(fo.outputs["Constant"], em.inputs["Strength"])
        lo = bpy.data.objects.new(f"nff{i}", ld)
        lo.location = to_blender(l["position"])
        sc.collection.objects.link(lo)
else:
    for o in sc.objects:
        if o.type == "LIGHT":
            o.data.shadow_soft_size = 0.0
            print("LIGHT", o.name, o.data.type, o.data.energy, tuple(o.location))

# --- world: the background for camera rays only -----------------------------
w = bpy.data.worlds.new("bg")
w.use_nodes = True
nt = w.node_tree
bg = nt.nodes["Background"]
lp = nt.nodes.new("ShaderNodeLightPath")
mix = nt.nodes.new("ShaderNodeMixRGB")
mix.inputs["Color1"].default_value = (0, 0, 0, 1)
mix.inputs["Color2"].default_value = (*cfg["background"], 1)
nt.links.new(lp.outputs["Is Camera Ray"], mix.inputs["Fac"])
nt.links.new(mix.outputs["Color"], bg.inputs["Color"])
sc.world = w

# --- render -----------------------------------------------------------------
sc.render.engine = "CYCLES"
sc.cycles.device = "CPU"
sc.cycles.samples = cfg["samples"]
sc.cycles.use_denoising = False
sc.cycles.use_adaptive_sampling = False
sc.cycles.max_bounces = 0
sc.cycles.transparent_max_bounces = 16
sc.cycles.filter_width = 1.0
sc.cycles.seed = 1
sc.render.resolution_x = cfg["width"]
sc.render.resolution_y = cfg["height"]
sc.render.resolution_percentage = 100
sc.render.film_transparent = False
sc.view_settings.view_transform = "Standard"
sc.view_settings.look = "None"
sc.view_settings.exposure = 0.0
sc.view_settings.gamma = 1.0
sc.display_settings.display_device = "None"
sc.render.image_settings.file_format = "PNG"
sc.render.image_settings.color_mode = "RGB"
sc.render.image_settings.color_depth = "8"
sc.render.filepath = cfg["out"]
import time
t0 = time.time()
bpy.ops.render.render(write_still=True)
print("RENDER_SECONDS", time.time() - t0)
