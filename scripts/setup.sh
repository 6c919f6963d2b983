#!/usr/bin/env bash
# Installs the Debian packages canopy needs (only those missing), then configures and builds the
# Release preset (-O3, host ISA) into build/. Idempotent: a second run installs and rebuilds nothing new.
# usage: scripts/setup.sh [TARGET...]   (the named targets only, as render.sh's `canopy`; none: every target)
set -euo pipefail
cd "$(dirname "$0")/.."

packages=(cmake ninja-build g++ libtbb-dev libopenimageio-dev openimageio-tools libopenexr-dev libglm-dev
          libtinyobjloader-dev libtinygltf-dev catch2 nlohmann-json3-dev libcli11-dev libembree-dev fonts-dejavu-core
          python3-dev pybind11-dev python3-numpy python3-pytest   # the Python module, for /usr/bin/python3
          python3-build python3-venv python3-pip python3-setuptools python3-wheel   # its wheel and pip install .
          libopenmpi-dev openmpi-bin                               # jobs of several processes (mpirun, srun)
          curl xz-utils   # scripts/sanitizers.sh tsan fetches and unpacks oneTBB's source
          ccache)         # a fresh clone reuses the objects of earlier builds (CMakeLists.txt)
# CANOPY_FUZZ=1: also clang 14 and its libFuzzer runtime, for the fuzz preset (scripts/fuzz.sh).
[ "${CANOPY_FUZZ:-0}" = 1 ] && packages+=(clang-14 libclang-rt-14-dev)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "setup: installing ${missing[*]}"
  sudo=""; [ "$(id -u)" -ne 0 ] && sudo="sudo"
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

cmake --preset release >/dev/null
targets=()
[ $# -gt 0 ] && targets=(--target "$@")
cmake --build --preset release -j "$(nproc)" "${targets[@]}"
