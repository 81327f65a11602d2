"""The sigma3 explorer (docs/explorer.md): random harmonic polynomial maps on the unit ball, how often sigma3
has a strict interior minimum, and the candidates for the paper's Fig. 2 situation.

    PYTHONPATH=build/python python3 examples/python/sigma3_explorer.py --trials 40 --out out/minima.png
"""
import argparse

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import lidef

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--trials", type=int, default=200)
parser.add_argument("--family", default="twist", choices=["random", "twist"])
parser.add_argument("--out", required=True, help="PNG file to write")
args = parser.parse_args()

trials = lidef.search_sigma3_minima(family=args.family, degree=4, trials=args.trials, seed=1)
with_minimum = [t for t in trials if t["strict_minima"] > 0]
candidates = [t for t in trials if t["candidate"]]
print("%d maps: %d with a strict interior minimum of sigma3, %d candidates"
      % (len(trials), len(with_minimum), len(candidates)))

minima = np.concatenate([t["minima"] for t in trials if len(t["minima"])] or [np.zeros((0, 4))])
fig, ax = plt.subplots(figsize=(5, 4))
ax.scatter(np.linalg.norm(minima[:, :3], axis=1), minima[:, 3], s=8)
ax.set_xlabel("distance of the minimum from the ball's center")
ax.set_ylabel("sigma3 at the minimum")
ax.set_title("%s family, %d maps" % (args.family, len(trials)))
fig.tight_layout()
fig.savefig(args.out, dpi=80)
print("wrote", args.out)
