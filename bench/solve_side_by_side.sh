#!/bin/bash
# Two lidef binaries side by side on the shared scenarios without targets: per scenario and round, OLD then NEW
# (`lidef deform S --threads 2 --quiet`, defaults, full solves), then whether the two runs wrote byte-identical
# coefficients.txt and certificate.json. Prints per run: iterations, solve s (summary.json time_s.solve), mean
# ms per iteration, mean gradient ms and mean certificate ms per iteration (iterations.csv).
# Usage, from the repository root after building: bash bench/solve_side_by_side.sh OLD_BINARY NEW_BINARY
# (SCENARIOS, ROUNDS, SHARED, OUT in the environment).
set -u
# shellcheck source=bench/side_by_side_common.sh
source "$(dirname "$0")/side_by_side_common.sh"
SCENARIOS=${SCENARIOS:-bar_bend bar_twist90 horse_leg_lift spot_head_turn animal_tail_lift bar_twist180}
run() {  # binary dir which round
  "$1" deform "$SHARED/scenarios/$n.json" --threads 2 --quiet --out "$2" > "$2.log" 2>&1
  python3 - "$2" "$n $3 $4" <<'PY'
import csv, json, sys
d = sys.argv[1]
r = list(csv.DictReader(open(d + "/iterations.csv")))
j = json.load(open(d + "/summary.json"))
n = max(1, len(r))
print("%-28s | %2d it | solve %.3f s | %.1f ms/it | gradient %.1f ms/it | certificate %.1f ms/it" % (
    sys.argv[2], j["iterations"], j["time_s"]["solve"], sum(float(x["ms_total"]) for x in r) / n,
    sum(float(x["ms_gradient"]) for x in r) / n, sum(float(x["ms_certificate"]) for x in r) / n))
PY
}
compare_round() {  # round: whether OLD and NEW wrote the same map and certificate
  same() { cmp -s "$OUT/$n-old-$1/$2" "$OUT/$n-new-$1/$2" && echo same || echo differ; }
  echo "  coefficients.txt $(same "$1" coefficients.txt), certificate.json $(same "$1" certificate.json)"
}
for n in $SCENARIOS; do
  alternate "$n" run compare_round
done
