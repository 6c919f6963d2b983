#!/usr/bin/env bash
# Set-up command 1: install what is missing, build the command alone (not the test suites: the first picture comes
# sooner), render the embedded default scene to an EXR.
# usage: scripts/render.sh [OUTPUT.exr] [more canopy render options]
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh canopy
out=${1:-default.exr}; shift || true
# A recognisable, low-noise first picture in about 10 s on 2 cores, with the progress bar on a terminal. canopy
# rejects a repeated option, so a default is added only when the user did not pass that option.
defaults=()
[[ " $* " =~ \ --spp[=\ ] ]] || defaults+=(--spp 64)
[[ " $* " =~ \ --size[=\ ] ]] || defaults+=(--size 512 384)
build/bin/canopy render -o "$out" "${defaults[@]}" "$@"
