#!/usr/bin/env bash
# Installs every Debian package lidef needs (libcgal-demo: real meshes in its data.tar.gz, elephant, armadillo,
# ..., which the automatic-cage tests extract at test time). clang, libclang-rt-14-dev (libFuzzer, clang's
# ASan/UBSan runtimes) and libomp-dev (OpenMP for clang) are for `make check-sanitize-ci` (CI) and `make fuzz`.
# pybind11-dev, python3-dev, python3-numpy, python3-pytest, python3-matplotlib: the Python module and its tests
# (python/, examples/python/). Idempotent: returns at once
# when all are present.
set -euo pipefail
PKGS=(
  build-essential cmake ninja-build ccache pkg-config
  clang libclang-rt-14-dev libomp-dev
  libeigen3-dev libspectra-dev nlohmann-json3-dev libcli11-dev libgtest-dev
  libopenblas-dev
  ocl-icd-opencl-dev opencl-headers opencl-clhpp-headers pocl-opencl-icd libclblast-dev
  libsuitesparse-dev libcgal-dev libtet1.5-dev
  libcgal-demo
  libvtk9-dev libvtk9-qt-dev qtbase5-dev
  gnuplot-nox
  pybind11-dev python3-dev python3-numpy python3-pytest python3-matplotlib
  xvfb xauth
)
missing=()
for p in "${PKGS[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#PKGS[@]} packages present"
  exit 0
fi
echo "install-deps: installing ${missing[*]}"
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -q
$SUDO apt-get install -y -q --no-install-recommends "${missing[@]}"
