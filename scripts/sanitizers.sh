#!/usr/bin/env bash
# The test suite under the sanitizers, as CI runs it (.ci/run). Stages, all by default:
#   asan: every test, built by the debug preset (AddressSanitizer, LeakSanitizer, UndefinedBehaviorSanitizer);
#   tsan: the tests of the parallel code, built by the tsan preset (ThreadSanitizer): the parallel builders'
#         1-and-2-thread determinism, split partitioning, the two-level and re-braided builds, the stream tracer
#         and its batch traversals. Not yet a CI stage: Debian's libtbb is not built with TSan, so TSan misses the
#         synchronisation between a thread that spawns a task and the one that runs it and reports the hand-over
#         as a race (tests/tsan.supp removes those inside TBB's headers; those in canopy's loop bodies remain).
# Both presets set CANOPY_TEST_SCALE=0.1 (tests/test_scale.h): the oracle and determinism tests run on a tenth
# of their rays and triangles. Every sanitizer report fails its test.
# Usage: scripts/sanitizers.sh [asan|tsan ...]   (default: asan)
set -euo pipefail
cd "$(dirname "$0")/.."

export ASAN_OPTIONS=detect_leaks=1:abort_on_error=1
export UBSAN_OPTIONS=halt_on_error=1:print_stacktrace=1
export TSAN_OPTIONS="halt_on_error=1:second_deadlock_stack=1:suppressions=$PWD/tests/tsan.supp"
readonly tsan_tests='1 and 2 threads|split partitioning|two-level|re-braid|top level|stream|batch|packet|wavefront|tracer'

stages=("$@")
[ ${#stages[@]} -gt 0 ] || stages=(asan)
for stage in "${stages[@]}"; do
  case "$stage" in
    asan)
      cmake --preset debug >/dev/null
      cmake --build --preset debug -j "$(nproc)"
      ctest --preset debug -j "$(nproc)" --timeout 1800
      ;;
    tsan)
      cmake --preset tsan >/dev/null
      cmake --build --preset tsan -j "$(nproc)"
      ctest --preset tsan -j "$(nproc)" --timeout 1800 -R "$tsan_tests" -E '^cli_'
      ;;
    *) echo "sanitizers: unknown stage '$stage' (known: asan, tsan)" >&2; exit 2 ;;
  esac
done
