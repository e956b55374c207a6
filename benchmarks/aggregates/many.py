"""Many dense models in a sparse world, as NFF: COPIES copies of a mesh
(an NFF of `p 3` triangles, as `sray convert MESH -o mesh.nff` writes),
each scaled into a unit box, standing at random places on a 200 x 200
floor strewn with SPHERES spheres of radius 0.1, the camera above them
all. A density summary finds at most two dense regions, so most copies
crowd a few voxels of the floor's grid.

    python3 many.py bunny.nff many.nff 16 20000
"""
import os
import random
import sys

# The NFF triangle reader of the dense-in-sparse scene.
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "dense_in_sparse"))
from scene import triangles  # noqa: E402


def main(src, out, copies, spheres):
    tris = list(triangles(src))
    lo = [min(v[a] for t in tris for v in t) for a in range(3)]
    hi = [max(v[a] for t in tris for v in t) for a in range(3)]
    s = 1.0 / max(hi[a] - lo[a] for a in range(3))
    c = [(lo[0] + hi[0]) / 2, lo[1], (lo[2] + hi[2]) / 2]
    r = random.Random(11)
    places = []
    while len(places) < copies:
        x, z = r.uniform(-12, 12), r.uniform(-12, 12)
        if all(abs(x - a) > 2 or abs(z - b) > 2 for a, b in places):
            places.append((x, z))
    with open(out, "w") as f:
        f.write("v\nfrom 0 14 22\nat 0 0 0\nup 0 1 0\nangle 60\nhither 0.001\n")
        f.write("resolution 512 512\nb 0.1 0.11 0.14\n")
        f.write("l 3 30 4 0.9 0.9 0.9\nl -20 20 10 0.4 0.4 0.4\n")
        f.write("f 0.5 0.5 0.5 1 0 0 0 1\np 4\n")
        f.write("-100 0 -100\n-100 0 100\n100 0 100\n100 0 -100\n")
        f.write("f 0.8 0.3 0.2 0.7 0.3 20 0 1\n")
        k = 0
        while k < spheres:
            x, z = r.uniform(-100, 100), r.uniform(-100, 100)
            if any(abs(x - a) < 1.5 and abs(z - b) < 1.5 for a, b in places):
                continue
            f.write("s %.4f 0.1 %.4f 0.1\n" % (x, z))
            k += 1
        f.write("f 0.8 0.8 0.8 1 0 0 0 1\n")
        for (px, pz) in places:
            for t in tris:
                f.write("p 3\n")
                for v in t:
                    p = [(v[a] - c[a]) * s for a in range(3)]
                    f.write("%.6g %.6g %.6g\n" % (p[0] + px, p[1], p[2] + pz))


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4]))
