"""sray against Blender (Cycles) on textured files other tools wrote.

    python3 compare.py [--sray PATH] [--size 384] [--samples 32] [--repeats 3]
                       [--only NAME ...]

Run from this directory after make_texture_files.py and make_blender_gltf.py
(see README.md). For each file it
  1. asks `sray info --json` for the bounds, and computes, as
     engine/src/scene/setup.rs does, the default view (files without a
     camera) and the default key and fill lights (files without lights);
  2. renders with sray, depth-first and breadth-first (--mode bf
     --memory 64MiB), and checks the two PNGs are byte-identical (cmp);
  3. renders with Blender through render_blender.py with the same view and
     lights (or the file's own);
  4. composes out/side/NAME.png (sray | Blender, both sRGB-encoded for
     viewing) and computes the figures below; results in out/results.json.

Figures (both images linear, 8-bit, as written):
  silhouette IoU  pixels that are not background in each image
                  (|pixel - background| > 6/255 in some channel):
                  intersection over union; 1 = the geometry lands on the
                  same pixels (camera and import match);
  structure corr  Pearson correlation of luminance / its local mean
                  (Gaussian, sigma 6 px) over pixels inside both
                  silhouettes: the texture's cells, checker and digits
                  against slowly varying shading; 1 = the same pattern on
                  the same pixels, about 0 or below = a misplaced texture;
  hue agreement   over pixels inside both silhouettes and coloured in
                  both (saturation > 0.25 and value > 0.04 in both; n/a
                  under 1,000 such pixels): mean cos(hue difference), and the
                  share within 20 degrees; 1 / 100 % = the texture's
                  colours land on the same pixels;
  vs_blender_lambert  (glTF files) the same figures against Blender with
                  its Principled BSDF replaced by a Lambert Diffuse BSDF of
                  the same base colour: a diagnostic of how much of the
                  difference is the BRDF;
  MAD             mean absolute difference over all pixels and channels,
                  in 0..255, linear values as written, and after sRGB
                  encoding both (what a viewer shows).
"""
import argparse
import colorsys  # noqa: F401  (documentation: hue as in colorsys)
import json
import math
import os
import statistics
import subprocess
import sys
import time

import numpy as np
from PIL import Image, ImageDraw, ImageFont

HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, "out")
INP = os.path.join(OUT, "inputs")
FIX = os.path.normpath(os.path.join(HERE, "..", "..", "tests", "fixtures", "gltf"))

# name, file, what it shows
CASES = [
    ("spot_tex_glb", os.path.join(INP, "spot_tex.glb"),
     "trimesh 5.2 glTF: spot.obj's UVs, the uvgrid texture, metallic 0 / roughness 1; no camera, no lights (sray's defaults)"),
    ("spot_tex_obj", os.path.join(INP, "spot_tex", "spot_tex.obj"),
     "trimesh 5.2 OBJ + MTL (map_Kd) + PNG, the same mesh and texture; NFF's Lambert model"),
    ("spot_tex_ply", os.path.join(INP, "spot_tex_ply", "spot_tex.ply"),
     "trimesh 5.2 binary PLY (s t per vertex) + `comment TextureFile` (added); NFF's Lambert model"),
    ("control_flipped", os.path.join(INP, "spot_tex", "spot_tex.obj"),
     "NEGATIVE CONTROL: spot_tex_obj with Blender's texture turned upside down (v -> 1 - v): what a misplaced texture scores"),
    ("spot4", os.path.join(FIX, "spot4.glb"),
     "fixture by trimesh: one mesh placed by four nodes, texture, camera; metallic 1 (glTF default) / roughness 0.9; default lights"),
    ("spot4_gltfpack", os.path.join(FIX, "spot4_gltfpack.glb"),
     "fixture by gltfpack 0.22: quantized positions/normals, UVs quantized with KHR_texture_transform (offset, scale), camera; default lights"),
    ("blender_scene", os.path.join(INP, "blender_scene.glb"),
     "Blender 3.4's glTF exporter: textured ground, ball with texture x COLOR_0, alpha MASK leaf, camera, point light (KHR_lights_punctual)"),
]

BG = [0.1, 0.11, 0.14]
FOV, ELEV, AZIM, FILL = 40.0, 20.0, 25.0, 0.9
KEY, FILL_L = [0.85] * 3, [0.35] * 3


# ---- vectors -----------------------------------------------------------------
def add(a, b): return [a[i] + b[i] for i in range(3)]
def sub(a, b): return [a[i] - b[i] for i in range(3)]
def mul(a, s): return [a[i] * s for i in range(3)]
def dot(a, b): return sum(a[i] * b[i] for i in range(3))
def cross(a, b): return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
def unit(a):
    n = math.sqrt(dot(a, a))
    return mul(a, 1 / n)


