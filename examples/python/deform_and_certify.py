"""Load a model (a model folder or a bare mesh file), deform it to a scenario's handles, certify the result
again on its own and write the files `lidef deform` writes.

    PYTHONPATH=build/python python3 examples/python/deform_and_certify.py --out out/py-bend
"""
import argparse

import numpy as np

import lidef

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--model", default="data/models/beam", help="model folder or mesh file (.obj/.off/.ply/.stl)")
parser.add_argument("--scenario", default="data/scenarios/beam_bend.json")
parser.add_argument("--out", required=True, help="output folder")
args = parser.parse_args()

model = lidef.load_model(args.model)
scenario = lidef.read_scenario(args.scenario)
print(model)

# A coarse subspace and sampling keep this to seconds; leave them out for the paper's defaults.
params = dict(scenario.parameters, reduced_dof=60, samples=4000)
result = lidef.deform(model, scenario.sources, scenario.targets, **params)
print(result)

# Every accepted map of the solver is certified; a certificate of the result on its own agrees.
cert = lidef.certify(model, result.coefficients, samples=params["samples"])
print("certified:", cert.certified, " min lower bound of sigma3: %.4g" % cert.min_lower_bound)
assert cert.certified == result.certified

# det J > 0 at the mesh's vertices (the certificate says: everywhere on the mesh and its solid).
f, J = model.evaluate(result.coefficients, model.mesh_vertices)
print("smallest det J at the mesh vertices: %.4g" % np.linalg.det(J).min())

result.write(args.out)
print("wrote", args.out)
