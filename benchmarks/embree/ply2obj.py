# Converts an ASCII PLY mesh (gzipped) to a Wavefront OBJ for Embree's viewer:
# python3 ply2obj.py dragon_vrip.ply.gz dragon.obj
import gzip, sys
src, dst = sys.argv[1], sys.argv[2]
with gzip.open(src, 'rt') as f, open(dst, 'w') as out:
    nv = nf = 0
    while True:
        line = f.readline().strip()
        if line.startswith('element vertex'): nv = int(line.split()[2])
        elif line.startswith('element face'): nf = int(line.split()[2])
        elif line == 'end_header': break
    mn = [1e30]*3; mx = [-1e30]*3
    for i in range(nv):
        p = f.readline().split()[:3]
        for k in range(3):
            v = float(p[k]); mn[k] = min(mn[k], v); mx[k] = max(mx[k], v)
        out.write('v %s %s %s\n' % tuple(p))
    tris = 0
    for i in range(nf):
        p = f.readline().split()
        n = int(p[0]); idx = [int(x) + 1 for x in p[1:1+n]]
        for j in range(1, n - 1):
            out.write('f %d %d %d\n' % (idx[0], idx[j], idx[j+1])); tris += 1
    print('vertices', nv, 'faces', nf, 'triangles', tris)
    print('bbox min', mn, 'max', mx)
