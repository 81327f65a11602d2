#!/usr/bin/env bash
# A lent GPU host may have a driver but none of lidef's build dependencies (CGAL, Eigen, VTK, OpenBLAS, ocl-icd), and
# cannot fetch them. This packs the three programs bench/gpu.sh measures with the shared libraries they load (all
# but glibc's) and the shared data into one archive built here, and runs gpu.sh from it there.
#
# Usage:
#   bench/gpu-bundle.sh pack BUILD_DIR DATA_DIR ARCHIVE.tar.xz   # here: BUILD_DIR is a Release build with benchmarks
#   bench/gpu-bundle.sh run ARCHIVE.tar.xz RESULT_DIR            # there: unpacks to /tmp/lidef-bundle, runs gpu.sh
#   bench/gpu-bundle.sh compare OLD.tar.xz NEW.tar.xz RESULT_DIR # there: NEW with the OpenCL tests, then OLD, NEW,
#                                                                # OLD, NEW without; one RESULT_DIR/N-old|new.md each
# `run` and `compare` pass REPS, SCENARIOS, DEVICE, DRAG, DRAG_SCENARIOS, CACHE, TESTS, QUICK on to gpu.sh.
# Without an OpenCL ICD registered on the host it registers the NVIDIA driver's libnvidia-opencl.so.1 where it
# finds one (OCL_ICD_VENDORS). The programs are built for the packing machine's CPU (LIDEF_NATIVE): pack on a
# machine whose instruction set the host has.
set -euo pipefail
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
programs=(app/lidef bench/bench_opencl bench/bench_cholesky tests/lidef_opencl_tests)

