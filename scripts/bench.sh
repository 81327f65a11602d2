#!/usr/bin/env bash
# Runs every benchmark program of a build. Usage: bench.sh BUILD_DIR [extra arguments for every program]
# Each program in BUILD_DIR/bench/ named bench_* and executable is run with the shared data folder as its first
# argument: $LIDEF_SHARED_DATA if set, else ../shared/data beside the checkout. Results are printed (markdown);
# docs/benchmarks.md records measured numbers with the command that produced them.
# bench_deform (the solver on every scenario, ~10 min) takes the same DATA_DIR; run it alone with e.g.
# BUILD_DIR/bench/bench_deform DATA_DIR --only bar_bend,animal_tail_lift.
set -euo pipefail
if [ $# -lt 1 ]; then
  echo "usage: $0 BUILD_DIR [args...]" >&2
  exit 2
fi
BUILD=$1
shift
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
DATA=${LIDEF_SHARED_DATA:-$ROOT/../shared/data}
[ -d "$DATA" ] && DATA=$(cd "$DATA" && pwd)
if [ ! -d "$DATA" ]; then
  echo "bench.sh: shared data folder not found: $DATA (set LIDEF_SHARED_DATA)" >&2
  exit 2
fi
if [ ! -d "$BUILD/bench" ]; then
  echo "bench.sh: no benchmark programs: $BUILD/bench does not exist (configure with -DLIDEF_BUILD_BENCH=ON)" >&2
  exit 2
fi
echo "# lidef benchmarks ($(date -u +%Y-%m-%dT%H:%M:%SZ))"
echo
echo "- machine: $(lscpu 2>/dev/null | sed -n 's/^Model name: *//p' | head -1), $(nproc) logical CPUs"
echo "- data: $DATA"
echo
found=0
status=0
for prog in "$BUILD"/bench/bench_*; do
  [ -f "$prog" ] && [ -x "$prog" ] || continue
  found=1
  echo "## $(basename "$prog")"
  echo
  if ! "$prog" "$DATA" "$@"; then
    echo "bench.sh: $(basename "$prog") failed" >&2
    status=1
  fi
  echo
done
if [ "$found" = 0 ]; then
  echo "bench.sh: no bench_* programs in $BUILD/bench" >&2
  exit 2
fi
exit $status
