#!/bin/bash
# lidef vs VHM on every shared and project scenario: reached, certified, mean E_iso-6.
# Run from the repository root after `make build`: bash bench/compare_vhm_all.sh; each scenario's
# $OUT/<name>/table.md has both rows (docs/benchmarks.md, "Comparison with the alternatives").
# ARGS (optional) are passed to every `lidef compare`, e.g. ARGS="--lambda-smooth 0.01".
set -u
L=${LIDEF:-build/app/lidef}
SHARED=${SHARED:-../shared/data}
OUT=${OUT:-/tmp/cmp}
mkdir -p "$OUT"
for s in $SHARED/scenarios/bar_bend.json $SHARED/scenarios/bar_twist90.json $SHARED/scenarios/bar_twist180.json data/scenarios/beam_bend.json data/scenarios/beam_twist180.json data/scenarios/beam_uturn.json data/scenarios/beam_pull_sharp.json data/scenarios/beam_twist270.json $SHARED/scenarios/spot_head_turn.json $SHARED/scenarios/horse_leg_lift.json $SHARED/scenarios/animal_tail_lift.json data/scenarios/beam_twist360.json data/scenarios/beam_pull_through.json data/scenarios/beam_twist150.json data/scenarios/beam_mirror.json; do
  n=$(basename $s .json)
  t0=$(date +%s)
  timeout 900 $L compare $s --out $OUT/$n --methods lidef,vhm --quiet ${ARGS:-} > $OUT/$n.log 2>&1
  echo "$n rc=$? $(( $(date +%s) - t0 )) s" >> $OUT/progress.txt
done
echo DONE >> $OUT/progress.txt
for d in "$OUT"/*/; do echo "== $(basename "$d")"; sed -n '5,6p' "$d/table.md"; done
