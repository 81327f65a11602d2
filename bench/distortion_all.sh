#!/bin/bash
# Bounded distortion on every shared scenario (docs/benchmarks.md, "Bounded distortion"): per scenario the
# unconstrained run (max sigma1/sigma3 sampled by `lidef verify` and the certified bound), a run with a
# target that does not bind (K = 2 x the certified bound: the bounds' cost per iteration) and a constrained run
# at K = 1 + 0.8 (sampled max - 1), below the unconstrained map's maximum.
# Run from the repository root after building: bash bench/distortion_all.sh; prints one table row per scenario.
# MODE=isometric measures the max_sigma1 / min_sigma3 targets instead (below).
set -u
L=${LIDEF:-build/app/lidef}
SHARED=${SHARED:-../shared/data}
OUT=${OUT:-/tmp/distortion}
ARGS=${ARGS:-}
mkdir -p "$OUT"
ms_per_iter() {  # mean ms_total per iteration of iterations.csv
  python3 -c "import csv,sys; r=list(csv.DictReader(open(sys.argv[1]))); print('%.0f' % (sum(float(x['ms_total']) for x in r)/max(1,len(r))))" "$1"
}
field() { python3 -c "import json,sys; j=json.load(open(sys.argv[1])); v=j
for k in sys.argv[2].split('.'): v=v[k]
print(v if not isinstance(v,float) else '%.4g' % v)" "$1" "$2"; }
# MODE=isometric: the isometric targets instead. Per scenario the unconstrained run's sampled max sigma1 and
# min sigma3 (`lidef verify`) and certified bounds, then a run under both targets at 0.8 of the way from 1
# to the sampled extremes: S = 1 + 0.8 (max sigma1 - 1), s = 1 - 0.8 (1 - min sigma3); reached, stop,
# iterations, solve time, ms per iteration (and the unconstrained run's), the certified bounds and whether
# `lidef verify` finds every sample within the targets.
if [ "${MODE:-}" = isometric ]; then
  echo "| scenario | sampled max sigma1 / min sigma3 | certified bounds | S / s | reached | stop | iterations | solve s | ms/iter off / on | certified bounds | verify |"
  for s in $SHARED/scenarios/*.json; do
    n=$(basename $s .json)
    $L deform $s --out $OUT/$n/free --quiet $ARGS > $OUT/$n.free.log 2>&1
    m=$SHARED/models/$(field $OUT/$n/free/summary.json model)
    $L verify $m --coeffs $OUT/$n/free/coefficients.txt --certificate $OUT/$n/free/certificate.json \
      --samples-per-voxel 4 --out $OUT/$n/verify > $OUT/$n.verify.log 2>&1
    s1=$(sed -n 's/.*sampled max sigma1 \([0-9.e+-]*\) .*/\1/p' $OUT/$n.verify.log)
    s3=$(sed -n 's/.*min sigma3 sampled in certified leaves \([0-9.e+-]*\).*/\1/p' $OUT/$n.verify.log)
    S=$(python3 -c "print('%.4g' % (1 + 0.8*($s1 - 1)))")
    t=$(python3 -c "print('%.4g' % (1 - 0.8*(1 - $s3)))")
    timeout ${KTIMEOUT:-240} $L deform $s --out $OUT/$n/iso --quiet --max-sigma1 $S --min-sigma3 $t $ARGS \
      > $OUT/$n.iso.log 2>&1
    $L verify $m --coeffs $OUT/$n/iso/coefficients.txt --certificate $OUT/$n/iso/certificate.json \
      --samples-per-voxel 4 --out $OUT/$n/iso-verify > $OUT/$n.iso-verify.log 2>&1
    v=$(grep -q "every sample within them" $OUT/$n.iso-verify.log && echo "within" || echo "NOT within")
    echo "| $n | $s1 / $s3 | $(field $OUT/$n/free/summary.json max_sigma1_upper_bound) / $(field $OUT/$n/free/summary.json min_sigma3_lower_bound) | $S / $t | $(field $OUT/$n/iso/summary.json handles_reached) | $(field $OUT/$n/iso/summary.json stop_reason) | $(field $OUT/$n/iso/summary.json iterations) | $(field $OUT/$n/iso/summary.json time_s.solve) | $(ms_per_iter $OUT/$n/free/iterations.csv) / $(ms_per_iter $OUT/$n/iso/iterations.csv) | $(field $OUT/$n/iso/summary.json max_sigma1_upper_bound) / $(field $OUT/$n/iso/summary.json min_sigma3_lower_bound) | $v |"
  done
  exit 0
fi
echo "| scenario | sampled max K | certified bound | ms/iter off | ms/iter on (K = 2x bound) | K target | reached | stop | iterations | solve s | certified bound | ms/iter |"
for s in $SHARED/scenarios/*.json; do
  n=$(basename $s .json)
  $L deform $s --out $OUT/$n/free --quiet $ARGS > $OUT/$n.free.log 2>&1
  $L verify $SHARED/models/$(field $OUT/$n/free/summary.json model) --coeffs $OUT/$n/free/coefficients.txt \
    --certificate $OUT/$n/free/certificate.json --samples-per-voxel 4 --out $OUT/$n/verify > $OUT/$n.verify.log 2>&1
  ks=$(sed -n 's/.*sampled max sigma1\/sigma3 \([0-9.e+-]*\).*/\1/p' $OUT/$n.verify.log)
  kb=$(field $OUT/$n/free/summary.json max_distortion_upper_bound)
  kloose=$(python3 -c "print(2*$kb)")
  $L deform $s --out $OUT/$n/loose --quiet --max-distortion $kloose $ARGS > $OUT/$n.loose.log 2>&1
  K=$(python3 -c "print('%.4g' % (1 + 0.8*($ks - 1)))")
  timeout ${KTIMEOUT:-240} $L deform $s --out $OUT/$n/k --quiet --max-distortion $K $ARGS > $OUT/$n.k.log 2>&1
  echo "| $n | $ks | $kb | $(ms_per_iter $OUT/$n/free/iterations.csv) | $(ms_per_iter $OUT/$n/loose/iterations.csv) | $K | $(field $OUT/$n/k/summary.json handles_reached) | $(field $OUT/$n/k/summary.json stop_reason) | $(field $OUT/$n/k/summary.json iterations) | $(field $OUT/$n/k/summary.json time_s.solve) | $(field $OUT/$n/k/summary.json max_distortion_upper_bound) | $(ms_per_iter $OUT/$n/k/iterations.csv) |"
done
