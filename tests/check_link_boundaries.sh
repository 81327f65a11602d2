#!/usr/bin/env bash
# The architecture's link boundaries (docs/architecture.md): lidef and lidef-studio must not need TetGen or
# CHOLMOD; lidef-compare must (so that this check can tell the difference). Reads the DT_NEEDED entries.
# Usage: check_link_boundaries.sh LIDEF_COMPARE BINARY_WITHOUT [BINARY_WITHOUT ...]
set -euo pipefail
needed() { readelf -d "$1" | sed -n 's/.*(NEEDED).*\[\(.*\)\]/\1/p'; }
heavy='^lib(tet|cholmod)\.so'
compare=$1
shift
if ! needed "$compare" | grep -Eq "$heavy"; then
  echo "FAIL: $compare needs neither libtet nor libcholmod (expected both: the check would be blind)"
  exit 1
fi
status=0
for bin in "$@"; do
  if hits=$(needed "$bin" | grep -E "$heavy"); then
    echo "FAIL: $bin needs $(echo $hits)"
    status=1
  else
    echo "ok: $bin needs no TetGen/CHOLMOD"
  fi
done
exit $status
