#!/bin/bash
# Sourced by the bench/*_side_by_side.sh scripts: two lidef binaries alternated in one run, so that both see
# the same machine state (docs/benchmarks.md: only numbers from one run compare).
# Sets OLD and NEW from the script's two arguments and SHARED, OUT, ROUNDS from the environment (defaults
# below); alternate KEY RUN [AFTER_ROUND] calls, for each round, RUN BINARY DIR WHICH ROUND with OLD (WHICH =
# old) and then NEW (new), DIR = $OUT/KEY-WHICH-ROUND emptied first, then AFTER_ROUND ROUND if given.
if [ $# -ne 2 ]; then
  echo "usage: bash $0 OLD_BINARY NEW_BINARY (from the repository root; SHARED, OUT, ROUNDS in the environment)" >&2
  exit 2
fi
OLD=$1
NEW=$2
SHARED=${SHARED:-../shared/data}
OUT=${OUT:-/tmp/$(basename "$0" .sh)}
ROUNDS=${ROUNDS:-2}
mkdir -p "$OUT"
alternate() {
  local key=$1 run=$2 after=${3:-} round which bin dir
  for round in $(seq 1 "$ROUNDS"); do
    for which in old new; do
      bin=$OLD
      [ "$which" = new ] && bin=$NEW
      dir=$OUT/$key-$which-$round
      rm -rf "$dir"
      "$run" "$bin" "$dir" "$which" "$round"
    done
    [ -n "$after" ] && "$after" "$round"
  done
  return 0
}
