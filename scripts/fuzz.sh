#!/usr/bin/env bash
# `make fuzz` after the build: runs every libFuzzer target of fuzz/ for SECONDS each, JOBS at a time, and fails
# on any finding (crash, sanitizer report, uncaught exception other than lidef::InputError, an input taking
# longer than 10 s, a leak, more than 2 GB of memory).
# Usage: fuzz.sh BUILD_DIR SECONDS [JOBS]
#
# Each target starts from its committed seeds (fuzz/corpus/<target>/) and kept findings
# (fuzz/regressions/<target>/); new inputs go to BUILD_DIR/fuzz-work/<target>/, never into the source tree.
# A finding is written to BUILD_DIR/fuzz-artifacts/<target>-crash-... : fix it, then commit the file as
# fuzz/regressions/<target>/<name> so that Fuzz.Replay.<target> (make test) replays it from then on.
set -euo pipefail
BUILD=$(cd "$1" && pwd)
SECONDS_EACH=$2
JOBS=${3:-2}
SRC=$(cd "$(dirname "$0")/.." && pwd)
ART=$BUILD/fuzz-artifacts
mkdir -p "$ART"
targets=()
for f in "$BUILD"/fuzz/lidef_fuzz_*; do
  [ -x "$f" ] && targets+=("$(basename "$f" | sed 's/^lidef_fuzz_//')")
done
if [ ${#targets[@]} -eq 0 ]; then
  echo "fuzz: no fuzz targets in $BUILD/fuzz" >&2
  exit 1
fi
run_one() {
  local t=$1
  local work=$BUILD/fuzz-work/$t
  mkdir -p "$work"
  local dirs=("$work" "$SRC/fuzz/corpus/$t")
  # The published cages (../shared/data, read there, never copied into the repo) seed the OBJ reader too.
  local shared=${LIDEF_SHARED_DATA:-$SRC/../shared/data}
  if [ "$t" = mesh_obj ] && [ -d "$shared/models" ]; then
    for m in "$shared"/models/*/cage.obj; do cp "$m" "$work/$(basename "$(dirname "$m")")_cage.obj"; done
  fi
  [ -d "$SRC/fuzz/regressions/$t" ] && dirs+=("$SRC/fuzz/regressions/$t")
  local log=$BUILD/fuzz-work/$t.log
  # FUZZ_SEED (CI: 1) fixes libFuzzer's random choices; with a time budget the number of runs still varies.
  if "$BUILD/fuzz/lidef_fuzz_$t" -max_total_time="$SECONDS_EACH" -timeout=10 -rss_limit_mb=2048 -max_len=65536 \
      -seed="${FUZZ_SEED:-0}" -print_final_stats=1 -artifact_prefix="$ART/$t-" "${dirs[@]}" > "$log" 2>&1; then
    echo "fuzz: $t: $(grep -o 'stat::number_of_executed_units: *[0-9]*' "$log" | grep -o '[0-9]*$') runs, no finding"
  else
    echo "fuzz: $t: FINDING (log $log, artifacts $ART/$t-*)"
    tail -n 40 "$log"
    # The input itself, so that a finding in CI can be reproduced from the log alone.
    for a in "$ART/$t"-*; do [ -f "$a" ] && echo "fuzz: $a (base64):" && base64 -w 0 "$a" | head -c 8192 && echo; done
    return 1
  fi
}
export -f run_one
export BUILD SRC ART SECONDS_EACH FUZZ_SEED
echo "fuzz: ${#targets[@]} targets, ${SECONDS_EACH} s each, $JOBS at a time"
if printf '%s\n' "${targets[@]}" | xargs -P "$JOBS" -I{} bash -c 'run_one {}'; then
  echo "fuzz: no finding"
else
  echo "fuzz: FAILED (see the findings above; keep each as fuzz/regressions/<target>/ once fixed)" >&2
  exit 1
fi
