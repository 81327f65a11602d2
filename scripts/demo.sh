#!/usr/bin/env bash
# The main job on the project's own default model (see README). Usage: demo.sh LIDEF_BINARY OUT_DIR
set -euo pipefail
LIDEF=$1
OUT=$2
"$LIDEF" check data/models/bar
