#!/usr/bin/env python3
"""canopy's Scene against the Python ray casters people already use: Open3D's RaycastingScene and embreex (the
pyembree API trimesh's embree intersector calls), whichever of them import, on the same random rays over a mesh.

    PYTHONPATH=build/python /usr/bin/python3 examples/python_peers.py ../shared/scenes/crytek-sponza/scene.json --rays 1000000

Rays: origins uniform in the scene's bounding box, directions uniform on the sphere, float32, a fixed seed; each
batch size in --rays (default 1 M and 4 M). Every caster builds --repeats times (median reported, apart from the
casts) and casts each batch --repeats times for the closest hit and for any hit (median reported), on all threads
(canopy and Open3D; embreex's run() loops over the rays on one thread, as its source does). Each caster's
input is made before the clock starts.

Hits are compared with canopy's: hit or miss, then the triangle. A disagreement is checked in float64: a tie (both
triangles at the same distance along the ray: a shared edge, coplanar triangles) or a graze (the ray within 1e-4,
barycentric, of an edge of the triangle one caster reports, where float32 kernels may round either way) is counted
apart from the unexplained ones.

Open3D 0.16 as Debian packages it (python3-open3d) misses every ray: Debian's libembree3 is built with ray masks
(EMBREE_RAY_MASK=ON) and Open3D leaves each ray's mask 0, which matches no geometry. So each peer first casts one ray
straight at a triangle's centroid; a peer that misses it is reported with a warning instead of times."""
import argparse
import statistics
import sys
import time

import numpy as np

EDGE_MARGIN = 1e-4  # barycentric distance from an edge within which float32 kernels may decide either way
T_MARGIN = 1e-5  # relative distance along the ray within which two hits are a tie


