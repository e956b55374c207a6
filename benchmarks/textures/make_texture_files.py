"""Makes the textured inputs of this comparison with tools no one here wrote
(trimesh, Pillow), from ../shared/meshes/spot.obj (Keenan Crane's Spot, which
has texture coordinates `vt`).

    python3 make_texture_files.py /work/shared/meshes/spot.obj out/inputs

writes
  uvgrid.png          a 512x512 procedural texture: 8x8 cells, hue stepping by
                      column and by 3 columns a row (so each row is a
                      different order of hues), lightness by row, each cell numbered "rc" (row, column),
                      row 0 at the image's top, so a flipped or shifted UV is
                      obvious;
  leaf.png            an RGBA leaf with holes (for make_blender_gltf.py);
  spot_tex.glb        trimesh's glTF export (TEXCOORD_0, baseColorTexture,
                      metallic 0, roughness 1);
  spot_tex/spot_tex.obj + material.mtl + the PNG: trimesh's OBJ export
                      (vt, mtllib, map_Kd);
  spot_tex_ply/spot_tex.ply + PNG: trimesh's PLY export (binary, `s t`
                      per vertex), plus the header line `comment
                      TextureFile uvgrid.png`, which trimesh does not write.
"""
import colorsys
import os
import sys

import numpy as np
import trimesh
from PIL import Image, ImageDraw, ImageFont


def uv_grid(n=512, cells=8):
    img = Image.new("RGB", (n, n))
    d = ImageDraw.Draw(img)
    c = n // cells
    try:
        font = ImageFont.load_default(size=c // 2)
    except TypeError:  # Pillow < 10.1
        font = ImageFont.load_default()
    for r in range(cells):
        for k in range(cells):
            h = ((k + 3 * r) % cells) / cells
            light = 0.30 + 0.45 * r / (cells - 1)
            if (r + k) % 2:
                light *= 0.55
            rgb = colorsys.hls_to_rgb(h, light, 0.9)
            d.rectangle([k * c, r * c, (k + 1) * c - 1, (r + 1) * c - 1],
                        fill=tuple(int(255 * v) for v in rgb))
            d.text((k * c + c // 2, r * c + c // 2), f"{r}{k}", fill=(255, 255, 255),
                   font=font, anchor="mm")
    # A white bar along the top edge and a black one along the left edge:
    # which way is up and which way is left, whatever the cell numbers say.
    d.rectangle([0, 0, n - 1, 5], fill=(255, 255, 255))
    d.rectangle([0, 0, 5, n - 1], fill=(0, 0, 0))
    return img


def leaf(n=256):
    """An RGBA leaf: opaque inside an ellipse, with three round holes and a
    stem; alpha 0 elsewhere (for an alpha-mask cut-out)."""
    img = Image.new("RGBA", (n, n), (0, 0, 0, 0))
    d = ImageDraw.Draw(img)
    d.ellipse([n * 0.22, n * 0.04, n * 0.78, n * 0.86], fill=(40, 150, 30, 255))
    d.line([n * 0.5, n * 0.08, n * 0.5, n * 0.99], fill=(120, 70, 20, 255), width=n // 32)
    for k in range(1, 6):
        y = n * (0.15 + 0.12 * k)
        d.line([n * 0.5, y, n * 0.3, y - n * 0.1], fill=(150, 200, 60, 255), width=n // 64)
        d.line([n * 0.5, y, n * 0.7, y - n * 0.1], fill=(150, 200, 60, 255), width=n // 64)
    for cx, cy, r in [(0.36, 0.30, 0.06), (0.64, 0.45, 0.05), (0.40, 0.65, 0.04)]:
        d.ellipse([n * (cx - r), n * (cy - r), n * (cx + r), n * (cy + r)], fill=(0, 0, 0, 0))
    return img


def main():
    src, out = sys.argv[1], sys.argv[2]
    os.makedirs(out, exist_ok=True)
    img = uv_grid()
    img.save(os.path.join(out, "uvgrid.png"))
    leaf().save(os.path.join(out, "leaf.png"))

    # process=False keeps the faces as they are; the loader splits the
    # vertices at UV seams (3,225 vertices for 2,930 positions).
    mesh = trimesh.load(src, process=False)
    uv = mesh.visual.uv
    assert uv is not None and len(uv) == len(mesh.vertices), "spot.obj lost its UVs"

    # glTF: an explicit metallic-roughness material (dielectric, rough).
    mat = trimesh.visual.material.PBRMaterial(
        name="uvgrid", baseColorTexture=img, baseColorFactor=[255, 255, 255, 255],
        metallicFactor=0.0, roughnessFactor=1.0)
    g = mesh.copy()
    g.visual = trimesh.visual.TextureVisuals(uv=uv, material=mat)
    g.export(os.path.join(out, "spot_tex.glb"))

    # OBJ + MTL + PNG: a simple (Phong) material with the image as map_Kd.
    sm = trimesh.visual.material.SimpleMaterial(
        name="uvgrid", image=img, diffuse=[255, 255, 255, 255])
    o = mesh.copy()
    o.visual = trimesh.visual.TextureVisuals(uv=uv, material=sm)
    d = os.path.join(out, "spot_tex")
    os.makedirs(d, exist_ok=True)
    o.export(os.path.join(d, "spot_tex.obj"))

    # PLY: trimesh writes per-vertex texture coordinates (`s t`) but not
    # the image's name; the one header line `comment TextureFile` (which
    # trimesh's own reader understands) is added here, nothing else.
    d = os.path.join(out, "spot_tex_ply")
    os.makedirs(d, exist_ok=True)
    ply = trimesh.exchange.ply.export_ply(o)
    head, sep, body = ply.partition(b"end_header\n")
    head = head.replace(b"element vertex", b"comment TextureFile uvgrid.png\nelement vertex", 1)
    with open(os.path.join(d, "spot_tex.ply"), "wb") as f:
        f.write(head + sep + body)
    img.save(os.path.join(d, "uvgrid.png"))
    print("trimesh", trimesh.__version__, "wrote", sorted(os.listdir(out)))


if __name__ == "__main__":
    main()
