#!/usr/bin/env python3
"""Point-cloud, splat and soup inputs made from a triangle mesh (an ASCII OFF, e.g. CGAL's demo meshes from
/usr/share/doc/libcgal-dev/data.tar.gz). Standard library only; seeded, so the same arguments give the same files.

  make_point_inputs.py MESH.off OUTDIR [--points N] [--splats N]

Writes OUTDIR/points.ply (binary little endian, x y z nx ny nz red green blue), points_ascii.ply, points.xyz,
points.obj (vertices only), splats.ply (the 3D Gaussian Splatting layout: random log scales, random unit
quaternions, random f_dc/f_rest/opacity, and an extra property 'tag'), holes.obj (the mesh with every 7th face
removed), crossing.obj (the mesh and a shifted, rotated copy through it).
"""
import argparse, math, os, random, struct


def read_off(path):
    toks = []
    for line in open(path):
        line = line.split('#')[0]
        toks += line.split()
    assert toks[0].endswith('OFF'), path
    nv, nf = int(toks[1]), int(toks[2])
    p = 4
    V = []
    for _ in range(nv):
        V.append(tuple(float(t) for t in toks[p:p + 3]))
        p += 3
    F = []
    for _ in range(nf):
        k = int(toks[p])
        idx = [int(t) for t in toks[p + 1:p + 1 + k]]
        p += 1 + k
        for c in range(1, k - 1):
            F.append((idx[0], idx[c], idx[c + 1]))
    return V, F


def sub(a, b): return (a[0] - b[0], a[1] - b[1], a[2] - b[2])
def cross(a, b): return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])
def norm(a): return math.sqrt(a[0] ** 2 + a[1] ** 2 + a[2] ** 2)


def sample(V, F, n, rng):
    areas = [norm(cross(sub(V[b], V[a]), sub(V[c], V[a]))) for a, b, c in F]
    cum, s = [], 0.0
    for x in areas:
        s += x
        cum.append(s)
    import bisect
    pts, nrm = [], []
    for _ in range(n):
        t = min(bisect.bisect_left(cum, rng.random() * s), len(F) - 1)
        a, b, c = (V[i] for i in F[t])
        u, v = rng.random(), rng.random()
        if u + v > 1: u, v = 1 - u, 1 - v
        pts.append(tuple(a[k] + u * (b[k] - a[k]) + v * (c[k] - a[k]) for k in range(3)))
        nn = cross(sub(b, a), sub(c, a))
        L = norm(nn) or 1.0
        nrm.append(tuple(x / L for x in nn))
    return pts, nrm


def write_obj(path, V, F):
    with open(path, 'w') as f:
        for v in V: f.write('v %.17g %.17g %.17g\n' % v)
        for t in F: f.write('f %d %d %d\n' % (t[0] + 1, t[1] + 1, t[2] + 1))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('mesh'); ap.add_argument('out')
    ap.add_argument('--points', type=int, default=5000); ap.add_argument('--splats', type=int, default=5000)
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    rng = random.Random(1)
    V, F = read_off(a.mesh)
    P, N = sample(V, F, a.points, rng)
    head = ('ply\nformat %s 1.0\nelement vertex %d\nproperty float x\nproperty float y\nproperty float z\n'
            'property float nx\nproperty float ny\nproperty float nz\nproperty uchar red\nproperty uchar green\n'
            'property uchar blue\nend_header\n')
    with open(os.path.join(a.out, 'points.ply'), 'wb') as f:
        f.write((head % ('binary_little_endian', len(P))).encode())
        for p, n in zip(P, N): f.write(struct.pack('<ffffffBBB', *p, *n, 200, 100, 50))
    with open(os.path.join(a.out, 'points_ascii.ply'), 'w') as f:
        f.write(head % ('ascii', len(P)))
        for p, n in zip(P, N): f.write('%r %r %r %r %r %r 200 100 50\n' % (*p, *n))
    with open(os.path.join(a.out, 'points.xyz'), 'w') as f:
        for p in P: f.write('%.17g %.17g %.17g\n' % p)
    write_obj(os.path.join(a.out, 'points.obj'), P, [])
    # Splats: centers on the surface, log scales around 1/200 of the bounding box, random rotations.
    lo = [min(v[k] for v in V) for k in range(3)]; hi = [max(v[k] for v in V) for k in range(3)]
    diag = norm(sub(hi, lo))
    S, _ = sample(V, F, a.splats, rng)
    names = (['x', 'y', 'z', 'nx', 'ny', 'nz'] + ['f_dc_%d' % k for k in range(3)] +
             ['f_rest_%d' % k for k in range(45)] + ['opacity'] + ['scale_%d' % k for k in range(3)] +
             ['rot_%d' % k for k in range(4)])
    with open(os.path.join(a.out, 'splats.ply'), 'wb') as f:
        f.write(('ply\nformat binary_little_endian 1.0\nelement vertex %d\n' % len(S)).encode())
        for n in names: f.write(('property float %s\n' % n).encode())
        f.write(b'property int tag\nend_header\n')
        for i, s in enumerate(S):
            q = [rng.gauss(0, 1) for _ in range(4)]
            vals = list(s) + [0, 0, 0] + [rng.uniform(-1, 1) for _ in range(48)] + [rng.uniform(-2, 2)]
            vals += [math.log(diag / 200 * rng.uniform(0.2, 2)) for _ in range(3)] + q
            f.write(struct.pack('<%dfi' % len(vals), *vals, i))
    write_obj(os.path.join(a.out, 'holes.obj'), V, [t for i, t in enumerate(F) if i % 7 != 3])
    c, sn = math.cos(0.6), math.sin(0.6)
    shift = [0.3 * (hi[k] - lo[k]) for k in range(3)]
    V2 = [(c * v[0] - sn * v[1] + shift[0], sn * v[0] + c * v[1] + shift[1], v[2] + shift[2]) for v in V]
    write_obj(os.path.join(a.out, 'crossing.obj'), V + V2, F + [tuple(i + len(V) for i in t) for t in F])


if __name__ == '__main__':
    main()
