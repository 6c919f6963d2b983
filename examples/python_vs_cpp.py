#!/usr/bin/env python3
"""Python's batch query against the C++ one: the same random rays through canopy.Accel.intersect and through
examples/batch_rays (the C++ API), hits compared bit for bit, the fastest of several batches timed on each side.

    PYTHONPATH=build/python /usr/bin/python3 examples/python_vs_cpp.py [--scene S] [--builder B] [--kernel K]

Rays: origins uniform in the scene's bounds, directions uniform on the sphere (numpy, fixed seed). Each round
runs the C++ program (its own build of the same tree, then --repeats batches) and --repeats Python batches."""
import argparse
import pathlib
import re
import subprocess
import sys
import tempfile
import time

import numpy as np

import canopy

ROOT = pathlib.Path(__file__).resolve().parent.parent


def random_rays(vertices, count, seed):
    rng = np.random.default_rng(seed)
    lower, upper = vertices.min(axis=0), vertices.max(axis=0)
    origins = (lower + rng.random((count, 3)) * (upper - lower)).astype(np.float32)
    directions = rng.normal(size=(count, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    return origins, directions.astype(np.float32)


def run_cpp(program, args, rays_path, hits_path, count):
    """The C++ side: its fastest batch in ms, and its hits (t, triangle, u, v)."""
    out = subprocess.run([program, args.scene, args.builder, args.kernel, rays_path, hits_path, str(args.repeats)],
                         check=True, capture_output=True, text=True).stdout
    ms = float(re.search(r"fastest of \d+: ([0-9.]+) ms", out).group(1))
    raw = np.fromfile(hits_path, dtype=np.uint32)
    t, triangle, u, v = (raw[i * count:(i + 1) * count] for i in range(4))
    return ms, (t.view(np.float32), triangle.view(np.int32), u.view(np.float32), v.view(np.float32))


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scene", default=str(ROOT.parent / "shared/scenes/crytek-sponza/scene.json"))
    parser.add_argument("--builder", default="binned")
    parser.add_argument("--kernel", default="bvh8")
    parser.add_argument("--rays", type=int, default=1_000_000)
    parser.add_argument("--repeats", type=int, default=5, help="batches timed a round on each side")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--batch-rays", default=str(ROOT / "build/bin/batch_rays"), help="the C++ program")
    args = parser.parse_args()

    vertices, triangles = canopy.load_triangles(args.scene)
    accel = canopy.Accel(vertices, triangles, builder=args.builder, kernel=args.kernel)
    origins, directions = random_rays(vertices, args.rays, seed=1)
    with tempfile.TemporaryDirectory() as tmp:
        rays_path, hits_path = f"{tmp}/rays.bin", f"{tmp}/hits.bin"
        np.concatenate([origins.ravel(), directions.ravel()]).tofile(rays_path)
        cpp_ms, py_ms = [], []
        for _ in range(args.rounds):
            ms, cpp_hits = run_cpp(args.batch_rays, args, rays_path, hits_path, args.rays)
            cpp_ms.append(ms)
            for _ in range(args.repeats):
                start = time.perf_counter()
                py_hits = accel.intersect(origins, directions)
                py_ms.append((time.perf_counter() - start) * 1e3)

    same = all(np.array_equal(a.view(np.uint32), b.view(np.uint32)) for a, b in zip(py_hits, cpp_hits))
    stats = accel.stats()
    print(f"{args.scene}: {stats['triangles']} triangles, {stats['builder']} {stats['kernel']}, "
          f"{args.rays} random rays, {int((py_hits[1] >= 0).sum())} hits")
    print(f"hits bit for bit the same as C++: {'yes' if same else 'NO'}")
    print(f"C++ batch    fastest {min(cpp_ms):8.2f} ms  ({args.rays / min(cpp_ms) / 1e3:.2f} Mrays/s), "
          f"{args.rounds} rounds of {args.repeats}")
    print(f"Python batch fastest {min(py_ms):8.2f} ms  ({args.rays / min(py_ms) / 1e3:.2f} Mrays/s)")
    print(f"Python / C++: {min(py_ms) / min(cpp_ms):.3f}")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
