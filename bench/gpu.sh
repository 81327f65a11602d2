#!/usr/bin/env bash
# The GPU measurements in one go, for a lent GPU host whose minutes should go to measuring, not to setting up:
# builds what the OpenCL measurements need (no studio, no Python), checks the device (it must list an OpenCL
# device with fp64, and the OpenCL parity tests must pass on it), then runs `lidef deform` on each scenario with both
# backends, bench_opencl (CPU vs OpenCL, whole solves, each stage alone, and the studio's drag on the engine alone)
# and bench_cholesky (the Newton system's factor on the host's cores), and prints one markdown
# table: iterations, solve time and mean ms per Newton iteration per backend, and whether both wrote the same
# verdicts. docs/benchmarks.md, "OpenCL backend", records what it printed, with the device.
#
# Usage: bench/gpu.sh DATA_DIR [OUT_DIR]
#   DATA_DIR   the shared data folder (models/ and scenarios/); on a device host copy it into the checkout first
#   OUT_DIR    where results go (default /tmp/lidef-gpu); the table is also written to OUT_DIR/gpu.md
# Environment: BUILD (build folder, default build-gpu; an existing build is reused), DEVICE (a substring of the
# OpenCL device's name, as --opencl-device), SCENARIOS (space-separated names, default the five easy shared
# scenarios and bar_twist180), REPS (timed repetitions of each stage alone, default 5), DRAG (seconds of the
# drag per backend, default 5; 0: none), DRAG_SCENARIOS (default animal_tail_lift bar_bend), CACHE (the subspace
# cache, default OUT_DIR/cache: two runs may share one), TESTS=0 (skip the OpenCL tests: a second run of other
# programs on a device the first run checked), QUICK=1 (one scenario and one repetition: a check of this script).
# The studio's window needs Qt, VTK and an X server and is not measured here (bench_studio); the drag on the
# engine alone is (bench_opencl --drag).
set -euo pipefail
if [ $# -lt 1 ]; then
  echo "usage: $0 DATA_DIR [OUT_DIR]" >&2
  exit 2
fi
DATA=$(cd "$1" && pwd)
OUT=${2:-/tmp/lidef-gpu}
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
BUILD=${BUILD:-$ROOT/build-gpu}
SCENARIOS=${SCENARIOS:-bar_bend bar_twist90 spot_head_turn horse_leg_lift animal_tail_lift bar_twist180}
REPS=${REPS:-5}
DRAG=${DRAG:-5}
DRAG_SCENARIOS=${DRAG_SCENARIOS:-animal_tail_lift bar_bend}
if [ "${QUICK:-0}" = 1 ]; then
  SCENARIOS=${SCENARIOS%% *}
  REPS=1
  DRAG_SCENARIOS=$SCENARIOS
fi
THREADS=$(nproc)
mkdir -p "$OUT"
CACHE=${CACHE:-$OUT/cache}
log() { echo "[gpu.sh $(date -u +%H:%M:%S)] $*" >&2; }

# --- Build (only what is measured). A folder with the three programs and no CMakeCache.txt is a bundle built
# elsewhere (bench/gpu-bundle.sh) and is used as it is: a lent host may lack the build's dependencies.
if [ -x "$BUILD/app/lidef" ] && [ ! -f "$BUILD/CMakeCache.txt" ]; then
  log "using the prebuilt programs in $BUILD"
elif [ ! -x "$BUILD/app/lidef" ] || [ ! -x "$BUILD/bench/bench_opencl" ]; then
  log "configuring $BUILD"
  generator=()
  command -v ninja > /dev/null && generator=(-G Ninja)
  cmake -S "$ROOT" -B "$BUILD" "${generator[@]}" -DCMAKE_BUILD_TYPE=Release -DLIDEF_BUILD_STUDIO=OFF \
    -DLIDEF_BUILD_PYTHON=OFF -DLIDEF_BUILD_TESTS=ON -DLIDEF_BUILD_BENCH=ON > "$OUT/configure.log"
fi
if [ -f "$BUILD/CMakeCache.txt" ]; then
  log "building"
  cmake --build "$BUILD" -j "$THREADS" --target lidef bench_opencl bench_cholesky lidef_opencl_tests > "$OUT/build.log"
fi

# --- The device: listed with fp64, and the backend's parity tests pass on it
"$BUILD/app/lidef" devices | tee "$OUT/devices.txt"
device_args=()
[ -n "${DEVICE:-}" ] && device_args=(--opencl-device "$DEVICE")
log "OpenCL parity tests"
if [ "${TESTS:-1}" = 0 ]; then
  log "skipped (TESTS=0)"
elif ! LIDEF_OPENCL_DEVICE=${DEVICE:-} LIDEF_SHARED_DATA=$DATA "$BUILD/tests/lidef_opencl_tests" \
  --gtest_brief=1 > "$OUT/opencl_tests.log" 2>&1; then
  tail -30 "$OUT/opencl_tests.log" >&2
  echo "gpu.sh: the OpenCL tests fail on this device; no measurement is made" >&2
  exit 1
fi

# --- lidef deform per scenario and backend: the user's command, its summary and iterations
mean_ms() {  # mean ms_total over iterations 2..N of iterations.csv (the first carries one-time uploads)
  awk -F, 'NR == 1 { for (i = 1; i <= NF; ++i) if ($i == "ms_total") c = i; next }
           NR > 2 { s += $c; n += 1 } END { if (n) printf "%.1f", s / n; else printf "n/a" }' "$1"
}
field() { sed -n "s/^  \"$2\": \([^,]*\),\{0,1\}$/\1/p" "$1" | head -1; }
table="$OUT/gpu.md"
{
  echo "| scenario | backend | iterations | solve s | ms / iteration (2..N) | certified | stop |"
  echo "|---|---|---:|---:|---:|---|---|"
} > "$table"
for s in $SCENARIOS; do
  for b in cpu opencl; do
    dir="$OUT/$s-$b"
    log "deform $s --backend $b"
    rc=0
    "$BUILD/app/lidef" deform "$DATA/scenarios/$s.json" --models "$DATA/models" --out "$dir" --backend "$b" \
      "${device_args[@]}" --threads "$THREADS" --cache-dir "$CACHE" --quiet > "$dir.log" 2>&1 || rc=$?
    if [ "$rc" -gt 1 ]; then
      echo "| $s | $b | failed (exit $rc, $dir.log) | | | | |" >> "$table"
      continue
    fi
    solve=$(sed -n 's/^ *"solve": \([0-9.e+-]*\).*/\1/p' "$dir/summary.json" | head -1)
    solve=$(awk -v s="$solve" 'BEGIN { printf "%.3f", s }')
    echo "| $s | $b | $(field "$dir/summary.json" iterations) | $solve | $(mean_ms "$dir/iterations.csv") |" \
      "$(field "$dir/summary.json" certified) | $(field "$dir/summary.json" stop_reason) |" >> "$table"
  done
  if cmp -s "$OUT/$s-cpu/certificate.json" "$OUT/$s-opencl/certificate.json"; then
    log "$s: the same certificate on both backends"
  else
    log "$s: the certificates differ (rounding of the two backends; compare the verdicts in the table)"
  fi
done
# --- After the user's command (a time limit cuts this part first): whole solves and each stage alone, CPU against OpenCL (bench_opencl's own tables)
log "bench_opencl"
only=$(echo $SCENARIOS | tr ' ' ',')
LIDEF_OPENCL_DEVICE=${DEVICE:-} "$BUILD/bench/bench_opencl" "$DATA" --only "$only" --reps "$REPS" \
  --threads "$THREADS" --cache-dir "$CACHE" --drag "$DRAG" --drag-only "$(echo $DRAG_SCENARIOS | tr ' ' ',')" \
  > "$OUT/bench_opencl.md"
log "bench_cholesky"
"$BUILD/bench/bench_cholesky" --threads "$THREADS" --reps "$((REPS * 4))" > "$OUT/bench_cholesky.md"

echo
echo "# lidef on $(sed -n 's/^--backend auto -> \([^;]*\).*/\1/p' "$OUT/devices.txt" | head -1) ($(date -u +%Y-%m-%dT%H:%M:%SZ), $THREADS CPU threads)"
echo
cat "$table"
echo
sed -n '/^### Dragging/,$p' "$OUT/bench_opencl.md"
cat "$OUT/bench_cholesky.md"
echo "bench_opencl: $OUT/bench_opencl.md"
