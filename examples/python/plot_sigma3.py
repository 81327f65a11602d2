"""Look at sigma3, the smallest singular value of the map's Jacobian (negative where it folds), after a
deformation: at the mesh's vertices from the map, and per certificate leaf with the leaf's proven lower bound.

    PYTHONPATH=build/python python3 examples/python/plot_sigma3.py --out out/sigma3.png
"""
import argparse

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import lidef

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--out", required=True, help="PNG file to write")
args = parser.parse_args()

model = lidef.load_model("data/models/beam")
scenario = lidef.read_scenario("data/scenarios/beam_bend.json")
result = lidef.deform(model, scenario.sources, scenario.targets, reduced_dof=60, samples=4000)

# sigma3 at the mesh's vertices: the smallest singular value, signed like det J.
_, J = model.evaluate(result.coefficients, model.mesh_vertices)
sigma3 = np.linalg.svd(J, compute_uv=False)[:, 2] * np.sign(np.linalg.det(J))

leaves = result.certificate.leaves
fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(11, 4))
V = result.deformed_vertices
sc = ax0.scatter(V[:, 0], V[:, 1], c=sigma3, s=2, cmap="viridis")
fig.colorbar(sc, ax=ax0, label="sigma3 at the mesh vertices")
ax0.set_aspect("equal")
ax0.set_title("deformed beam (x, y)")
ax1.hist(leaves["sigma3"], bins=50, alpha=0.6, label="sigma3 at leaf centers")
ax1.hist(leaves["lower_bound"], bins=50, alpha=0.6, label="proven lower bound per leaf")
ax1.axvline(0, color="k", lw=0.8)
ax1.set_xlabel("sigma3")
ax1.legend()
ax1.set_title("certificate: %d leaves, min lower bound %.3g" % (len(leaves["side"]), result.certificate.min_lower_bound))
fig.tight_layout()
fig.savefig(args.out, dpi=80)
print("min sigma3 at the mesh vertices %.4g, min proven lower bound %.4g; wrote %s"
      % (sigma3.min(), result.certificate.min_lower_bound, args.out))
