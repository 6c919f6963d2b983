#!/usr/bin/env python3
"""Times each query of canopy.Scene on a million random rays and points inside a scene (origins and points uniform in
its box, directions uniform): closest and any hits in each input form, hit counts and lists, closest points, signed
distances. Builds once; each query the fastest of 3 (signed distance: 1).

    PYTHONPATH=build/python /usr/bin/python3 examples/python_queries.py ../shared/scenes/crytek-sponza/scene.json"""
import argparse
import time

import numpy as np

import canopy


def fastest_ms(query, repeats=3):
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        query()
        best = min(best, time.perf_counter() - start)
    return best * 1e3


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scene")
    parser.add_argument("--rays", type=int, default=1_000_000)
    args = parser.parse_args()
    vertices, triangles = canopy.load_triangles(args.scene)
    scene = canopy.Scene()
    scene.add_mesh(vertices, triangles)
    print(f"build: {fastest_ms(lambda: scene.occluded(np.zeros((1, 6), np.float32)), 1):.1f} ms (the first query builds)")
    rng = np.random.default_rng(1)
    lower, upper = vertices.min(axis=0), vertices.max(axis=0)
    origins = rng.uniform(lower, upper, (args.rays, 3)).astype(np.float32)
    directions = rng.normal(size=(args.rays, 3)).astype(np.float32)
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    rays = np.concatenate([origins, directions], axis=1)
    rays64 = rays.astype(np.float64)
    points = rng.uniform(lower, upper, (args.rays, 3)).astype(np.float32)
    queries = [
        ("intersect, float32 origins and directions", lambda: scene.intersect(origins, directions)),
        ("intersect, float32 (n, 6)", lambda: scene.intersect(rays)),
        ("intersect, float64 (n, 6)", lambda: scene.intersect(rays64)),
        ("occluded", lambda: scene.occluded(origins, directions)),
        ("count_intersections", lambda: scene.count_intersections(origins, directions)),
        ("list_intersections", lambda: scene.list_intersections(origins, directions)),
        ("closest_points", lambda: scene.closest_points(points)),
        ("signed_distance", lambda: scene.signed_distance(points)),
    ]
    print("| query | ms |\n|---|---|")
    for name, query in queries:
        print(f"| {name} | {fastest_ms(query, 1 if name == 'signed_distance' else 3):.1f} |")


if __name__ == "__main__":
    main()
