"""Issue 15's dense model in a sparse world, as NFF.

Reads an NFF mesh written by `sray convert MESH -o mesh.nff` (triangles as
`p 3`), scales it into a unit box standing at the origin, and writes it on a
200 x 200 floor polygon under two lights, with N spheres of radius 0.1 strewn
over the floor (a fixed seed; none within 1.5 of the model), the camera on
the model. N = 0 gives "the model alone" on the same floor.

    python3 scene.py dragon.nff dense_sparse.nff 20000
"""
import random
import sys


def triangles(path):
    lines = open(path).read().split("\n")
    i = 0
    while i < len(lines):
        if lines[i].startswith("p 3"):
            yield [tuple(map(float, lines[i + k].split())) for k in (1, 2, 3)]
            i += 4
        else:
            i += 1


def main(src, out, n):
    tris = list(triangles(src))
    lo = [min(v[a] for t in tris for v in t) for a in range(3)]
    hi = [max(v[a] for t in tris for v in t) for a in range(3)]
    s = 1.0 / max(hi[a] - lo[a] for a in range(3))
    c = [(lo[0] + hi[0]) / 2, lo[1], (lo[2] + hi[2]) / 2]
    r = random.Random(7)
    with open(out, "w") as f:
        f.write("v\nfrom 1.2 0.9 1.6\nat 0 0.35 0\nup 0 1 0\nangle 40\nhither 0.001\n")
        f.write("resolution 512 512\nb 0.1 0.11 0.14\n")
        f.write("l 3 8 4 0.9 0.9 0.9\nl -5 6 2 0.4 0.4 0.4\n")
        f.write("f 0.5 0.5 0.5 1 0 0 0 1\np 4\n")
        f.write("-100 0 -100\n-100 0 100\n100 0 100\n100 0 -100\n")
        f.write("f 0.8 0.3 0.2 0.7 0.3 20 0 1\n")
        k = 0
        while k < n:
            x, z = r.uniform(-100, 100), r.uniform(-100, 100)
            if abs(x) < 1.5 and abs(z) < 1.5:
                continue
            f.write("s %.4f 0.1 %.4f 0.1\n" % (x, z))
            k += 1
        f.write("f 0.8 0.8 0.8 1 0 0 0 1\n")
        for t in tris:
            f.write("p 3\n")
            for v in t:
                f.write("%.6g %.6g %.6g\n" % tuple((v[a] - c[a]) * s for a in range(3)))


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], int(sys.argv[3]))