def front(up):
    a = [abs(c) for c in up]
    if a[1] >= a[0] and a[1] >= a[2]:
        f = [0, 0, math.copysign(1, up[1])]
    elif a[2] >= a[0]:
        f = [0, -math.copysign(1, up[2]), 0]
    else:
        f = [0, 0, 1]
    return unit(sub(f, mul(up, dot(f, up))))


def default_view(lo, hi, image, up=(0.0, 1.0, 0.0)):
    """engine/src/scene/setup.rs default_view, without overrides."""
    up = list(up)
    centre = mul(add(lo, hi), 0.5)
    fr = front(up)
    right = unit(cross(mul(fr, -1), up))
    el, az = math.radians(ELEV), math.radians(AZIM)
    d = unit(add(mul(add(mul(fr, math.cos(az)), mul(right, math.sin(az))), math.cos(el)),
                 mul(up, math.sin(el))))
    fwd = mul(d, -1)
    right = unit(cross(fwd, up))
    upv = cross(right, fwd)
    long = max(image)
    t = math.tan(math.radians(FOV) / 2) * FILL
    tx, ty = t * image[0] / long, t * image[1] / long
    dist = 0.0
    for k in range(8):
        c = [hi[i] if k >> i & 1 else lo[i] for i in range(3)]
        o = sub(c, centre)
        x, y, z = dot(o, right), dot(o, upv), dot(o, d)
        dist = max(dist, z + abs(x) / tx, z + abs(y) / ty)
    return {"from": add(centre, mul(d, dist)), "at": centre, "up": up, "fov": FOV}


def default_lights(lo, hi, view):
    centre = mul(add(lo, hi), 0.5)
    r = math.sqrt(dot(sub(hi, lo), sub(hi, lo))) / 2
    back = unit(sub(view["from"], view["at"]))
    fwd = mul(back, -1)
    right = unit(cross(fwd, view["up"]))
    upv = cross(right, fwd)
    place = lambda d: add(centre, mul(unit(d), 4 * r))  # noqa: E731
    return [
        {"position": place(add(add(back, upv), mul(right, -0.8))), "color": KEY},
        {"position": place(add(add(back, mul(right, 0.9)), mul(upv, -0.15))), "color": FILL_L},
    ]


def gltf_json(path):
    import struct
    b = open(path, "rb").read()
    if b[:4] == b"glTF":
        n = struct.unpack("<I", b[12:16])[0]
        return json.loads(b[20:20 + n])
    return json.loads(b)


