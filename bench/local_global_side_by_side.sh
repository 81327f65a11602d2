#!/bin/bash
# Two lidef binaries side by side where the continuation's local/global strategy runs (docs/solver.md,
# "Continuation"): horse_leg_lift and bar_twist180 under binding distortion targets, the project's
# beam_pull_through, and spot_head_turn under its target (no local/global: the control). OLD and NEW
# alternated, ROUNDS rounds, 2 threads. Prints per run: wall seconds, iterations and stop reason, handle error,
# energy, the certified bounds and summary.json's solve / local_global / total seconds.
# Usage, from the repository root after building: bash bench/local_global_side_by_side.sh OLD_BINARY NEW_BINARY
set -u
# shellcheck source=bench/side_by_side_common.sh
source "$(dirname "$0")/side_by_side_common.sh"
CONFIGS="$SHARED/scenarios/horse_leg_lift.json|--max-distortion 1.1 --max-iterations 8
$SHARED/scenarios/bar_twist180.json|--max-distortion 1.486 --max-iterations 8
data/scenarios/beam_pull_through.json|
$SHARED/scenarios/spot_head_turn.json|--max-distortion 1.169 --max-iterations 8"
run() {  # binary dir which round
  local start
  start=$(date +%s.%N)
  # shellcheck disable=SC2086 # the arguments are words
  "$1" deform "$sc" $args --threads 2 --quiet --out "$2" > "$2.log" 2>&1
  python3 - "$2" "$(basename "$sc" .json)" "$3" "$start" "$(date +%s.%N)" <<'PY'
import json, sys
d, name, which, start, end = sys.argv[1:6]
wall = float(end) - float(start)
j = json.load(open(d + "/summary.json"))
t = j["time_s"]
lg = "%.2f" % t["local_global"] if "local_global" in t else "-"
print("%s | %s | wall %.1f s | %d it %s | err %.4g | E %.10g | K <= %.6g | s3 >= %.6g | solve %.2f s, "
      "local_global %s s, total %.2f s" % (name, which, wall, j["iterations"], j["stop_reason"],
      j["max_handle_error"], j["energy"]["total"], j["max_distortion_upper_bound"],
      j["min_sigma3_lower_bound"], t["solve"], lg, t["total"]))
PY
}
i=0
while IFS='|' read -r sc args; do
  i=$((i + 1))
  alternate "$i" run
done <<< "$CONFIGS"
