#!/usr/bin/env bash
# `make check-sanitize` after the build: runs the unit label of an ASan + UBSan build and fails on any report.
# Usage: check-sanitize.sh BUILD_DIR [JOBS]
#
# Every sanitizer report goes to a log file (log_path), including those of the lidef/lidef-compare processes the
# CLI tests start: a test that expects a failing exit status would otherwise pass on a sanitizer's abort. So
# the run fails when ctest fails OR when any log file exists.
set -euo pipefail
BUILD=$(cd "$1" && pwd)
JOBS=${2:-2}
LOGS=$BUILD/sanitizer-logs
rm -rf "$LOGS"
mkdir -p "$LOGS"
export ASAN_OPTIONS="log_path=$LOGS/asan:detect_leaks=1:strict_string_checks=1:detect_stack_use_after_return=1:check_initialization_order=1"
export UBSAN_OPTIONS="log_path=$LOGS/ubsan:print_stacktrace=1:halt_on_error=1"
# Tests left out under ASan (docs/dev.md, "Sanitizers and fuzzing"): the slow label, as in CI, and
# $SANITIZE_EXCLUDE (a ctest -E regex) when set.
# $SANITIZE_SELECT (a ctest -R regex) runs only those tests.
# $SANITIZE_LABEL (a ctest -L regex) runs that label instead of everything but slow (`make check-sanitize-ci`:
# sanitize, the sanitized subset of the unit tests).
EXCLUDE=${SANITIZE_EXCLUDE:-}
SELECT=${SANITIZE_SELECT:-}
if [ -n "${SANITIZE_LABEL:-}" ]; then
  args=(-L "$SANITIZE_LABEL" -j "$JOBS" --timeout 1500 --output-on-failure)
else
  args=(-LE slow -j "$JOBS" --timeout 1500 --output-on-failure)
fi
if [ -n "$EXCLUDE" ]; then args+=(-E "$EXCLUDE"); fi
if [ -n "$SELECT" ]; then args+=(-R "$SELECT"); fi
rc=0
start=$(date +%s)
(cd "$BUILD" && ctest "${args[@]}") || rc=$?
echo "check-sanitize: ctest took $(($(date +%s) - start)) s"
shopt -s nullglob
reports=("$LOGS"/*)
if [ ${#reports[@]} -gt 0 ]; then
  echo "check-sanitize: ${#reports[@]} sanitizer report(s):" >&2
  for f in "${reports[@]}"; do
    echo "==== $f" >&2
    head -n 60 "$f" >&2
  done
  rc=1
fi
if [ "$rc" -ne 0 ]; then
  echo "check-sanitize: FAILED" >&2
  exit 1
fi
echo "check-sanitize: no sanitizer report, all tests passed"
