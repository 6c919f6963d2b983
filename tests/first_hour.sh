#!/usr/bin/env bash
# Replays a new user's first hour (issue "A new user's first hour"): each thing a new user hit, run again, its exit
# status and message checked. Prints one line a check and exits 1 if any failed.
# usage: tests/first_hour.sh BUILD_DIR [SCENE]   (SCENE: a big scene for the output-path checks; default
#        ../shared/scenes/crytek-sponza/scene.json when present, else a 2-million-triangle generator)
set -uo pipefail
build=$(cd "$1" && pwd); source_dir=$(cd "$(dirname "$0")/.." && pwd)
canopy=$build/bin/canopy
scene=${2:-$source_dir/../shared/scenes/crytek-sponza/scene.json}
[ -f "$scene" ] || scene="gen:triangles?tris=2000000&seed=1"
work=$(mktemp -d); trap 'rm -rf "$work"' EXIT
failed=0

pass() { echo "ok:   $1"; }
fail() { echo "FAIL: $1"; shift; printf '      %s\n' "$@"; failed=1; }

# expect NAME STATUS TEXT COMMAND...: the command exits STATUS and its stderr holds TEXT (fixed string).
expect() {
  local name=$1 status=$2 text=$3; shift 3
  local err; err=$("$@" 2>&1 >/dev/null); local got=$?
  if [ "$got" -ne "$status" ]; then fail "$name" "exit $got, expected $status: $*" "$err"
  elif ! grep -qF -- "$text" <<<"$err"; then fail "$name" "stderr lacks '$text': $*" "$err"
  else pass "$name"; fi
}

# 1. The README's builder race runs through every builder.
if PYTHONPATH=$build/python /usr/bin/python3 "$source_dir/examples/compare_builders.py" "gen:box?tris=2000" >"$work/race.txt" 2>&1; then
  pass "compare_builders.py races every builder"
else fail "compare_builders.py races every builder" "$(tail -3 "$work/race.txt")"; fi

# 2. An output path that cannot be written is refused before any work (the scene is not even loaded: the time is
# shown, not checked), and nothing is written.
start=$(date +%s%N)
expect "render -o into a missing folder" 2 "no folder /nonexistent/dir" "$canopy" render "$scene" -o /nonexistent/dir/x.exr
echo "      refused after $(( ($(date +%s%N) - start) / 1000000 )) ms"
expect "render -o x.xyz" 2 "the extension must be one of .exr, .png, .jpg, .jpeg" "$canopy" render "$scene" -o "$work/x.xyz"
expect "render -o noext" 2 "the extension must be one of" "$canopy" render "$scene" -o noext
expect "bench --json into a missing folder" 2 "no folder /nonexistent" "$canopy" bench "$scene" --json /nonexistent/b.json
expect "study --plot as SVG" 2 "the extension must be one of .png" "$canopy" study "$scene" --builder binned --plot "$work/s.svg"
expect "accuracy --json into a missing folder" 2 "no folder /nonexistent" "$canopy" accuracy --json /nonexistent/a.json
expect "render --heatmap -o PNG" 2 "the extension must be one of .exr" "$canopy" render "$scene" --heatmap -o "$work/h.png"
if [ -z "$(ls -A "$work" | grep -v race.txt)" ]; then pass "no output file written"; else fail "no output file written" "$(ls "$work")"; fi

# 3. auto where it works, refused with its reason where it does not; --version.
expect "accuracy --builder auto" 2 "accuracy traces no frames" "$canopy" accuracy --builder auto --rays 10
expect "study --builder auto" 2 "unknown builder 'auto'" "$canopy" study "gen:box?tris=100" --builder auto
if "$canopy" study --help | grep -q ' auto:'; then fail "study --help does not offer auto"; else pass "study --help does not offer auto"; fi
if "$canopy" tradeoff "gen:box?tris=500" --builder auto --seconds 0.05 --reference-spp 1 --size 16 12 -o "$work/t" --quiet 2>/dev/null \
    | grep -qE 'auto\([a-z-]+\) bvh'; then pass "tradeoff --builder auto names its choice"; else fail "tradeoff --builder auto names its choice"; fi
rm -f "$work"/t.*
if "$canopy" --version | grep -qE '^canopy [0-9.]+'; then pass "canopy --version"; else fail "canopy --version"; fi
expect "canopy dynamic, a helper's name" 2 "unknown command 'dynamic'; the commands are render, bench, study, tradeoff, accuracy, rays, reproduce (dynamic: bench --dynamic)" "$canopy" dynamic

# 4. The memory guard: a negative limit is refused; images count in the estimate.
expect "--memory-limit -5" 2 "--memory-limit" "$canopy" render "gen:box?tris=100" --memory-limit -5 -o "$work/x.exr"
expect "a 16384x16384 image under a 2G cap" 1 "try a smaller image (--size)" "$canopy" render "gen:box?tris=100" --size 16384 16384 --memory-limit 2G -o "$work/x.exr"

