#!/usr/bin/env bash
# canopy under `mpirun -n 2` against canopy alone (renderer/distributed.h):
#   render:    two ranks' image equals one process's with the same samples, pixel for pixel, bit for bit;
#   tradeoff:  the same for the reference that two ranks render;
#   study:     two ranks' study of three scenes gives the rows of three one-process studies (the deterministic
#              columns: builder and tree metrics, not timings), each row naming its host;
#   bad_scene: a scene that fails on rank 1 alone ends the job within 30 s (CANOPY_MPI_TIMEOUT), non-zero, with
#              rank 1's message once;
#   usage:     an option error that every rank finds exits 2, as in one process (cli/main.cpp), with one message.
# usage: mpi_checks.sh CHECK CANOPY MPIEXEC PYTHON WORK_DIR
set -uo pipefail
check=$1 canopy=$2 mpiexec=$3 python=$4 work=$5
mkdir -p "$work" && cd "$work" || exit 1
# Tests run as root here; --oversubscribe lets two ranks start wherever the machine has fewer free cores.
mpirun=("$mpiexec" -n 2 --allow-run-as-root --oversubscribe)
fail() { echo "FAIL: $*"; exit 1; }
run() { echo "+ $*"; "$@" || fail "exit $?: $*"; }

same_pixels() {  # idiff: exit 0 only when no pixel differs at all (-fail 0 -warn 0)
    idiff -fail 0 -warn 0 "$1" "$2" || fail "$1 and $2 differ"
    echo "ok: $1 and $2 hold the same pixels"
}

case "$check" in
  render)
    scene='gen:box?tris=3000&seed=1'
    run "$canopy" render "$scene" --spp 7 --size 32 24 --threads 1 -o one.exr
    run "${mpirun[@]}" "$canopy" render "$scene" --spp 7 --size 32 24 --threads 1 -o two.exr
    same_pixels one.exr two.exr
    ;;
  tradeoff)
    scene='gen:cylinders?tris=1000&seed=3'
    rm -f one.* two.*
    run "$canopy" tradeoff "$scene" --builder lbvh --seconds 0.01 --reference-spp 5 --size 16 12 --threads 1 -o one
    run "${mpirun[@]}" "$canopy" tradeoff "$scene" --builder lbvh --seconds 0.01 --reference-spp 5 --size 16 12 --threads 1 -o two
    same_pixels one.reference-*.exr two.reference-*.exr
    ;;
  study)
    scenes=('gen:box?tris=1500&seed=1' 'gen:cylinders?tris=1500&seed=2' 'gen:surface?tris=1500&seed=3')
    options=(--builder binned,lbvh --size 16 12 --repeats 1)
    for i in 0 1 2; do run "$canopy" study "${scenes[$i]}" "${options[@]}" --json "one-$i.json"; done
    run "${mpirun[@]}" "$canopy" study "${scenes[@]}" "${options[@]}" --json two.json
    "$python" - "$(hostname)" <<'PY' || fail "the two-rank study's rows differ from the one-process studies'"
import json, sys
deterministic = ("builder", "sah", "epo", "lcv", "scalar_sah", "scalar_epo", "wide_sah", "wide_epo")
two = json.load(open("two.json"))["scenes"]
one = [json.load(open(f"one-{i}.json"))["scenes"][0] for i in range(3)]
assert [s["scene"] for s in two] == [s["scene"] for s in one], "scenes or their order differ"
for a, b in zip(one, two):
    assert len(a["builders"]) == len(b["builders"]) == 2, "a scene lacks rows"
    for x, y in zip(a["builders"], b["builders"]):
        for key in deterministic:
            assert x[key] == y[key], f"{a['scene']} {x['builder']}: {key} {x[key]} != {y[key]}"
        assert y["host"] == sys.argv[1], f"host {y['host']}"
print("ok: the rows of", len(two), "scenes match")
PY
    ;;
  bad_scene)
    limit=${CANOPY_MPI_TIMEOUT:-30}
    start=$(date +%s)
    output=$(timeout "$limit" "${mpirun[@]}" "$canopy" study 'gen:box?tris=100' 'gen:box?tris=abc' --builder binned --size 4 4 --repeats 1 2>&1)
    status=$?
    echo "$output"
    [ "$status" -ne 124 ] || fail "the job hung (killed after $limit s)"
    [ "$status" -ne 0 ] || fail "the job exited 0"
    # Under the sanitizer presets a report also exits non-zero: it must not pass.
    ! grep -qE "(Address|Leak|UndefinedBehavior)Sanitizer|runtime error:" <<<"$output" || fail "sanitizer report"
    grep -qF "tris" <<<"$output" || fail "no message naming the generator's field"
    [ "$(grep -c 'canopy: error:.*(rank 1 on ' <<<"$output")" -eq 1 ] || fail "not one error message from rank 1"
    echo "ok: exit $status after $(( $(date +%s) - start )) s"
    ;;
  usage)
    output=$("${mpirun[@]}" "$canopy" bench 'gen:box?tris=200' --esc-sa-max 8x 2>&1)
    status=$?
    echo "$output"
    [ "$status" -eq 2 ] || fail "exit $status, not 2"
    [ "$(grep -c 'canopy: error: --esc-sa-max: only with --builder esc' <<<"$output")" -eq 1 ] || fail "not one error message"
    echo "ok: exit 2"
    ;;
  *) fail "unknown check '$check'" ;;
esac
