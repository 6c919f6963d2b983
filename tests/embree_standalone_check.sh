#!/usr/bin/env bash
# canopy's `embree medium` row and the standalone Embree path tracer (tools/embree_path_tracer.cpp) trace the
# same paths of the same scene: the same rays per frame (exactly, both shading from Embree's hit record with the same
# arithmetic) and image means within 0.5% (the images are accumulated in different orders and precisions).
# Usage: embree_standalone_check.sh CANOPY EMBREE_PATH_TRACER SCENE OUT_DIR
set -euo pipefail
canopy=$1 standalone=$2 scene=$3 out=$4
mkdir -p "$out"
args=(--size 64 48 --frames 2 --threads 2)
"$canopy" bench "$scene" --builder binned --accel embree --embree-quality medium --no-epo --builds 1 "${args[@]}" \
  --json "$out/embree_row.json" > /dev/null
"$standalone" "$scene" "${args[@]}" > "$out/standalone.txt"
/usr/bin/python3 - "$out/embree_row.json" "$out/standalone.txt" <<'PY'
import json, sys
rows = [r for r in json.load(open(sys.argv[1]))["results"] if r["accel"] == "embree"]
if len(rows) != 1:
    sys.exit(f"expected one embree row in {sys.argv[1]}, found {len(rows)}")
row = rows[0]
fields = dict(line.rsplit(" ", 1) for line in open(sys.argv[2]) if not line.startswith("scene "))
rays, mean = float(fields["rays/frame"]), float(fields["image mean"])
print(f"rays/frame: canopy's embree row {row['rays_per_frame']}, standalone {rays}; "
      f"image mean: {row['image_mean']:.6f}, {mean:.6f}")
if row["rays_per_frame"] != rays:
    sys.exit("rays per frame differ")
if abs(row["image_mean"] - mean) > 0.005 * mean:
    sys.exit("image means differ by more than 0.5%")
PY
