#!/usr/bin/env bash
# The main job on the project's own default model (see README): deform data/models/beam with the handle
# scenario data/scenarios/beam_bend.json; every accepted Newton step is certified locally injective.
# Usage: demo.sh LIDEF_BINARY OUT_DIR
set -euo pipefail
LIDEF=$1
OUT=$2
SCENARIO=data/scenarios/beam_bend.json
echo "== lidef check data/models/beam"
"$LIDEF" check data/models/beam
echo
echo "== lidef deform $SCENARIO --out $OUT"
rc=0
"$LIDEF" deform "$SCENARIO" --out "$OUT" || rc=$?
if [ "$rc" -eq 2 ]; then
  echo "demo: lidef deform failed (exit 2)" >&2
  exit 1
fi
# The main job must end with a certified map (CI runs this demo after the test suite).
if ! grep -q '"certified": true' "$OUT/summary.json"; then
  echo "demo: the written map is not certified ($OUT/summary.json)" >&2
  exit 1
fi
echo
echo "Results are in $OUT/ (docs/solver.md describes every file):"
echo "  summary.json       stop reason, iterations, handle error, global volume ratio, certified"
echo "  iterations.csv     energy, weights, step, min sigma3 lower bound and stage times per Newton iteration"
echo "  coefficients.txt   the certified map (lidef eval / lidef certify / lidef verify read it)"
echo "  certificate.json, voxels.csv   its local-injectivity certificate (docs/outputs.md)"
echo "Open in ParaView:"
echo "  paraview $OUT/deformed.vtp    colour by E_iso_minus_6 (distortion), detJ (volume ratio) or sigma3"
echo "  paraview $OUT/leaves.vtu      the certification octree: Threshold depth >= 1 shows the refined voxels"
echo "Check the certificate independently by dense sampling:"
echo "  $LIDEF verify data/models/beam --coeffs $OUT/coefficients.txt --certificate $OUT/certificate.json --out $OUT/verify"
STUDIO="$(dirname "$LIDEF")/../gui/lidef-studio"
if [ -x "$STUDIO" ]; then
  echo "Drag the handles yourself (docs/studio.md):"
  echo "  $(realpath --relative-to=. "$STUDIO") data/scenarios/beam_bend.json"
fi
