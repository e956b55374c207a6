"""Blender (3.4) writes a textured glTF scene with its own exporter:

    blender -b --factory-startup --python make_blender_gltf.py -- out/inputs

reads out/inputs/uvgrid.png and leaf.png (make_texture_files.py) and writes
out/inputs/blender_scene.glb:
  - a 4x4 ground plane with uvgrid.png (Blender's plane UVs, 0..1) through
    a Mapping node (rotation 25 degrees, scale 1.6, an offset), which the
    exporter writes as KHR_texture_transform; the texture repeats;
  - a UV sphere with uvgrid.png times a vertex colour (COLOR_0, red at
    the bottom to blue at the top, a height gradient);
  - a vertical quad with leaf.png and blend mode CLIP (exported as
    alphaMode MASK, alphaCutoff 0.5): the ground shows through the holes;
  - a camera (perspective, 40 degrees) and a point light
    (KHR_lights_punctual; the exporter's default photometric units).
"""
import math
import os
import sys

import bpy

out = sys.argv[sys.argv.index("--") + 1]
bpy.ops.wm.read_factory_settings(use_empty=True)
sc = bpy.context.scene


def textured(name, image, clip=False, vcol=None, mapping=None):
    m = bpy.data.materials.new(name)
    m.use_nodes = True
    nt = m.node_tree
    bsdf = nt.nodes["Principled BSDF"]
    bsdf.inputs["Roughness"].default_value = 1.0
    bsdf.inputs["Metallic"].default_value = 0.0
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = bpy.data.images.load(os.path.abspath(os.path.join(out, image)))
    col = tex.outputs["Color"]
    if mapping:
        uv = nt.nodes.new("ShaderNodeTexCoord")
        mp = nt.nodes.new("ShaderNodeMapping")
        mp.vector_type = "POINT"
        mp.inputs["Location"].default_value = (*mapping["offset"], 0)
        mp.inputs["Rotation"].default_value = (0, 0, math.radians(mapping["rotation"]))
        mp.inputs["Scale"].default_value = (*mapping["scale"], 1)
        nt.links.new(uv.outputs["UV"], mp.inputs["Vector"])
        nt.links.new(mp.outputs["Vector"], tex.inputs["Vector"])
    if vcol:
        attr = nt.nodes.new("ShaderNodeVertexColor")
        attr.layer_name = vcol
        mul = nt.nodes.new("ShaderNodeMixRGB")
        mul.blend_type = "MULTIPLY"
        mul.inputs["Fac"].default_value = 1.0
        nt.links.new(col, mul.inputs["Color1"])
        nt.links.new(attr.outputs["Color"], mul.inputs["Color2"])
        col = mul.outputs["Color"]
    nt.links.new(col, bsdf.inputs["Base Color"])
    if clip:
        nt.links.new(tex.outputs["Alpha"], bsdf.inputs["Alpha"])
        m.blend_method = "CLIP"
        m.alpha_threshold = 0.5
    return m


bpy.ops.mesh.primitive_plane_add(size=4, location=(0, 0, 0))
bpy.context.object.name = "ground"
# A Mapping node on the ground's UVs: the exporter writes it as
# KHR_texture_transform (offset, rotation, scale), the importer reads it back.
bpy.context.object.data.materials.append(textured(
    "ground", "uvgrid.png",
    mapping={"offset": (0.15, 0.1), "rotation": 25.0, "scale": (1.6, 1.6)}))

bpy.ops.mesh.primitive_uv_sphere_add(segments=48, ring_count=24, radius=0.6,
                                     location=(-0.7, -0.4, 0.6))
s = bpy.context.object
s.name = "ball"
bpy.ops.object.shade_smooth()
ca = s.data.color_attributes.new("Col", "BYTE_COLOR", "CORNER")
for poly in s.data.polygons:
    for li in poly.loop_indices:
        z = s.data.vertices[s.data.loops[li].vertex_index].co.z  # -0.6..0.6
        t = (z + 0.6) / 1.2
        ca.data[li].color = (1.0 - t, 0.3, t, 1.0)
s.data.materials.append(textured("ball", "uvgrid.png", vcol="Col"))

bpy.ops.mesh.primitive_plane_add(size=1.4, location=(0.8, 0.3, 0.75),
                                 rotation=(math.radians(90), 0, math.radians(-20)))
bpy.context.object.name = "leaf"
bpy.context.object.data.materials.append(textured("leaf", "leaf.png", clip=True))

# The exporter writes yfov and aspectRatio for the scene's resolution: a
# square one, as the comparison renders (for another aspect ratio sray keeps
# the angle across the longer side, Blender the vertical yfov).
sc.render.resolution_x = sc.render.resolution_y = 384
cam = bpy.data.cameras.new("cam")
cam.angle = math.radians(40)
co = bpy.data.objects.new("cam", cam)
sc.collection.objects.link(co)
co.location = (1.2, -5.0, 2.6)
d = -co.location
co.rotation_euler = d.to_track_quat("-Z", "Y").to_euler()
sc.camera = co

light = bpy.data.lights.new("lamp", "POINT")
# glTF point lights are candela and sray shows them unscaled (1 cd at 1 m
# on white Lambert is 1/pi): the exporter writes W/(4 pi) x 683 cd, so
# 1.6 W is about 87 cd, a well-exposed image 5.6 m away.
light.energy = 1.6
light.shadow_soft_size = 0.0
lo = bpy.data.objects.new("lamp", light)
lo.location = (-2.5, -3.0, 4.0)
sc.collection.objects.link(lo)

bpy.ops.export_scene.gltf(filepath=os.path.join(out, "blender_scene.glb"),
                          export_format="GLB", export_cameras=True,
                          export_lights=True, export_colors=True)
print("wrote", os.path.join(out, "blender_scene.glb"))