def random_rays(vertices, count, seed):
    """float32 origins uniform in the vertices' bounding box and directions uniform on the sphere."""
    rng = np.random.default_rng(seed)
    low, high = vertices.min(axis=0).astype(np.float64), vertices.max(axis=0).astype(np.float64)
    origins = low + rng.random((count, 3)) * (high - low)
    directions = rng.normal(size=(count, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    return origins.astype(np.float32), directions.astype(np.float32)


class CanopyCaster:
    """canopy.Scene: closest hits by intersect, any hits by occluded, on (n, 6) float32 rays read in place."""
    name = "canopy"

    def __init__(self, threads=0):
        import canopy
        self.canopy, self.threads = canopy, threads

    def build(self, vertices, triangles):
        self.scene = self.canopy.Scene(threads=self.threads)
        self.scene.add_mesh(vertices, triangles)

    def prepare(self, origins, directions):
        return np.ascontiguousarray(np.concatenate([origins, directions], axis=1), np.float32)

    def closest(self, rays):
        return self.scene.intersect(rays)["triangle"].astype(np.int64)

    def any(self, rays):
        return self.scene.occluded(rays)


class Open3DCaster:
    """open3d.t.geometry.RaycastingScene: cast_rays and test_occlusions on an (n, 6) float32 tensor. Its BVH is built
    on the first query, so build() casts one ray."""
    name = "open3d"

    def __init__(self, threads=0):
        import open3d
        self.o3d, self.threads = open3d, threads

    def build(self, vertices, triangles):
        self.scene = self.o3d.t.geometry.RaycastingScene()
        self.scene.add_triangles(self.o3d.core.Tensor(np.ascontiguousarray(vertices, np.float32)),
                                 self.o3d.core.Tensor(np.ascontiguousarray(triangles, np.uint32)))
        self.scene.cast_rays(self.o3d.core.Tensor(np.zeros((1, 6), np.float32)))

    def prepare(self, origins, directions):
        return self.o3d.core.Tensor(np.ascontiguousarray(np.concatenate([origins, directions], axis=1), np.float32))

    def closest(self, rays):
        ids = self.scene.cast_rays(rays, nthreads=self.threads)["primitive_ids"].numpy().astype(np.int64)
        ids[ids == self.o3d.t.geometry.RaycastingScene.INVALID_ID] = -1
        return ids

    def any(self, rays):
        return self.scene.test_occlusions(rays, nthreads=self.threads).numpy().astype(bool)


class EmbreexCaster:
    """embreex (Embree 2 under pyembree's API): EmbreeScene.run, closest by default, any with query='OCCLUDED'
    (which answers 0 for an occluded ray and -1 otherwise). The scene is committed on the first run, so build()
    casts one ray."""
    name = "embreex"

    def __init__(self, threads=0):
        from embreex import rtcore_scene
        from embreex.mesh_construction import TriangleMesh
        self.make_scene, self.make_mesh = rtcore_scene.EmbreeScene, TriangleMesh

    def build(self, vertices, triangles):
        self.scene = self.make_scene()
        self.mesh = self.make_mesh(scene=self.scene, vertices=np.ascontiguousarray(vertices, np.float32),
                                   indices=np.ascontiguousarray(triangles, np.int32))
        self.scene.run(np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32))

    def prepare(self, origins, directions):
        return np.ascontiguousarray(origins, np.float32), np.ascontiguousarray(directions, np.float32)

    def closest(self, rays):
        return np.asarray(self.scene.run(*rays), np.int64)

    def any(self, rays):
        return np.asarray(self.scene.run(*rays, query="OCCLUDED")) != -1


PEERS = {"open3d": Open3DCaster, "embreex": EmbreexCaster}


def make_caster(name, threads=0):
    """The caster of that name, or the reason it is unavailable (its import failed) as a string."""
    try:
        return PEERS[name](threads)
    except ImportError as error:
        return f"{name} does not import ({error})"


def centroid_ray(vertices, triangles):
    """A ray straight at the centroid of the largest triangle, from just above it, and that triangle's index."""
    corners = vertices[triangles].astype(np.float64)
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    largest = int(np.argmax(np.linalg.norm(normals, axis=1)))
    normal = normals[largest] / np.linalg.norm(normals[largest])
    size = np.linalg.norm(vertices.max(axis=0) - vertices.min(axis=0))
    origin = corners[largest].mean(axis=0) + 1e-3 * size * normal
    return origin[None].astype(np.float32), -normal[None].astype(np.float32), largest


def misses_everything(caster, vertices, triangles):
    """A warning when the caster misses a ray aimed straight at a triangle's centroid (Open3D with Debian's
    libembree3: ray mask 0), else None. Any hit at all will do: something may lie between origin and triangle."""
    origin, direction, _ = centroid_ray(vertices, triangles)
    if caster.closest(caster.prepare(origin, direction))[0] >= 0:
        return None
    return (f"WARNING: {caster.name} misses a ray aimed straight at a triangle's centroid, so it misses every ray "
            "and its times would be bogus. "
            + ("Debian's libembree3 is built with ray masks (EMBREE_RAY_MASK=ON) and Open3D 0.16 sets each ray's "
               "mask to 0, which no geometry matches. Open3D's own wheels link a bundled Embree built without ray "
               "masks (Embree's default) and do not have this problem." if caster.name == "open3d" else ""))


def ray_triangle_f64(origins, directions, corners):
    """Distances along the rays to the triangles' planes and the smallest barycentric weight there, in float64,
    pair by pair: (k, 3) origins and directions, (k, 3, 3) corners."""
    o, d, c = (np.asarray(a, np.float64) for a in (origins, directions, corners))
    normal = np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.einsum("ij,ij->i", normal, c[:, 0] - o) / np.einsum("ij,ij->i", normal, d)
        point = o + t[:, None] * d
        area = np.einsum("ij,ij->i", normal, normal)
        weights = [np.einsum("ij,ij->i", np.cross(c[:, (i + 2) % 3] - c[:, (i + 1) % 3], point - c[:, (i + 1) % 3]),
                             normal) / area for i in range(3)]
    return t, np.minimum(np.minimum(weights[0], weights[1]), weights[2])


def grazes(vertices, triangles, origins, directions, triangle):
    """Whether each ray passes within EDGE_MARGIN of an edge of its triangle, or meets it at t near 0: where float32
    kernels may find the hit or not."""
    t, smallest = ray_triangle_f64(origins, directions, vertices[triangles[triangle]])
    size = np.linalg.norm(vertices.max(axis=0) - vertices.min(axis=0))
    return (np.abs(smallest) < EDGE_MARGIN) | (np.abs(t) * np.linalg.norm(directions, axis=1) < 1e-4 * size)


def compare_closest(vertices, triangles, origins, directions, ours, theirs):
    """Counts of agreement between two closest-hit answers (triangle per ray, -1 a miss), with disagreements
    checked in float64: 'ties' (both triangles as far along the ray) and 'grazes' set apart from 'unexplained'."""
    vertices = np.asarray(vertices, np.float64)
    triangles = np.asarray(triangles, np.int64)
    hit_miss = (ours >= 0) != (theirs >= 0)
    both = (ours >= 0) & (theirs >= 0) & (ours != theirs)
    ties = np.zeros(len(ours), bool)
    explained = np.zeros(len(ours), bool)
    rays = np.flatnonzero(both)
    if len(rays):
        o, d = origins[rays], directions[rays]
        t_ours, _ = ray_triangle_f64(o, d, vertices[triangles[ours[rays]]])
        t_theirs, _ = ray_triangle_f64(o, d, vertices[triangles[theirs[rays]]])
        ties[rays] = np.abs(t_ours - t_theirs) <= T_MARGIN * np.maximum(np.abs(t_ours), np.abs(t_theirs))
        explained[rays] = (grazes(vertices, triangles, o, d, ours[rays])
                           | grazes(vertices, triangles, o, d, theirs[rays]))
    rays = np.flatnonzero(hit_miss)
    if len(rays):
        hitter = np.where(ours[rays] >= 0, ours[rays], theirs[rays])
        explained[rays] = grazes(vertices, triangles, origins[rays], directions[rays], hitter)
    grazed = explained & ~ties
    return {"rays": len(ours), "hit_miss_agree": int(np.sum(~hit_miss)), "hit_miss_disagree": int(hit_miss.sum()),
            "triangle_agree": int(np.sum((ours == theirs) & (ours >= 0))), "triangle_disagree": int(both.sum()),
            "ties": int(ties.sum()), "grazes": int(grazed.sum()),
            "unexplained": int(np.sum((hit_miss | both) & ~ties & ~grazed))}


def compare_any(vertices, triangles, origins, directions, ours, theirs, ours_closest, theirs_closest):
    """Counts of agreement between two any-hit answers; a disagreement is a graze when the closest triangle of the
    caster that hit grazes the ray."""
    vertices = np.asarray(vertices, np.float64)
    triangles = np.asarray(triangles, np.int64)
    differ = np.flatnonzero(ours != theirs)
    hitter = np.where(ours[differ], ours_closest[differ], theirs_closest[differ])
    known = hitter >= 0  # a caster whose any hit has no closest hit is unexplained
    grazed = np.zeros(len(differ), bool)
    grazed[known] = grazes(vertices, triangles, origins[differ[known]], directions[differ[known]], hitter[known])
    return {"rays": len(ours), "agree": int(len(ours) - len(differ)), "disagree": len(differ),
            "grazes": int(grazed.sum()), "unexplained": int(len(differ) - grazed.sum())}


def median_seconds(work, repeats):
    """The median wall time of `repeats` calls of work(), and the last call's result."""
    times, result = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        result = work()
        times.append(time.perf_counter() - start)
    return statistics.median(times), result


def measure(caster, vertices, triangles, batches, repeats):
    """Build time, and per batch the closest and any times and answers, of one caster."""
    build, _ = median_seconds(lambda: caster.build(vertices, triangles), repeats)
    results = []
    for origins, directions in batches:
        rays = caster.prepare(origins, directions)
        closest_s, closest = median_seconds(lambda: caster.closest(rays), repeats)
        any_s, any_hit = median_seconds(lambda: caster.any(rays), repeats)
        results.append({"closest_s": closest_s, "closest": closest, "any_s": any_s, "any": any_hit})
    return build, results


def print_times(rows, counts):
    """The table of times: build once a caster, then a line per caster and batch, with canopy's time over each."""
    print(f"{'caster':>8} {'build ms':>9} {'rays':>9} {'closest ms':>11} {'any ms':>8} {'Mrays/s':>8} "
          f"{'canopy/peer build':>18} {'closest':>8} {'any':>6}")
    canopy_build, canopy_results = rows["canopy"]
    for name, (build, results) in rows.items():
        for count, result, mine in zip(counts, results, canopy_results):
            ratios = (f"{'-':>18} {'-':>8} {'-':>6}" if name == "canopy" else
                      f"{canopy_build / build:18.2f} {mine['closest_s'] / result['closest_s']:8.2f} "
                      f"{mine['any_s'] / result['any_s']:6.2f}")
            print(f"{name:>8} {1e3 * build:9.1f} {count:9d} {1e3 * result['closest_s']:11.1f} "
                  f"{1e3 * result['any_s']:8.1f} {count / result['closest_s'] / 1e6:8.2f} {ratios}")


def print_agreement(name, count, closest, any_hit):
    print(f"{name} vs canopy, {count} rays: closest hit/miss agree {closest['hit_miss_agree']}/{closest['rays']}, "
          f"same triangle {closest['triangle_agree']} (different: {closest['triangle_disagree']}); of the "
          f"disagreements {closest['ties']} ties, {closest['grazes']} grazes, {closest['unexplained']} unexplained. "
          f"Any hit agree {any_hit['agree']}/{any_hit['rays']}, {any_hit['grazes']} grazes, "
          f"{any_hit['unexplained']} unexplained.")


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("scene", help=".obj, .gltf, scene.json or gen:NAME?tris=N")
    parser.add_argument("--rays", default="1000000,4000000", help="comma-separated batch sizes")
    parser.add_argument("--repeats", type=int, default=3, help="builds and casts a caster does, the median reported")
    parser.add_argument("--threads", type=int, default=0, help="canopy's and Open3D's threads, 0 for all")
    parser.add_argument("--peers", default=",".join(PEERS), help="comma-separated: " + ", ".join(PEERS))
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()

    import canopy
    vertices, triangles = canopy.load_triangles(args.scene)
    counts = [int(c) for c in args.rays.split(",")]
    batches = [random_rays(vertices, count, args.seed + i) for i, count in enumerate(counts)]
    print(f"{args.scene}: {len(triangles)} triangles; batches of {', '.join(map(str, counts))} random rays; "
          f"median of {args.repeats}")
    casters = [CanopyCaster(args.threads)]
    for name in args.peers.split(","):
        caster = make_caster(name, args.threads)
        if isinstance(caster, str):
            print(f"skipped: {caster}")
            continue
        caster.build(vertices, triangles)
        warning = misses_everything(caster, vertices, triangles)
        if warning:
            print(warning)
            continue
        casters.append(caster)
    rows = {caster.name: measure(caster, vertices, triangles, batches, args.repeats) for caster in casters}
    print_times(rows, counts)
    for name, (_, results) in rows.items():
        if name == "canopy":
            continue
        for count, (origins, directions), mine, theirs in zip(counts, batches, rows["canopy"][1], results):
            closest = compare_closest(vertices, triangles, origins, directions, mine["closest"], theirs["closest"])
            any_hit = compare_any(vertices, triangles, origins, directions, mine["any"], theirs["any"],
                                  mine["closest"], theirs["closest"])
            print_agreement(name, count, closest, any_hit)
    if len(rows) == 1:
        print("no working peer to compare with (see above): canopy's times alone", file=sys.stderr)


if __name__ == "__main__":
    main()
