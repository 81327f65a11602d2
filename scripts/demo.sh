#!/usr/bin/env bash
# The main job on the project's own default model (see README). Usage: demo.sh LIDEF_BINARY OUT_DIR
# Until the deformation solver exists (issue: solver), the demo validates the default model, evaluates the
# identity map at the mesh vertices, and certifies it.
set -euo pipefail
LIDEF=$1
OUT=$2
MODEL=data/models/beam
mkdir -p "$OUT"
echo "== lidef check $MODEL"
"$LIDEF" check "$MODEL"
echo
echo "== lidef eval (identity map at the mesh vertices)"
awk '$1 == "v" { print $2, $3, $4 }' "$MODEL/mesh.obj" > "$OUT/mesh_vertices.xyz"
"$LIDEF" eval "$MODEL" --coeffs identity --points "$OUT/mesh_vertices.xyz" --out "$OUT/identity_eval.csv"
echo
echo "== lidef certify (identity map)"
rc=0
"$LIDEF" certify "$MODEL" --coeffs identity --out "$OUT/certificate" || rc=$?
if [ "$rc" -ne 0 ]; then
  echo "demo: the identity map was not certified (exit $rc) — this is a bug" >&2
  exit 1
fi
echo
echo "Results are in $OUT/:"
echo "  identity_eval.csv          f, J, signed singular values at the mesh vertices"
echo "  certificate/certificate.json, voxels.csv   the certificate (see docs/certificate-outputs.md)"
echo "  certificate/leaves.vtu, field.vti          open in ParaView: paraview $OUT/certificate/leaves.vtu"
echo "     (colour leaves by 'margin' or 'depth'; Slice the .vti and colour by 'sigma3')"