pack() {
  local build=$1 data=$2 archive=$3
  stage=$(mktemp -d)  # global: the EXIT trap runs after this function returns
  trap 'rm -rf "$stage"' EXIT
  mkdir -p "$stage/lib" "$stage/data"
  for p in "${programs[@]}"; do
    mkdir -p "$stage/$(dirname "$p")"
    cp "$build/$p" "$stage/$p"
  done
  # Every shared library the programs load except the C library's own (the host's is newer and must be used).
  for p in "${programs[@]}"; do ldd "$build/$p"; done | awk '$3 ~ /^\// { print $3 }' | sort -u |
    grep -v -E '/(libc|libm|libdl|libpthread|librt|ld-linux[^/]*)\.so' |
    while read -r lib; do cp -L "$lib" "$stage/lib/"; done
  chmod -R u+w "$stage"
  strip --strip-unneeded "$stage"/app/* "$stage"/bench/* "$stage"/tests/* "$stage"/lib/*
  cp -r "$data/models" "$data/scenarios" "$stage/data/"
  # The tests know the source tree and the CLI by the absolute paths of this build; `run` recreates them as links.
  local source
  source=$(sed -n 's/^CMAKE_HOME_DIRECTORY:INTERNAL=//p' "$build/CMakeCache.txt")
  printf '%s\n%s\n' "${source:-$ROOT}" "$(cd "$build" && pwd)/app/lidef" > "$stage/paths.txt"
  tar -cJf "$archive" -C "$stage" .
  echo "$archive: $(du -h "$archive" | cut -f1)"
}

run() {
  local archive=$1 result=$2 dir=/tmp/lidef-bundle
  rm -rf "$dir" && mkdir -p "$dir" "$result"
  # Python's tarfile: the host may lack xz.
  python3 -c "import sys, tarfile; tarfile.open(sys.argv[1]).extractall(sys.argv[2])" "$archive" "$dir"
  # A newer host C++ runtime serves the bundle's programs too; an older one would not.
  for l in libstdc++.so.6 libgcc_s.so.1; do
    for d in /usr/lib/x86_64-linux-gnu /lib/x86_64-linux-gnu /usr/lib64; do
      [ -e "$d/$l" ] && rm -f "$dir/lib/$l" && break
    done
  done
  export LD_LIBRARY_PATH=$dir/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}
  { read -r source; read -r cli; } < "$dir/paths.txt"
  [ -e "$source" ] || { mkdir -p "$(dirname "$source")" && ln -s "$ROOT" "$source"; }
  [ -e "$cli" ] || { mkdir -p "$(dirname "$cli")" && ln -s "$dir/app/lidef" "$cli"; }
  # The NVIDIA driver's OpenCL library is often present without its ICD file (a container image that registers
  # only PoCL): register it beside whatever is registered.
  if [ -z "${OCL_ICD_VENDORS:-}" ] && ! grep -qs nvidia /etc/OpenCL/vendors/*; then
    local icd
    icd=$(find /usr/lib /usr/lib64 /usr/local/nvidia /usr/lib/x86_64-linux-gnu -name 'libnvidia-opencl.so.1' 2> /dev/null |
      head -1 || true)
    if [ -n "$icd" ]; then
      mkdir -p "$dir/icd" && echo "$icd" > "$dir/icd/nvidia.icd"
      cp /etc/OpenCL/vendors/*.icd "$dir/icd/" 2> /dev/null || true
      export OCL_ICD_VENDORS=$dir/icd
      echo "gpu-bundle.sh: registered the OpenCL ICD $icd" >&2
    fi
  fi
  BUILD=$dir "$ROOT/bench/gpu.sh" "$dir/data" "$result"
}

# Two bundles side by side in one session on one device (a change measured against the code before it): the new
# bundle's OpenCL tests and first run also fill the subspace cache both use, then old and new alternate. Each
# run's table, drag rows and bench_opencl report go to one markdown file (RESULT_DIR/N-old.md, N-new.md; the tests'
# log to RESULT_DIR/opencl_tests.log): few files, for hosts that return only a few. RUN_TIMEOUT (seconds, default
# 300) bounds each run; TESTS=0 skips the tests.
compare() {
  local old=$1 new=$2 result=$3 i=0 which archive rc
  mkdir -p "$result"
  export CACHE=${CACHE:-/tmp/lidef-bundle-cache}
  for which in new old new old new; do
    i=$((i + 1))
    archive=$new
    [ "$which" = old ] && archive=$old
    local start
    start=$(date -u +%H:%M:%S)
    rc=0
    TESTS=$([ $i = 1 ] && echo "${TESTS:-1}" || echo 0) timeout "${RUN_TIMEOUT:-300}" bash "$0" run "$archive" "/tmp/lidef-compare-$i" \
      > "/tmp/lidef-compare-$i.out" 2> "/tmp/lidef-compare-$i.err" || rc=$?
    {
      echo "# run $i: $which ($archive), $start-$(date -u +%H:%M:%S) UTC, exit $rc"
      cat "/tmp/lidef-compare-$i.out"
      echo
      tail -5 "/tmp/lidef-compare-$i.err"
      echo
      cat "/tmp/lidef-compare-$i/bench_opencl.md" 2> /dev/null || true
    } > "$result/$i-$which.md"
    [ $i = 1 ] && cp "/tmp/lidef-compare-1/opencl_tests.log" "$result/" 2> /dev/null
    [ $i = 1 ] && [ "$rc" != 0 ] && { echo "gpu-bundle.sh: the new bundle's run failed (exit $rc)" >&2; return 1; }
  done
  return 0
}

case "${1:-}" in
  pack) [ $# -eq 4 ] || { echo "usage: $0 pack BUILD_DIR DATA_DIR ARCHIVE.tar.xz" >&2; exit 2; }; pack "$2" "$3" "$4" ;;
  run) [ $# -eq 3 ] || { echo "usage: $0 run ARCHIVE.tar.xz RESULT_DIR" >&2; exit 2; }; run "$2" "$3" ;;
  compare)
    [ $# -eq 4 ] || { echo "usage: $0 compare OLD.tar.xz NEW.tar.xz RESULT_DIR" >&2; exit 2; }
    compare "$2" "$3" "$4"
    ;;
  *)
    echo "usage: $0 pack BUILD_DIR DATA_DIR ARCHIVE.tar.xz | run ARCHIVE.tar.xz RESULT_DIR |" \
      "compare OLD.tar.xz NEW.tar.xz RESULT_DIR" >&2
    exit 2
    ;;
esac
