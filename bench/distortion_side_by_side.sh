#!/bin/bash
# Two lidef binaries side by side under the distortion targets of docs/benchmarks.md ("Bounded distortion"):
# per target, OLD and NEW alternated (ROUNDS rounds, ITERATIONS iterations at most (default 8; "all": the
# scenario's own limit), 2 threads), then the unconstrained runs of NEW. Prints per run: ms per iteration and certificate seconds (iterations.csv), the solve's
# iterations and stop reason, the final energy, the certified bounds (summary.json) and the sampled maximum of
# sigma1/sigma3 (`lidef verify`, 4 samples per leaf, first round only).
# Usage, from the repository root after building: bash bench/distortion_side_by_side.sh OLD_BINARY NEW_BINARY
set -u
# shellcheck source=bench/side_by_side_common.sh
source "$(dirname "$0")/side_by_side_common.sh"
# ITERATIONS=all: the scenarios' own iteration limit, so that a blocked run goes on to the continuation's
# later strategies (local/global maps) as a user's run does.
ITERATIONS=${ITERATIONS:-8}
LIMIT="--max-iterations $ITERATIONS"
[ "$ITERATIONS" = all ] && LIMIT=""
# scenario and target arguments, one run configuration per line (CONFIGS in the environment: a subset)
CONFIGS=${CONFIGS:-"spot_head_turn|--max-distortion 1.169
bar_bend|--max-distortion 1.477
horse_leg_lift|--max-distortion 1.1
animal_tail_lift|--max-distortion 1.31
bar_twist90|--max-distortion 1.192
bar_twist180|--max-distortion 1.486
spot_head_turn|--max-sigma1 1.17 --min-sigma3 0.9101
bar_bend|--max-sigma1 1.183 --min-sigma3 0.7187"}
stats() {  # dir: ms/iter, certificate s, iterations, stop, energy, K bound, sigma1 bound, sigma3 bound
  python3 - "$1" <<'PY'
import csv, json, sys
d = sys.argv[1]
r = list(csv.DictReader(open(d + "/iterations.csv")))
j = json.load(open(d + "/summary.json"))
ms = sum(float(x["ms_total"]) for x in r) / max(1, len(r))
cs = sum(float(x["ms_certificate"]) for x in r) / 1000
t = j["time_s"]
print("%.0f ms/it | cert %.2f s | solve %.2f s (local/global %.2f s) | %d it %s | E %.6g | K <= %.5g | s1 <= %.5g | s3 >= %.5g" % (
    ms, cs, t["solve"], t.get("local_global", 0), j["iterations"], j["stop_reason"], j["energy"]["total"],
    j["max_distortion_upper_bound"], j["max_sigma1_upper_bound"], j["min_sigma3_lower_bound"]))
PY
}
sampled() {  # binary dir scenario: the sampled max sigma1/sigma3 of the written map
  local m
  m=$SHARED/models/$(python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['model'])" "$2/summary.json")
  "$1" verify "$m" --coeffs "$2/coefficients.txt" --certificate "$2/certificate.json" --samples-per-voxel 4 \
    --out "$2/verify" > "$2/verify.log" 2>&1
  sed -n 's/.*sampled max sigma1\/sigma3 \([0-9.e+-]*\).*/\1/p' "$2/verify.log" | head -1
}
run() {  # binary dir which round
  local extra=""
  # shellcheck disable=SC2086 # the arguments are words
  "$1" deform "$SHARED/scenarios/$n.json" $args $LIMIT --threads 2 --quiet --out "$2" > "$2.log" 2>&1
  [ "$4" = 1 ] && extra=" | sampled K $(sampled "$1" "$2")"
  echo "$n $args | $3 | $(stats "$2")$extra"
}
same() {  # round: whether OLD and NEW wrote the same map and certificate
  local o=$OUT/$key-old-$1 w=$OUT/$key-new-$1 f r=""
  for f in coefficients.txt certificate.json; do
    if cmp -s "$o/$f" "$w/$f"; then r="$r $f same"; else r="$r $f DIFFERS"; fi
  done
  echo "$n $args | round $1:$r"
}
i=0
while IFS='|' read -r n args; do
  i=$((i + 1))
  key=$i-$n
  alternate "$key" run same
done <<< "$CONFIGS"
for n in spot_head_turn bar_bend horse_leg_lift animal_tail_lift bar_twist90 bar_twist180; do
  for round in $(seq 1 "$ROUNDS"); do
    d=$OUT/free-$n-$round
    rm -rf "$d"
    # shellcheck disable=SC2086 # the arguments are words
    $NEW deform "$SHARED/scenarios/$n.json" $LIMIT --threads 2 --quiet --out "$d" > "$d.log" 2>&1
    echo "$n unconstrained | new | $(stats "$d")"
  done
done
