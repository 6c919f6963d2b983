#!/usr/bin/env python3
"""Builds every registered builder on a scene, casts the same million diffuse rays through each, and prints
build time, SAH and rays per second.

    PYTHONPATH=build/python /usr/bin/python3 examples/compare_builders.py ../shared/scenes/sibenik/scene.json

Diffuse rays: from points spread over the surfaces by area, leaving the side of a random choice along a
cosine-weighted direction, as the path tracer's bounces do."""
import argparse
import time

import numpy as np

import canopy


def diffuse_rays(vertices, triangles, count, seed):
    rng = np.random.default_rng(seed)
    corners = vertices[triangles].astype(np.float64)
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    areas = np.linalg.norm(normals, axis=1)
    chosen = rng.choice(len(triangles), size=count, p=areas / areas.sum())
    a, b = rng.random((2, count))
    flip = a + b > 1
    a, b = np.where(flip, 1 - a, a), np.where(flip, 1 - b, b)
    c = corners[chosen]
    points = c[:, 0] + a[:, None] * (c[:, 1] - c[:, 0]) + b[:, None] * (c[:, 2] - c[:, 0])
    n = normals[chosen] / np.maximum(areas[chosen], 1e-30)[:, None]
    n *= rng.choice([-1.0, 1.0], size=(count, 1))
    # Cosine-weighted about n: a uniform point on the sphere added to the normal.
    sphere = rng.normal(size=(count, 3))
    directions = n + sphere / np.linalg.norm(sphere, axis=1, keepdims=True)
    scale = np.abs(vertices).max()
    origins = points + n * scale * 1e-5
    return origins.astype(np.float32), directions.astype(np.float32)


def figure(value, width, decimals):
    """The value in a column of `width`, or "-" where the tree has no such figure (lbvh's direct wide tree: no SAH)."""
    return f"{'-':>{width}}" if value is None else f"{value:{width}.{decimals}f}"


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("scene", help=".obj, .gltf, scene.json or gen:NAME?tris=N")
    parser.add_argument("--rays", type=int, default=1_000_000)
    parser.add_argument("--kernel", default="auto")
    parser.add_argument("--builders", default=",".join(canopy.builders()), help="comma-separated names")
    args = parser.parse_args()

    vertices, triangles = canopy.load_triangles(args.scene)
    origins, directions = diffuse_rays(vertices, triangles, args.rays, seed=1)
    print(f"{args.scene}: {len(triangles)} triangles, {args.rays} diffuse rays")
    print(f"{'builder':>15} {'build ms':>10} {'SAH':>9} {'Mrays/s':>9} {'hits':>9}")
    for builder in args.builders.split(","):
        accel = canopy.Accel(vertices, triangles, builder=builder, kernel=args.kernel)
        stats = accel.stats()
        start = time.perf_counter()
        triangle = accel.intersect(origins, directions)[1]
        seconds = time.perf_counter() - start
        print(f"{builder:>15} {stats['build_ms']:10.1f} {figure(stats['sah'], 9, 2)} {args.rays / seconds / 1e6:9.2f} "
              f"{int((triangle >= 0).sum()):9d}")


if __name__ == "__main__":
    main()
