"""canopy.trimesh.RayMeshIntersector against the float64 oracle of brute_force.py, on a generated mesh and on shared
meshes (../shared/scenes; skipped where absent), and against trimesh's own pure-Python intersector where trimesh
imports. Rays the oracle flags as uncertain are left out of exact comparisons."""
import pathlib
import types

import numpy as np
import pytest

import brute_force as bf
import canopy
import canopy.trimesh

SHARED_SCENES = pathlib.Path(__file__).resolve().parents[3] / "shared" / "scenes"
RAYS = 400


def generated_mesh():
    """A torus and a clutter of open triangles across it, as one mesh."""
    clutter = bf.scattered_triangles(8, count=60, grid=6, low=(-1.0, -1.0, -0.4), high=(1.0, 1.0, 0.4))
    vertices, faces, _, _ = bf.stack_meshes([bf.torus(segments=24, rings=12), clutter])
    return vertices, faces


def shared_mesh(name):
    """A shared scene's world-space triangles, loaded through its scene.json; skips when the scene is absent."""
    path = SHARED_SCENES / name / "scene.json"
    if not path.exists():
        pytest.skip(f"{path} is absent")
    return canopy.load_triangles(str(path))


MESHES = {"generated": generated_mesh, "stanford-bunny": lambda: shared_mesh("stanford-bunny"),
          "cornell-box": lambda: shared_mesh("cornell-box")}


def rays_at(vertices, faces, count, seed):
    """Half the rays aimed at random surface points from around the mesh (so that they hit), half random."""
    rng = np.random.default_rng(seed)
    vertices = np.asarray(vertices, np.float64)
    low, high = vertices.min(axis=0), vertices.max(axis=0)
    origins = rng.uniform(low - 0.3 * (high - low), high + 0.3 * (high - low), (count, 3))
    corners = vertices[np.asarray(faces, np.int64)[rng.integers(0, len(faces), count)]]
    a, b = rng.random((2, count))
    a, b = np.where(a + b > 1, 1 - a, a), np.where(a + b > 1, 1 - b, b)
    edges = corners[:, 1:] - corners[:, :1]
    targets = corners[:, 0] + a[:, None] * edges[:, 0] + b[:, None] * edges[:, 1]
    directions = np.where(np.arange(count)[:, None] % 2 == 0, targets - origins, bf.random_unit_vectors(rng, count))
    return origins, directions


class Case:
    """A mesh object as trimesh's intersectors take it, the adapter on it, rays and the oracle's hits."""

    def __init__(self, name):
        vertices, faces = MESHES[name]()
        self.name = name
        self.mesh = types.SimpleNamespace(vertices=np.asarray(vertices, np.float64), faces=np.asarray(faces, np.int64))
        self.ray = canopy.trimesh.RayMeshIntersector(self.mesh)
        self.origins, self.directions = rays_at(self.mesh.vertices, self.mesh.faces, RAYS, seed=len(name))
        self.hits = bf.all_hits(self.mesh.vertices, self.mesh.faces, self.origins, self.directions)
        self.sure = ~self.hits["uncertain"]
        self.size = float(np.linalg.norm(np.ptp(self.mesh.vertices, axis=0)))
        assert self.sure.mean() > 0.95


@pytest.fixture(scope="module", params=list(MESHES))
def case(request):
    return Case(request.param)


def hits_of_ray(index_ray, values, ray):
    """The values of one ray's hits, in the order given."""
    return list(values[index_ray == ray])


def test_intersects_first_is_the_closest_triangle(case):
    got = case.ray.intersects_first(case.origins, case.directions)
    assert got.shape == (RAYS,) and got.dtype == np.int64
    want = bf.closest_hits(case.hits)["triangle"]
    sure = case.sure & ~case.hits["tied"]
    assert np.array_equal(got[sure], want[sure])
    assert (want[sure] >= 0).sum() > RAYS // 3, "enough rays hit"


