#!/usr/bin/env python
"""Generate a glb of N distinct dragon meshes (for the bounded-memory glTF benchmark).

Usage: make_many.py MESH.ply OUT.glb N
Mesh i is the dragon scaled into a unit box and stretched in y by 1 + i/(4N), so
that no two meshes are the same data; each is placed once, on a sqrt(N)-wide grid
(spacing 1.3). N = 1 gives the dragon alone as one mesh.
"""
import math
import sys

import numpy as np
import trimesh


def main():
    path, out, n = sys.argv[1], sys.argv[2], int(sys.argv[3])
    m = trimesh.load(path, process=False)
    v = np.asarray(m.vertices, dtype=np.float64)
    lo, hi = v.min(axis=0), v.max(axis=0)
    v = (v - lo) / float((hi - lo).max())
    faces = np.asarray(m.faces)
    side = max(1, int(math.ceil(math.sqrt(n))))
    scene = trimesh.Scene()
    for i in range(n):
        r, c = divmod(i, side)
        w = v.copy()
        w[:, 1] *= 1.0 + i / (4.0 * n)
        w[:, 0] += (c - (side - 1) / 2) * 1.3
        w[:, 2] += (r - (side - 1) / 2) * 1.3
        mesh = trimesh.Trimesh(vertices=w, faces=faces, process=False)
        scene.add_geometry(mesh, node_name=f"d{i}", geom_name=f"dragon{i}")
    scene.set_camera(angles=(-0.6, 0.0, 0.0), fov=(50, 50))
    scene.export(out)
    print(f"{out}: {n} meshes, {n * len(faces)} triangles")


if __name__ == "__main__":
    main()