# 5. Progress on stderr as plain lines when it is not a terminal, none with --quiet; --threads on study and reproduce.
"$canopy" bench "gen:box?tris=2000" --builder binned --builds 1 --frames 1 --size 32 24 2>"$work/progress.txt" >/dev/null
if grep -q "frame" "$work/progress.txt"; then pass "bench shows progress"; else fail "bench shows progress" "$(cat "$work/progress.txt")"; fi
"$canopy" bench "gen:box?tris=2000" --builder binned --builds 1 --frames 1 --size 32 24 --quiet 2>"$work/progress.txt" >/dev/null
if [ ! -s "$work/progress.txt" ]; then pass "bench --quiet is quiet"; else fail "bench --quiet is quiet" "$(cat "$work/progress.txt")"; fi
rm -f "$work/progress.txt"
for command in study reproduce; do
  if "$canopy" $command --help | grep -q -- '--threads'; then pass "$command --threads"; else fail "$command --threads"; fi
done

# 6. The smaller ones.
"$canopy" render "gen:box?tris=200" --size 16 12 --spp 4 -o "$work/grey.png" --quiet >/dev/null 2>&1
"$canopy" render "gen:box?tris=200" --size 16 12 --spp 4 -o "$work/grey.exr" --quiet >/dev/null 2>&1
png=$(oiiotool --stats "$work/grey.png" 2>/dev/null | awk '/Stats Avg/ {print $3; exit}')
exr=$(oiiotool --stats "$work/grey.exr" 2>/dev/null | awk '/Stats Avg/ {print $3; exit}')
# oiiotool gives a PNG's mean in 0..255; the sRGB curve lifts a mid-grey linear mean well above itself.
if [ -n "$png" ] && [ -n "$exr" ] && awk -v p="$png" -v e="$exr" 'BEGIN { if (p > 1) p /= 255; exit !(p > e + 0.15) }'; then
  pass "PNG gets the sRGB curve ($png of 255 against linear $exr)"
else fail "PNG gets the sRGB curve" "png mean '$png', exr mean '$exr'"; fi
rm -f "$work/grey.png" "$work/grey.exr"
mkdir "$work/folder.obj"; mkfifo "$work/fifo.obj"
expect "a folder as a scene" 1 "is a folder, not a file" "$canopy" render "$work/folder.obj" -o "$work/x.exr"
expect "a FIFO as a scene" 1 "is not a regular file" "$canopy" render "$work/fifo.obj" -o "$work/x.exr"
printf 'v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n' >"$work/m.obj"
echo '{"meshes": [{"name": "m", "file": "m.json"}]}' >"$work/scene.json"; echo '{}' >"$work/m.json"
expect "a scene.json mesh that is JSON" 1 "meshes[0].file: 'm.json' is not a mesh file" "$canopy" render "$work/scene.json" -o "$work/x.exr"
printf 'v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n' >"$work/line.obj"
if "$canopy" render "$work/line.obj" --size 8 8 --spp 1 -o "$work/line.exr" --quiet 2>&1 >/dev/null | grep -q "all 1 triangles have zero area"; then
  pass "a scene of zero-area triangles is named"; else fail "a scene of zero-area triangles is named"; fi
expect "a glTF without its .bin" 1 "buffers[0].uri: 'buffer.bin' does not exist" "$canopy" render "$source_dir/fuzz/corpus/gltf/external.gltf" -o "$work/x.exr"
expect "an unknown option exits 2" 2 "--nosuch" "$canopy" render --nosuch
expect "a missing scene exits 1" 1 "no such file" "$canopy" render "$work/none.obj" -o "$work/x.exr"
if PYTHONPATH=$build/python /usr/bin/python3 -c "
import numpy as np, canopy
a = canopy.Accel(np.eye(3, dtype=np.float32), np.array([[0, 1, 2]], np.uint32))
t, tri, u, v = a.intersect(np.zeros((0, 3), np.float32), np.zeros((0, 3), np.float32))
assert t.shape == (0,) and a.occluded(np.zeros((0, 3), np.float32), np.zeros((0, 3), np.float32)).shape == (0,)
" 2>"$work/py.txt"; then pass "Python: an empty batch gives empty arrays"; else fail "Python: an empty batch gives empty arrays" "$(tail -2 "$work/py.txt")"; fi
commit=$(git -C "$source_dir" rev-parse --short HEAD 2>/dev/null)
if [ -z "$commit" ] || (cd "$work" && "$canopy" --version | grep -qF "commit $commit"); then
  pass "--version names the build's commit from any folder"; else fail "--version names the build's commit from any folder" "$("$canopy" --version)"; fi

# 7. Every builder finishes every pathological scene (timed at a million triangles in docs/results.md; here only
# finishing is checked, with no time limit).
if "$build/bin/pathological_builds" 5000 all 1e9 >"$work/path.md" 2>&1 && ! grep -qE 'refused|stopped' "$work/path.md"; then
  pass "every builder finishes every pathological scene (5,000 triangles)"
else fail "every builder finishes every pathological scene" "$(grep -E 'refused|stopped|pathological_builds' "$work/path.md" | head -3)"; fi
rm -f "$work/path.md"

# 8. render.sh builds the command alone.
if grep -q 'setup.sh canopy' "$source_dir/scripts/render.sh"; then pass "render.sh builds only the canopy target"; else fail "render.sh builds only the canopy target"; fi

exit $failed