def node_matrix(n):
    if "matrix" in n:
        return np.array(n["matrix"], dtype=float).reshape(4, 4).T
    t = np.array(n.get("translation", [0, 0, 0]), float)
    x, y, z, w = n.get("rotation", [0, 0, 0, 1])
    r = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                  [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                  [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    s = np.diag(n.get("scale", [1, 1, 1]))
    m = np.eye(4)
    m[:3, :3] = r @ s
    m[:3, 3] = t
    return m


def file_camera(j):
    """The view of the first camera node (root nodes only: enough here)."""
    for n in j.get("nodes", []):
        if "camera" in n:
            m = node_matrix(n)
            f = m @ [0, 0, 0, 1]
            fwd = m @ [0, 0, -1, 0]
            up = m @ [0, 1, 0, 0]
            return {"from": list(f[:3]), "at": list(f[:3] + fwd[:3]), "up": list(up[:3] / np.linalg.norm(up[:3]))}
    return None


# ---- running -------------------------------------------------------------------
# Debian's Blender embeds the system Python 3.11 and finds its standard
# library from the first python3.11 on PATH; a pyenv interpreter running
# this script would lend it its own (without numpy, which the glTF importer
# needs). Blender gets PATH without pyenv.
BLENDER_ENV = dict(os.environ, PATH=os.pathsep.join(
    p for p in os.environ.get("PATH", "").split(os.pathsep) if ".pyenv" not in p))


def run(cmd, **kw):
    t0 = time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True, **kw)
    dt = time.perf_counter() - t0
    if p.returncode != 0:
        print("FAILED:", " ".join(cmd), "\n", p.stdout[-2000:], p.stderr[-2000:], file=sys.stderr)
        raise SystemExit(1)
    return p, dt


def srgb(x):
    x = np.clip(x, 0, 1)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def hsv(a):
    mx, mn = a.max(-1), a.min(-1)
    c = mx - mn
    s = np.where(mx > 0, c / np.maximum(mx, 1e-9), 0)
    r, g, b = a[..., 0], a[..., 1], a[..., 2]
    cc = np.maximum(c, 1e-9)
    h = np.where(mx == r, ((g - b) / cc) % 6, np.where(mx == g, (b - r) / cc + 2, (r - g) / cc + 4)) / 6
    return h, s, mx


def lum(x):
    return x @ np.array([0.2126, 0.7152, 0.0722])


def blur(x, sigma):
    r = int(3 * sigma)
    k = np.exp(-0.5 * (np.arange(-r, r + 1) / sigma) ** 2)
    k /= k.sum()
    p = np.pad(x, r, mode="edge")
    p = np.apply_along_axis(lambda v: np.convolve(v, k, mode="valid"), 0, p)
    return np.apply_along_axis(lambda v: np.convolve(v, k, mode="valid"), 1, p)


def erode(m, n):
    for _ in range(n):
        m = m & np.roll(m, 1, 0) & np.roll(m, -1, 0) & np.roll(m, 1, 1) & np.roll(m, -1, 1)
    return m


def figures(a8, b8):
    a, b = a8.astype(float) / 255, b8.astype(float) / 255
    bg = np.array(BG)
    fa = (np.abs(a - bg) > 6 / 255).any(-1)
    fb = (np.abs(b - bg) > 6 / 255).any(-1)
    iou = (fa & fb).sum() / max((fa | fb).sum(), 1)
    ha, sa, va = hsv(a)
    hb, sb, vb = hsv(b)
    m = (sa > 0.25) & (sb > 0.25) & (va > 0.04) & (vb > 0.04) & fa & fb
    dh = (ha - hb)[m] * 2 * math.pi
    enough = m.sum() >= 1000  # a grey object has no hue to compare
    hue_cos = float(np.cos(dh).mean()) if enough else float("nan")
    within = float((np.abs(np.angle(np.exp(1j * dh))) < math.radians(20)).mean()) if enough else float("nan")
    # Structure: luminance over its local mean (shading varies slowly, the
    # texture's cells, checker and digits quickly), correlated over pixels
    # inside both silhouettes (eroded by 3 pixels, so edges do not count).
    la, lb = lum(a), lum(b)
    ra, rb = la / np.maximum(blur(la, 6), 1e-4), lb / np.maximum(blur(lb, 6), 1e-4)
    inside = erode(fa & fb, 3) & (la > 0.01) & (lb > 0.01)
    struct = float(np.corrcoef(ra[inside], rb[inside])[0, 1]) if inside.sum() > 10 else float("nan")
    mad_lin = float(np.abs(a - b).mean() * 255)
    mad_srgb = float(np.abs(srgb(a) - srgb(b)).mean() * 255)
    return {"silhouette_iou": float(iou), "structure_corr": struct, "hue_pixels": int(m.sum()), "hue_cos": hue_cos,
            "hue_within_20deg": within, "mad_linear": mad_lin, "mad_srgb": mad_srgb,
            "mean_sray": float(a.mean() * 255), "mean_blender": float(b.mean() * 255)}


def side_by_side(a8, b8, title, path):
    h, w, _ = a8.shape
    show = lambda x: Image.fromarray((srgb(x.astype(float) / 255) * 255 + 0.5).astype(np.uint8))  # noqa: E731
    bar = 22
    img = Image.new("RGB", (2 * w + 4, h + bar), (255, 255, 255))
    img.paste(show(a8), (0, bar))
    img.paste(show(b8), (w + 4, bar))
    d = ImageDraw.Draw(img)
    try:
        font = ImageFont.load_default(size=14)
    except TypeError:
        font = ImageFont.load_default()
    d.text((4, 3), f"sray  {title}", fill=(0, 0, 0), font=font)
    d.text((w + 8, 3), "Blender 3.4 Cycles", fill=(0, 0, 0), font=font)
    img.save(path, optimize=True)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--sray", default=os.path.normpath(os.path.join(HERE, "..", "..", "target", "release", "sray")))
    ap.add_argument("--blender", default="blender")
    ap.add_argument("--size", type=int, default=384)
    ap.add_argument("--samples", type=int, default=32)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--only", nargs="*")
    args = ap.parse_args()
    W = H = args.size
    for d in ("sray", "blender", "side", "setup"):
        os.makedirs(os.path.join(OUT, d), exist_ok=True)
    res_path = os.path.join(OUT, "results.json")
    results = json.load(open(res_path)) if os.path.exists(res_path) else {}
    for name, path, what in CASES:
        if args.only and name not in args.only:
            continue
        print("==", name, flush=True)
        info = json.loads(run([args.sray, "info", path, "--json"])[0].stdout)
        lo, hi = info_bounds(info)
        ext = path.rsplit(".", 1)[-1].lower()
        cam = lights = None
        j = gltf_json(path) if ext in ("glb", "gltf") else {}
        has_cam = file_camera(j) is not None
        has_lights = bool(j.get("extensions", {}).get("KHR_lights_punctual", {}).get("lights"))
        view = file_camera(j) if has_cam else default_view(lo, hi, (W, H))
        if not has_cam:
            cam = view
        if not has_lights:
            lights = default_lights(lo, hi, view)
        setup = {"file": path, "out": os.path.join(OUT, "blender", name + ".png"), "width": W,
                 "height": H, "samples": args.samples, "camera": cam, "lights": lights,
                 "background": BG, "lambert": ext in ("obj", "ply")}
        if name == "control_flipped":
            setup["flip_v"] = True
        if ext == "ply":
            setup["texture"] = os.path.join(os.path.dirname(path), "uvgrid.png")
        sp = os.path.join(OUT, "setup", name + ".json")
        json.dump(setup, open(sp, "w"), indent=1)

        df = os.path.join(OUT, "sray", name + ".png")
        bf = os.path.join(OUT, "sray", name + "_bf.png")
        base = [args.sray, "render", path, "--width", str(W), "--height", str(H), "-q"]
        times = []
        for _ in range(args.repeats):
            p, dt = run(base + ["-o", df, "--mode", "df", "--threads", "1"])
            times.append(dt)
        warn = (p.stderr or "").strip()
        run(base + ["-o", bf, "--mode", "bf", "--memory", "64MiB"])
        same = subprocess.run(["cmp", df, bf], capture_output=True).returncode == 0
        btimes, bwall = [], []
        for _ in range(args.repeats):
            p, bw = run(env=BLENDER_ENV, cmd=[args.blender, "-b", "--factory-startup", "-t", "1", "--python-exit-code", "1", "--python",
                        os.path.join(HERE, "render_blender.py"), "--", sp])
            sec = [float(line.split()[1]) for line in p.stdout.splitlines() if line.startswith("RENDER_SECONDS")]
            btimes.append(sec[0])
            bwall.append(bw)
        blog = [line for line in p.stdout.splitlines() if line.startswith(("IMPORTED", "MASK", "LIGHT"))]
        a8 = np.asarray(Image.open(df).convert("RGB"))
        b8 = np.asarray(Image.open(setup["out"]).convert("RGB"))
        fig = figures(a8, b8)
        if ext in ("glb", "gltf"):
            # Diagnostic: Blender again with Principled BSDF -> Lambert.
            diag = dict(setup, principled_to_lambert=True,
                        out=os.path.join(OUT, "blender", name + "_lambert.png"))
            dp = os.path.join(OUT, "setup", name + "_lambert.json")
            json.dump(diag, open(dp, "w"), indent=1)
            run(env=BLENDER_ENV, cmd=[args.blender, "-b", "--factory-startup", "-t", "1",
                                      "--python-exit-code", "1", "--python",
                                      os.path.join(HERE, "render_blender.py"), "--", dp])
            l8 = np.asarray(Image.open(diag["out"]).convert("RGB"))
            lf = figures(a8, l8)
            fig["vs_blender_lambert"] = {k: lf[k] for k in ("structure_corr", "mad_linear", "mad_srgb", "mean_blender")}
        side_by_side(a8, b8, name, os.path.join(OUT, "side", name + ".png"))
        results[name] = {"file": os.path.relpath(path, HERE), "what": what, "df_equals_bf": same,
                         "sray_seconds_median": statistics.median(times),
                         "blender_render_seconds_median": statistics.median(btimes),
                         "blender_process_seconds_median": statistics.median(bwall),
                         "sray_seconds": times, "blender_render_seconds": btimes,
                         "sray_stderr": warn[-600:], "blender_log": blog, **fig,
                         "camera": "file" if has_cam else "sray default view",
                         "lights": "file" if has_lights else "sray default lights"}
        print(json.dumps(results[name], indent=1), flush=True)
        json.dump(results, open(res_path, "w"), indent=1)


def info_bounds(info):
    """The scene's bounds from `sray info --json` (bbox_min, bbox_max)."""
    return [float(x) for x in info["bbox_min"]], [float(x) for x in info["bbox_max"]]


if __name__ == "__main__":
    main()
