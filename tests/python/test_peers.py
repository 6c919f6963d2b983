"""canopy's hits against each Python peer of examples/python_peers.py that imports and works (Open3D's
RaycastingScene, embreex), on 50 k random rays over a shared mesh (a generated one where the shared scenes are
absent); skipped, with the reason, for a peer that does not import or that misses a ray aimed straight at a
triangle's centroid (Open3D 0.16 with Debian's libembree3, built with ray masks: Open3D sets every ray's mask to 0).
The comparison itself is tested too: canopy.Accel against canopy.Scene, and answers with known faults."""
import importlib.util
import pathlib

import numpy as np
import pytest

import brute_force as bf
import canopy

ROOT = pathlib.Path(__file__).resolve().parents[2]
SHARED_MESH = ROOT.parent / "shared" / "scenes" / "stanford-bunny" / "scene.json"
RAYS = 50_000


def load_example():
    """examples/python_peers.py as a module: the casters and the comparison live there, for the example's use too."""
    spec = importlib.util.spec_from_file_location("python_peers", ROOT / "examples" / "python_peers.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


peers = load_example()


class AccelCaster:
    """canopy.Accel as a caster: the single-mesh class, a second path to the same kernel."""
    name = "canopy.Accel"

    def build(self, vertices, triangles):
        self.accel = canopy.Accel(vertices, triangles, builder="sbvh")

    def prepare(self, origins, directions):
        return origins, directions

    def closest(self, rays):
        return self.accel.intersect(*rays)[1].astype(np.int64)

    def any(self, rays):
        return self.accel.occluded(*rays)


class BlindCaster:
    """A caster that misses every ray, as Open3D does with Debian's libembree3."""

    def __init__(self, name):
        self.name = name

    def prepare(self, origins, directions):
        return origins

    def closest(self, rays):
        return np.full(len(rays), -1, np.int64)


@pytest.fixture(scope="module")
def world():
    """A mesh, random rays over it, and canopy's closest and any hits."""
    if SHARED_MESH.exists():
        vertices, triangles = canopy.load_triangles(str(SHARED_MESH))
    else:
        v, t, _, _ = bf.stack_meshes([bf.torus(), bf.scattered_triangles(5)])
        vertices, triangles = v.astype(np.float32), t.astype(np.uint32)
    origins, directions = peers.random_rays(vertices, RAYS, seed=3)
    ours = peers.CanopyCaster()
    ours.build(vertices, triangles)
    rays = ours.prepare(origins, directions)
    return {"vertices": vertices, "triangles": triangles, "origins": origins, "directions": directions,
            "closest": ours.closest(rays), "any": ours.any(rays)}


def compare(world, caster):
    """The closest-hit and any-hit comparisons of a built caster with canopy."""
    rays = caster.prepare(world["origins"], world["directions"])
    closest, any_hit = caster.closest(rays), caster.any(rays)
    mesh_and_rays = (world["vertices"], world["triangles"], world["origins"], world["directions"])
    return (peers.compare_closest(*mesh_and_rays, world["closest"], closest),
            peers.compare_any(*mesh_and_rays, world["any"], any_hit, world["closest"], closest))


@pytest.mark.parametrize("name", list(peers.PEERS))
def test_a_working_peer_finds_the_same_hits(world, name):
    caster = peers.make_caster(name)
    if isinstance(caster, str):
        pytest.skip(caster)
    caster.build(world["vertices"], world["triangles"])
    warning = peers.misses_everything(caster, world["vertices"], world["triangles"])
    if warning:
        pytest.skip(warning)
    closest, any_hit = compare(world, caster)
    assert closest["hit_miss_agree"] + closest["hit_miss_disagree"] == RAYS
    assert (world["closest"] >= 0).sum() > RAYS // 10, "enough rays hit"
    # Float32 kernels may differ on rays within 1e-4 of an edge; beyond those, a handful in 50 k at most.
    assert closest["unexplained"] <= RAYS * 1e-4, closest
    assert any_hit["unexplained"] <= RAYS * 1e-4, any_hit


def test_canopy_accel_and_scene_agree(world):
    caster = AccelCaster()
    caster.build(world["vertices"], world["triangles"])
    closest, any_hit = compare(world, caster)
    assert closest["hit_miss_agree"] == RAYS and closest["unexplained"] == 0
    assert any_hit["agree"] == RAYS


def test_the_comparison_counts_faults(world):
    ours = world["closest"]
    hit = np.flatnonzero(ours >= 0)
    faulty = ours.copy()
    faulty[hit[:100]] = -1  # hits turned into misses
    faulty[hit[100:200]] = (ours[hit[100:200]] + len(world["triangles"]) // 2) % len(world["triangles"])
    mesh_and_rays = (world["vertices"], world["triangles"], world["origins"], world["directions"])
    closest = peers.compare_closest(*mesh_and_rays, ours, faulty)
    assert closest["hit_miss_disagree"] == 100 and closest["triangle_disagree"] == 100
    assert closest["unexplained"] >= 195, "faults far from any edge are not excused"
    any_hit = peers.compare_any(*mesh_and_rays, world["any"], faulty >= 0, ours, faulty)
    assert any_hit["disagree"] == 100 and any_hit["unexplained"] >= 95


def test_a_ray_across_a_shared_edge_is_a_tie():
    square = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32)
    triangles = np.array([[0, 1, 2], [0, 2, 3]], np.uint32)
    origins, directions = np.array([[0.5, 0.5, 1.0]], np.float32), np.array([[0.0, 0.0, -1.0]], np.float32)
    closest = peers.compare_closest(square, triangles, origins, directions, np.array([0]), np.array([1]))
    assert closest["ties"] == 1 and closest["unexplained"] == 0


def test_a_caster_that_misses_the_centroid_ray_is_flagged(world):
    warning = peers.misses_everything(BlindCaster("open3d"), world["vertices"], world["triangles"])
    assert warning and "ray mask" in warning and "EMBREE_RAY_MASK" in warning
    ours = peers.CanopyCaster()
    ours.build(world["vertices"], world["triangles"])
    assert peers.misses_everything(ours, world["vertices"], world["triangles"]) is None
