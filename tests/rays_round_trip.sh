#!/usr/bin/env bash
# A renderer's rays through Python and back: `canopy rays record` writes a frame's nee rays, canopy.load_rays and
# canopy.save_rays copy them through numpy, and `canopy bench --rays` replays the copy, every canopy row of the
# recording's tree giving the recorded hits bit for bit (no answer or distance differs). A ray file numpy made from
# the renderer's own arrays (canopy.make_rays) replays too.
# Usage: rays_round_trip.sh CANOPY PYTHON PYTHONPATH OUT_DIR
set -euo pipefail
canopy=$1 python=$2 pythonpath=$3 out=$4
mkdir -p "$out"
scene='gen:box?tris=3000&seed=1'
"$canopy" rays record "$scene" --workload nee --size 48 36 -o "$out/recorded.npy"
PYTHONPATH=$pythonpath "$python" - "$out" <<'PY'
import sys
import numpy as np
import canopy
out = sys.argv[1]
rays = canopy.load_rays(f"{out}/recorded.npy")
assert rays.dtype == canopy.RAY_DTYPE and len(rays) > 48 * 36, rays.shape
assert rays["any"].any() and not rays["any"].all(), "nee records closest and any-hit rays"
canopy.save_rays(f"{out}/copy.npy", rays)
assert canopy.load_rays(f"{out}/copy.npy").tobytes() == rays.tobytes()
rng = np.random.default_rng(5)
d = rng.normal(size=(1000, 3))
canopy.save_rays(f"{out}/own.npy", canopy.make_rays(rng.uniform(-1, 1, size=(1000, 3)), d / np.linalg.norm(d, axis=1, keepdims=True),
                                                   any_hit=np.arange(1000) % 2 == 0))
print(f"python: {len(rays)} rays read, written and read again unchanged")
PY
"$canopy" bench "$scene" --rays "$out/copy.npy" --builder binned --tracer single,stream --builds 1 --frames 1 --no-epo --quiet \
  > "$out/replay.txt"
cat "$out/replay.txt"
rows=$(grep -c ': of [0-9]* recorded answers, 0 differ .*, 0 ties .*, 0 on the same triangle' "$out/replay.txt")
[ "$rows" -eq 2 ] || { echo "expected both canopy rows to give the recorded hits bit for bit"; exit 1; }
"$canopy" bench "$scene" --rays "$out/own.npy" --builder binned --tracer single --builds 1 --frames 1 --no-epo --quiet \
  | grep -q 'replay: 1000 rays of'
