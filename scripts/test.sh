#!/usr/bin/env bash
# Set-up command 2: install what is missing, build, run the whole test suite (CTest + Catch2).
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
ctest --preset release -j "$(nproc)" --timeout 900
