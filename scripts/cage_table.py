#!/usr/bin/env python3
"""The measurements of docs/cages.md: `lidef cage` on libcgal-demo meshes, then a pull with `lidef deform`.

usage: scripts/cage_table.py LIDEF_BINARY MESH_DIR WORK_DIR [MESH ...]
MESH_DIR: data/meshes of /usr/share/doc/libcgal-dev/data.tar.gz (tar xzf ... data/meshes).
Pull: the mesh vertex of largest x moves by +5 % of the bounding-box diagonal in x, the vertex of smallest x stays;
lidef deform --samples 4000 --reduced-dof 60. Prints one line per mesh.
"""
import json
import os
import subprocess
import sys
import time

lidef, mesh_dir, work = sys.argv[1:4]
meshes = sys.argv[4:] or ["hand.off", "elephant.off", "elephant-with-holes.off", "cow.off", "pig.stl",
                          "armadillo.off", "bunny00.off", "refined_elephant.off"]
os.makedirs(work, exist_ok=True)
for m in meshes:
    out = os.path.join(work, m.split(".")[0])
    subprocess.run(["rm", "-rf", out, out + "_def", out + "_cache"], check=True)
    t = time.time()
    r = subprocess.run([lidef, "cage", os.path.join(mesh_dir, m), "--out", out, "--quiet"], capture_output=True,
                       text=True)
    wall = time.time() - t
    if r.returncode != 0:
        print(m, "FAILED", r.stderr[-500:])
        continue
    j = json.load(open(out + "/model.json"))
    a, s = j["attempts"][-1], j["seconds"]["attempts"][-1]
    V = [list(map(float, l.split()[1:4])) for l in open(out + "/mesh.obj") if l.startswith("v ")]
    hi, lo, d = max(V, key=lambda v: v[0]), min(V, key=lambda v: v[0]), j["diagonal"]
    scenario = {"name": "pull", "model": os.path.abspath(out),
                "handles": [{"source": hi, "target": [hi[0] + 0.05 * d, hi[1], hi[2]]}, {"source": lo, "target": lo}]}
    json.dump(scenario, open(out + "_pull.json", "w"))
    r2 = subprocess.run([lidef, "deform", out + "_pull.json", "--out", out + "_def", "--quiet", "--cache-dir",
                         out + "_cache", "--samples", "4000", "--reduced-dof", "60"], capture_output=True, text=True)
    try:
        su = json.load(open(out + "_def/summary.json"))
        pull = "certified=%s handles_reached=%s %s after %d iterations, coverage %.3f" % (
            su["certified"], su["handles_reached"], su["stop_reason"], su["iterations"], su["mesh_coverage"])
    except (OSError, KeyError, ValueError):
        pull = "deform failed: " + r2.stderr[-300:]
    print("%s: mesh %d/%d, wrap %d, cage %d/%d, clearance %.4f (faces not proven clear %d), retries %d, "
          "wrap/simplify/check %.2f/%.2f/%.2f s, total %.2f s (wall %.2f s); pull: %s" % (
              m, j["mesh"]["vertices"], j["mesh"]["triangles"], a["wrap_faces"], j["cage"]["vertices"],
              j["cage"]["triangles"], j["min_distance_mesh_to_cage"] / d, a["faces_within_clearance"], j["retries"],
              s["wrap"], s["simplify"], s["check"], j["seconds"]["total"], wall, pull), flush=True)
