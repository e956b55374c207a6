#!/usr/bin/env python
"""Generate instanced-dragon glb scenes for the sray benchmark.

Usage: make_dragons.py MESH.ply OUT.glb N [ANGLE_X]
One dragon mesh, referenced by N nodes on a sqrt(N) x sqrt(N) grid (spacing 1.3),
each rotated about y by i*137.5 deg and scaled by 0.8 + 0.4*((i*7919) % 100)/100.
"""
import math
import sys

import numpy as np
import trimesh
from trimesh import transformations as tf


def load_dragon(path):
    m = trimesh.load(path, process=False)
    print(f"loaded {path}: {len(m.faces)} triangles, {len(m.vertices)} vertices")
    v = np.asarray(m.vertices, dtype=np.float64)
    lo, hi = v.min(axis=0), v.max(axis=0)
    s = 1.0 / float((hi - lo).max())
    # scale so the largest bbox side is 1, then min y = 0, centred in x and z
    v = (v - lo) * s
    size = (hi - lo) * s
    v[:, 0] -= size[0] / 2
    v[:, 2] -= size[2] / 2
    m.vertices = v
    b = m.bounds
    print("normalised bounds:", b.tolist())
    return m


def placements(n):
    side = int(round(math.sqrt(n)))
    assert side * side == n
    out = []
    for i in range(n):
        r, c = divmod(i, side)
        x = (c - (side - 1) / 2) * 1.3
        z = (r - (side - 1) / 2) * 1.3
        ang = math.radians((i * 137.5) % 360.0)
        sc = 0.8 + 0.4 * ((i * 7919) % 100) / 100
        T = tf.translation_matrix([x, 0.0, z]) @ tf.rotation_matrix(ang, [0, 1, 0]) @ np.diag([sc, sc, sc, 1.0])
        out.append(T)
    return side, out


def main():
    mesh_path, out, n = sys.argv[1], sys.argv[2], int(sys.argv[3])
    ax = float(sys.argv[4]) if len(sys.argv) > 4 else -0.6
    mesh = load_dragon(mesh_path)
    side, Ts = placements(n)
    s = trimesh.Scene()
    s.add_geometry(mesh, node_name="d0", geom_name="dragon", transform=Ts[0])
    for i in range(1, n):
        s.graph.update(frame_from=s.graph.base_frame, frame_to=f"d{i}", matrix=Ts[i], geometry="dragon")
    half = (side - 1) / 2 * 1.3 + 0.7
    C = np.array([0.0, 0.4, 0.0])
    D = 1.4 * half / math.tan(math.radians(25)) + 0.5
    cam = s.set_camera(angles=(ax, 0.0, 0), distance=D, center=C, fov=(50, 50))
    print("nodes:", len(s.graph.nodes_geometry), "geometries:", len(s.geometry))
    print("camera distance", D, "center", C.tolist())
    print("camera transform:\n", np.round(s.camera_transform, 4))
    data = s.export(file_type="glb")
    with open(out, "wb") as f:
        f.write(data)
    print(f"wrote {out}: {len(data)} bytes")


if __name__ == "__main__":
    main()
