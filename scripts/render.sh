#!/usr/bin/env bash
# Set-up command 1: install what is missing, build, render the embedded default scene to an EXR.
# usage: scripts/render.sh [OUTPUT.exr] [more canopy render options]
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
out=${1:-default.exr}; shift || true
build/bin/canopy render -o "$out" "$@"
