#!/usr/bin/env bash
# Builds the fuzz preset (clang 14, libFuzzer, ASan + UBSan) and runs every fuzz target for FUZZ_SECONDS
# (default 60) from its seed corpus, fuzz/corpus/NAME, with its dictionary, fuzz/dict/*.dict; FUZZ_PARALLEL
# targets at once (default: as many as there are cores). New inputs go to build-fuzz/corpus/NAME, never into the repository. A crash, leak,
# timeout, out-of-memory or sanitizer report fails the run and leaves its input in build-fuzz/findings/NAME/.
# Usage: scripts/fuzz.sh [obj|scene_json|gltf|generator ...]   (default: all four)
set -euo pipefail
cd "$(dirname "$0")/.."

seconds=${FUZZ_SECONDS:-60}
parallel=${FUZZ_PARALLEL:-$(nproc)}
targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=(obj scene_json gltf generator)

dictionary_of() {
  case "$1" in
    scene_json) echo json ;;
    *) echo "$1" ;;
  esac
}

run_target() {
  local name=$1
  local corpus=build-fuzz/corpus/$name findings=build-fuzz/findings/$name
  mkdir -p "$corpus" "$findings"
  if build-fuzz/bin/fuzz_"$name" "$corpus" fuzz/corpus/"$name" -dict=fuzz/dict/"$(dictionary_of "$name")".dict \
       -max_total_time="$seconds" -timeout=20 -rss_limit_mb=2048 -artifact_prefix="$findings"/ -print_final_stats=1 \
       > build-fuzz/"$name".log 2>&1; then
    echo "fuzz $name: $(grep -m1 -o 'stat::number_of_executed_units: *[0-9]*' build-fuzz/"$name".log | grep -o '[0-9]*$') inputs in ${seconds} s, no finding"
  else
    echo "fuzz $name: FINDING (build-fuzz/$name.log, input in $findings/):"
    grep -m3 -E "ERROR|runtime error|Timeout|out-of-memory|terminate" build-fuzz/"$name".log || tail -n 20 build-fuzz/"$name".log
    return 1
  fi
}

cmake --preset fuzz >/dev/null
cmake --build --preset fuzz -j "$(nproc)"
failed=0 running=0
for name in "${targets[@]}"; do
  run_target "$name" &
  running=$((running + 1))
  if [ "$running" -ge "$parallel" ]; then
    wait -n || failed=1
    running=$((running - 1))
  fi
done
while [ "$running" -gt 0 ]; do
  wait -n || failed=1
  running=$((running - 1))
done
exit "$failed"
