#!/usr/bin/env bash
# The test suite under the sanitizers, as CI runs it (.ci/run). Stages, all by default:
#   asan: every test but the papers' reports (label `report`) and mpi_study (label `release-only`), built by
#         the debug preset (AddressSanitizer, LeakSanitizer, UndefinedBehaviorSanitizer; the tests' own files
#         without UBSan, which nearly doubled their compile time);
#   tsan: the tests of the parallel code, built by the tsan preset (ThreadSanitizer) against a oneTBB built with
#         ThreadSanitizer (Debian's libtbb is not, so TSan would miss the synchronisation inside it and report
#         every task hand-over as a race): the parallel builders' 1-and-2-thread determinism, the sparse node
#         storage they share, split partitioning, the two-level and re-braided builds, the stream tracer and its
#         batch traversals. tests/tsan.supp suppresses only reports through Debian's Embree, which is not
#         instrumented either.
# Both presets set CANOPY_TEST_SCALE=0.1 (tests/test_scale.h): the oracle and determinism tests run on a tenth
# of their rays and triangles. Every sanitizer report fails its test.
# Usage: scripts/sanitizers.sh [asan|tsan ...]   (default: asan, asan tsan in .ci/run)
set -euo pipefail
cd "$(dirname "$0")/.."

# Allocation stacks of 8 frames, not the default 30: storing the kd-tree builder's deep recursive stacks took 60%
# of its shared-scene test (154 s, 19 s with 8). The MPI tests keep 30 for their suppressions (tests/CMakeLists.txt).
export ASAN_OPTIONS=detect_leaks=1:abort_on_error=1:malloc_context_size=8
export UBSAN_OPTIONS=halt_on_error=1:print_stacktrace=1
export TSAN_OPTIONS="halt_on_error=1:second_deadlock_stack=1:suppressions=$PWD/tests/tsan.supp"
readonly tsan_tests='1 and 2 threads|sparse tree|split partitioning|two-level|re-braid|top level|stream|batch|packet|wavefront|tracer'

# oneTBB 2021.8.0, the version of Debian 12's libtbb-dev, from Debian's archive (the checksum is the .dsc's),
# built with -fsanitize=thread into build-tsan/_deps/onetbb-tsan, where the tsan preset's CMAKE_PREFIX_PATH finds
# it before the system's. Only the core library: canopy does not link tbbmalloc. Built once; a later run reuses it.
readonly tbb_url=http://deb.debian.org/debian/pool/main/o/onetbb/onetbb_2021.8.0.orig.tar.xz
readonly tbb_sha256=7e9111b8bb59c8800bf6d0b06afe7b0891937443d2dae1ee1101c8e2ede6a7ef
readonly tbb_deps=build-tsan/_deps
readonly tbb_prefix=$tbb_deps/onetbb-tsan
build_tsan_tbb() {
  [ -f "$tbb_prefix/sha256" ] && [ "$(cat "$tbb_prefix/sha256")" = "$tbb_sha256" ] && return
  mkdir -p "$tbb_deps"
  curl -sSfL --retry 3 -o "$tbb_deps/onetbb.tar.xz" "$tbb_url"
  echo "$tbb_sha256  $tbb_deps/onetbb.tar.xz" | sha256sum -c --quiet
  rm -rf "$tbb_deps/onetbb-src" "$tbb_deps/onetbb-build" "$tbb_prefix"
  mkdir "$tbb_deps/onetbb-src"
  tar -xJf "$tbb_deps/onetbb.tar.xz" -C "$tbb_deps/onetbb-src" --strip-components=1
  # TBB_STRICT off: oneTBB 2021.8 predates GCC 12's warnings, which -Werror would make fatal.
  cmake -S "$tbb_deps/onetbb-src" -B "$tbb_deps/onetbb-build" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
    -DCMAKE_INSTALL_PREFIX="$PWD/$tbb_prefix" -DTBB_SANITIZE=thread -DTBB_TEST=OFF -DTBB_STRICT=OFF \
    -DTBBMALLOC_BUILD=OFF -DTBB_DISABLE_HWLOC_AUTOMATIC_SEARCH=ON >/dev/null
  # GCC warns that TSan does not model oneTBB's atomic_thread_fence calls: hundreds of lines, kept in a log.
  cmake --build "$tbb_deps/onetbb-build" -j "$(nproc)" >"$tbb_deps/onetbb-build.log" 2>&1 ||
    { tail -40 "$tbb_deps/onetbb-build.log" >&2; exit 1; }
  cmake --install "$tbb_deps/onetbb-build" >/dev/null
  echo "$tbb_sha256" >"$tbb_prefix/sha256"
  rm -rf "$tbb_deps/onetbb-src" "$tbb_deps/onetbb-build" "$tbb_deps/onetbb.tar.xz"
}

stages=("$@")
[ ${#stages[@]} -gt 0 ] || stages=(asan)
for stage in "${stages[@]}"; do
  case "$stage" in
    asan)
      cmake --preset debug >/dev/null
      cmake --build --preset debug -j "$(nproc)"
      ctest --preset debug -j "$(nproc)" --timeout 1800 -LE '^(report|release-only)$'
      ;;
    tsan)
      build_tsan_tbb
      cmake --preset tsan >/dev/null
      # A cache configured before the TSan TBB existed would still name the system's.
      grep -q "^TBB_DIR:PATH=$PWD/$tbb_prefix/" build-tsan/CMakeCache.txt ||
        { echo "sanitizers: build-tsan does not use $tbb_prefix (remove build-tsan/CMakeCache.txt)" >&2; exit 1; }
      # Only the test executables: the stage runs none of the command line's, Python's or the examples' tests.
      cmake --build --preset tsan -j "$(nproc)" --target canopy_tests canopy_api_tests
      ctest --preset tsan -j "$(nproc)" --timeout 1800 -R "$tsan_tests" -E '^cli_'
      ;;
    *) echo "sanitizers: unknown stage '$stage' (known: asan, tsan)" >&2; exit 2 ;;
  esac
done
