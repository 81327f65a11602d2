#!/usr/bin/env python3
"""Writes data/scenarios/beam_mirror.json: the project's scenario whose targets no certified map reaches.

1000 points drawn uniformly in the beam (x in [-1, 1], y and z in [-0.2, 0.2]; Python's random, seed 1, six
decimals) are handles pulled to their mirror image across the plane y = 0. A reflection reverses orientation;
with 1000 handles pinning the subspace (s = 300 reduced coefficients per coordinate at the defaults; the handle
matrix's condition number ~1e4), `lidef deform` proves before solving that every map of the subspace within the handle tolerance
has det J < 0 somewhere in the certified domain (docs/certificate.md, "Targets no certified map reaches"), so
a correct run ends blocked_by_certificate with the last certified map written. Usage:
    python3 scripts/make_mirror_scenario.py > data/scenarios/beam_mirror.json
"""
import json
import random


def main():
    # A regular lattice does not do: its points leave directions of the subspace unseen (measured: the
    # handle matrix of a 21 x 5 x 5 lattice is singular at s = 300); random points see them all.
    rng = random.Random(1)
    handles = []
    for _ in range(1000):
        x = round(rng.uniform(-1.0, 1.0), 6)
        y = round(rng.uniform(-0.2, 0.2), 6)
        z = round(rng.uniform(-0.2, 0.2), 6)
        handles.append(([x, y, z], [x, -y, z]))
    description = (
        "1000 points drawn uniformly in the beam pulled to their mirror image across the plane y = 0: a "
        "reflection, which reverses orientation. With 1000 handles "
        "pinning the subspace, lidef deform proves before solving that every map of the subspace within the "
        "handle tolerance folds (det J < 0 at a voxel center); a correct run tries only a direct solve and "
        "ends blocked_by_certificate with the last certified map written, summary.json's unreachable.proven "
        "true (scripts/make_mirror_scenario.py writes this file)")
    lines = ['{', '  "name": "beam_mirror",', '  "model": "beam",',
             '  "description": ' + json.dumps(description) + ',', '  "handles": [']
    rows = ['    {"source": %s, "target": %s}' % (json.dumps(s), json.dumps(t)) for s, t in handles]
    lines.append(',\n'.join(rows))
    lines += ['  ]', '}']
    print('\n'.join(lines))


if __name__ == '__main__':
    main()