def test_intersects_any_is_whether_a_ray_hits(case):
    got = case.ray.intersects_any(case.origins, case.directions)
    assert got.shape == (RAYS,) and got.dtype == np.bool_
    assert np.array_equal(got[case.sure], bf.hit_counts(case.hits)[case.sure] > 0)


def test_intersects_id_gives_every_hit_in_order_along_each_ray(case):
    index_tri, index_ray = case.ray.intersects_id(case.origins, case.directions, max_hits=None)
    assert index_tri.dtype == index_ray.dtype == np.int64 and index_tri.shape == index_ray.shape
    assert np.all(np.diff(index_ray) >= 0), "grouped by ray, in ascending order"
    hits = case.hits
    for ray in np.flatnonzero(case.sure):
        want = hits_of_ray(hits["ray"], hits["triangle"], ray)
        got = hits_of_ray(index_ray, index_tri, ray)
        if hits["tied"][ray]:
            assert sorted(got) == sorted(want)
        else:
            assert got == want, ray
    assert bf.hit_counts(hits)[case.sure].max() >= 2, "some rays cross several surfaces"


def test_intersects_id_with_locations_and_first_hits_only(case):
    index_tri, index_ray, locations = case.ray.intersects_id(case.origins, case.directions, multiple_hits=False,
                                                             return_locations=True)
    want = bf.closest_hits(case.hits)
    assert len(np.unique(index_ray)) == len(index_ray), "one hit a ray"
    assert np.array_equal(index_ray, np.flatnonzero(case.ray.intersects_any(case.origins, case.directions)))
    sure = (case.sure & ~case.hits["tied"])[index_ray]
    assert np.array_equal(index_tri[sure], want["triangle"][index_ray[sure]])
    assert locations.shape == (len(index_ray), 3) and locations.dtype == np.float64
    expected = case.origins[index_ray] + want["t"][index_ray][:, None] * case.directions[index_ray]
    np.testing.assert_allclose(locations[sure], expected[sure], rtol=0, atol=1e-6 * case.size)


@pytest.mark.parametrize("max_hits", [1, 2])
def test_max_hits_keeps_the_first_hits_of_each_ray(case, max_hits):
    all_tri, all_ray = case.ray.intersects_id(case.origins, case.directions, max_hits=None)
    index_tri, index_ray = case.ray.intersects_id(case.origins, case.directions, max_hits=max_hits)
    assert np.bincount(index_ray, minlength=RAYS).max() <= max_hits
    for ray in range(RAYS):
        assert hits_of_ray(index_ray, index_tri, ray) == hits_of_ray(all_ray, all_tri, ray)[:max_hits]


def test_intersects_location_gives_the_hit_points(case):
    locations, index_ray, index_tri = case.ray.intersects_location(case.origins, case.directions)
    assert locations.dtype == np.float64 and index_ray.dtype == index_tri.dtype == np.int64
    hits = case.hits
    # A tied ray meets two triangles at one point (coplanar overlaps: cornell-box), which is one location.
    sure = case.sure & ~hits["tied"]
    mine, theirs = sure[index_ray], sure[hits["ray"]]
    assert np.array_equal(index_ray[mine], hits["ray"][theirs])
    expected = case.origins[hits["ray"][theirs]] + hits["t"][theirs][:, None] * case.directions[hits["ray"][theirs]]
    np.testing.assert_allclose(locations[mine], expected, rtol=0, atol=1e-6 * case.size)


def test_contains_points_by_parity(case):
    if case.name != "generated":
        pytest.skip("only the generated torus is closed")
    vertices, faces = bf.torus()
    torus = types.SimpleNamespace(vertices=vertices, faces=faces)
    points = np.random.default_rng(9).uniform(-1.0, 1.0, (2000, 3)) * [1, 1, 0.4]
    inside, decided = bf.inside_by_parity(torus.vertices, torus.faces, points)
    clear = decided & (bf.closest_points(torus.vertices, torus.faces, points)["distance"] > 1e-4)
    got = canopy.trimesh.RayMeshIntersector(torus).contains_points(points)
    assert got.shape == (2000,) and got.dtype == np.bool_
    assert 0.1 < inside[clear].mean() < 0.9 and np.array_equal(got[clear], inside[clear])


