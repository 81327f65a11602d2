#!/bin/bash
# Two lidef binaries side by side on the shared scenarios without targets: per scenario and round, OLD then NEW
# (`lidef deform S --threads 2 --quiet`, defaults, full solves), then whether the two runs wrote byte-identical
# coefficients.txt and certificate.json. Prints per run: iterations, solve s (summary.json time_s.solve), mean
# ms per iteration and mean certificate ms per iteration (iterations.csv).
# Usage, from the repository root after building: bash bench/solve_side_by_side.sh OLD_BINARY NEW_BINARY
set -u
OLD=$1
NEW=$2
SHARED=${SHARED:-../shared/data}
OUT=${OUT:-/tmp/solve-sbs}
ROUNDS=${ROUNDS:-2}
SCENARIOS=${SCENARIOS:-bar_bend bar_twist90 horse_leg_lift spot_head_turn animal_tail_lift bar_twist180}
mkdir -p "$OUT"
for n in $SCENARIOS; do
  for round in $(seq 1 "$ROUNDS"); do
    for which in old new; do
      bin=$OLD
      [ $which = new ] && bin=$NEW
      d=$OUT/$n-$which-$round
      rm -rf "$d"
      $bin deform "$SHARED/scenarios/$n.json" --threads 2 --quiet --out "$d" > "$d.log" 2>&1
      python3 - "$d" "$n $which $round" <<'PY'
import csv, json, sys
d = sys.argv[1]
r = list(csv.DictReader(open(d + "/iterations.csv")))
j = json.load(open(d + "/summary.json"))
n = max(1, len(r))
print("%-28s | %2d it | solve %.3f s | %.1f ms/it | certificate %.1f ms/it" % (
    sys.argv[2], j["iterations"], j["time_s"]["solve"], sum(float(x["ms_total"]) for x in r) / n,
    sum(float(x["ms_certificate"]) for x in r) / n))
PY
    done
    same() { cmp -s "$OUT/$n-old-$round/$1" "$OUT/$n-new-$round/$1" && echo same || echo differ; }
    echo "  coefficients.txt $(same coefficients.txt), certificate.json $(same certificate.json)"
  done
done