def test_a_ray_through_a_shared_edge_has_one_location():
    square = types.SimpleNamespace(vertices=np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float64),
                                   faces=np.array([[0, 1, 2], [0, 2, 3]]))
    intersector = canopy.trimesh.RayMeshIntersector(square)
    origins, directions = np.array([[0.5, 0.5, 1.0]]), np.array([[0.0, 0.0, -1.0]])  # onto the diagonal
    locations, index_ray, index_tri = intersector.intersects_location(origins, directions)
    assert len(locations) == 1 and set(index_tri) <= {0, 1}
    np.testing.assert_allclose(locations[0], [0.5, 0.5, 0.0], atol=1e-12)
    assert intersector.intersects_first(origins, directions)[0] in (0, 1)


def test_empty_batches_and_bad_shapes():
    vertices, faces = bf.torus()
    intersector = canopy.trimesh.RayMeshIntersector(types.SimpleNamespace(vertices=vertices, faces=faces))
    nothing = np.zeros((0, 3))
    first = intersector.intersects_first(nothing, nothing)
    assert first.shape == (0,) and first.dtype == np.int64
    hit = intersector.intersects_any(nothing, nothing)
    assert hit.shape == (0,) and hit.dtype == np.bool_
    index_tri, index_ray = intersector.intersects_id(nothing, nothing)
    assert index_tri.shape == index_ray.shape == (0,) and index_tri.dtype == index_ray.dtype == np.int64
    locations, index_ray, index_tri = intersector.intersects_location(nothing, nothing)
    assert locations.shape == (0, 3) and locations.dtype == np.float64 and index_tri.shape == (0,)
    with pytest.raises(ValueError, match="must both be"):
        intersector.intersects_first(np.zeros((2, 3)), np.zeros((3, 3)))
    with pytest.raises(ValueError, match="points must be"):
        intersector.contains_points(np.zeros(3))


def test_a_new_vertex_array_rebuilds_the_scene():
    vertices, faces = bf.torus()
    mesh = types.SimpleNamespace(vertices=vertices, faces=faces)
    intersector = canopy.trimesh.RayMeshIntersector(mesh)
    origins, directions = np.array([[0.6, 0.0, 2.0]]), np.array([[0.0, 0.0, -1.0]])
    before = intersector.intersects_location(origins, directions)[0]
    mesh.vertices = vertices + [0.0, 0.0, 0.5]
    after = intersector.intersects_location(origins, directions)[0]
    np.testing.assert_allclose(after[:, 2], before[:, 2] + 0.5, atol=1e-6)


def test_against_trimesh_pure_python_intersector(case):
    trimesh = pytest.importorskip("trimesh")
    mesh = trimesh.Trimesh(case.mesh.vertices, case.mesh.faces, process=False)
    theirs = trimesh.ray.ray_triangle.RayMeshIntersector(mesh)
    mesh.ray = canopy.trimesh.RayMeshIntersector(mesh)
    sure = case.sure & ~case.hits["tied"]
    first = mesh.ray.intersects_first(case.origins, case.directions)
    assert np.array_equal(first[sure], theirs.intersects_first(case.origins, case.directions)[sure])
    assert np.array_equal(mesh.ray.intersects_any(case.origins, case.directions)[sure],
                          theirs.intersects_any(case.origins, case.directions)[sure])
    _, mine_ray, _ = mesh.ray.intersects_location(case.origins, case.directions)
    _, their_ray, _ = theirs.intersects_location(case.origins, case.directions)
    assert np.array_equal(np.bincount(mine_ray, minlength=RAYS)[sure], np.bincount(their_ray, minlength=RAYS)[sure])
