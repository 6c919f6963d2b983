"""canopy.Scene's queries against the float64 numpy oracle of brute_force.py: closest hits, any hits, hit counts,
every hit along a ray, closest points, distances, signed distances and occupancy; and the batch rules: dtypes,
(..., 6) rays or origins and directions, image-shaped and empty batches, non-finite rays, strict mode, empty meshes.

The scene: a torus, an icosphere in its hole (both closed) and an open clutter of scattered triangles over a bumpy
grid, as three geometries; 100 k random rays and points. Rays the oracle flags as uncertain (a float32 kernel may
round them either way) are left out of exact comparisons."""
import numpy as np
import pytest

import brute_force as bf
import canopy

RAYS = 100_000
POINTS = 100_000


class World:
    """A scene of several meshes, its stacked float64 copy for the oracle, random rays and the oracle's hits."""

    def __init__(self, meshes, rays=0, seed=0):
        self.meshes = [(v.astype(np.float32), t.astype(np.uint32)) for v, t in meshes]
        self.vertices, self.triangles, self.geometry, self.local = bf.stack_meshes(self.meshes)
        self.base = np.cumsum([0] + [len(t) for _, t in self.meshes])  # global triangle index of each mesh's first
        self.low, self.high = self.vertices.min(axis=0), self.vertices.max(axis=0)
        self.size = float(np.linalg.norm(self.high - self.low))
        self.scene = scene_of(self.meshes)
        rng = np.random.default_rng(seed)
        self.origins, self.directions = random_rays(rng, self.low, self.high, rays)
        self.hits = bf.all_hits(self.vertices, self.triangles, self.origins, self.directions) if rays else None

    def global_index(self, geometry, triangle):
        """Triangle indices over the stacked meshes from (geometry id, triangle within it); -1 stays -1."""
        geometry, triangle = np.asarray(geometry), np.asarray(triangle)
        return np.where(triangle >= 0, self.base[np.maximum(geometry, 0)] + triangle, -1)


def scene_of(meshes, **options):
    """A Scene holding the meshes, checking that they are numbered 0, 1, ... as added."""
    scene = canopy.Scene(**options)
    ids = [scene.add_mesh(v, t) for v, t in meshes]
    assert ids == list(range(len(meshes)))
    return scene


def random_rays(rng, low, high, count):
    """float32 origins uniform in the box grown by a quarter, directions of random lengths (t is in their units)."""
    margin = 0.25 * (high - low)
    origins = rng.uniform(low - margin, high + margin, (count, 3))
    directions = bf.random_unit_vectors(rng, count) * rng.uniform(0.5, 2.0, (count, 1))
    return origins.astype(np.float32), directions.astype(np.float32)


def clutter():
    """Scattered triangles and a bumpy grid across the torus, an open mesh."""
    return bf.scattered_triangles(5, count=200, grid=10, low=(-1.2, -1.2, -0.6), high=(1.2, 1.2, 0.6))


@pytest.fixture(scope="module")
def world():
    return World([bf.torus(), bf.icosphere(2), clutter()], rays=RAYS, seed=1)


@pytest.fixture(scope="module")
def closed_world():
    return World([bf.torus(), bf.icosphere(2)])


def t_tolerance(world, origins, directions):
    """How far a float32 kernel's t may be from the exact one: 1e-5 of the coordinates' size over the direction."""
    extent = max(np.abs(world.low).max(), np.abs(world.high).max())
    return 1e-5 * bf.ray_scale(origins.astype(np.float64), directions.astype(np.float64), extent)


def expect_closest(world, hits, got, rays):
    """Compare intersect's answers with the oracle on the rays it is sure of (neither uncertain nor tied)."""
    want = bf.closest_hits(hits)
    sure = ~hits["uncertain"] & ~hits["tied"]
    assert sure.mean() > 0.99, "the oracle should decide nearly every ray"
    found = sure & (want["triangle"] >= 0)
    assert found.sum() > 0.05 * len(sure), "enough rays should hit"
    want_geometry = np.where(want["triangle"] >= 0, world.geometry[want["triangle"]], -1)
    want_local = np.where(want["triangle"] >= 0, world.local[want["triangle"]], -1)
    assert np.array_equal(got["geometry"][sure], want_geometry[sure])
    assert np.array_equal(got["triangle"][sure], want_local[sure])
    origins, directions = rays
    tolerance = 1e-5 * want["t"][found] + t_tolerance(world, origins, directions)[found]
    assert np.all(np.abs(got["t"][found] - want["t"][found]) <= tolerance)
    np.testing.assert_allclose(got["u"][found], want["u"][found], atol=1e-4)
    np.testing.assert_allclose(got["v"][found], want["v"][found], atol=1e-4)
    normals = bf.unit_normals(world.vertices, world.triangles)[want["triangle"][found]]
    np.testing.assert_allclose(got["normal"][found], normals, atol=1e-5)
    missed = got["triangle"] == -1
    assert np.all(np.isinf(got["t"][missed])) and np.all(got["geometry"][missed] == -1)
    assert np.all(got["normal"][missed] == 0)


def test_generated_meshes_are_closed_and_outward():
    for vertices, triangles in [bf.torus(), bf.icosphere(2)]:
        assert bf.is_closed_and_oriented(triangles)
        assert bf.signed_volume(vertices, triangles) > 0
    open_vertices, open_triangles = clutter()
    assert not bf.is_closed_and_oriented(open_triangles)


def test_the_oracle_agrees_with_moller_trumbore():
    """Two independent oracles, Plücker edges here and test_canopy's Möller–Trumbore, on rays both are sure of."""
    from test_canopy import brute_force as moller_trumbore, random_rays as canopy_rays, random_scene
    vertices, triangles = random_scene(11)
    origins, directions = canopy_rays(12, 3000)
    want_t, want_triangle, want_u, want_v, certain = moller_trumbore(vertices, triangles, origins, directions, 0.1, 2.0)
    hits = bf.all_hits(vertices, triangles, origins, directions, 0.1, 2.0)
    got = bf.closest_hits(hits)
    sure = certain & ~hits["uncertain"] & ~hits["tied"]
    assert sure.mean() > 0.99 and np.array_equal(got["triangle"][sure], want_triangle[sure])
    found = sure & (want_triangle >= 0)
    np.testing.assert_allclose(got["t"][found], want_t[found], rtol=1e-12)
    np.testing.assert_allclose(got["u"][found], want_u[found], atol=1e-12)
    np.testing.assert_allclose(got["v"][found], want_v[found], atol=1e-12)


def test_the_closest_point_oracle_is_no_farther_than_any_surface_sample():
    rng = np.random.default_rng(3)
    vertices, triangles, _, _ = bf.stack_meshes([bf.torus(), clutter()])
    points = rng.uniform(-1.5, 1.5, (200, 3))
    want = bf.closest_points(vertices, triangles, points)
    corners = bf.triangle_corners(vertices, triangles)
    a, b = rng.random((2, 100_000))
    a, b = np.where(a + b > 1, 1 - a, a), np.where(a + b > 1, 1 - b, b)
    areas = np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    c = corners[rng.choice(len(corners), len(a), p=areas / areas.sum())]
    samples = c[:, 0] + a[:, None] * (c[:, 1] - c[:, 0]) + b[:, None] * (c[:, 2] - c[:, 0])
    nearest_sample = np.sqrt(((points[:, None] - samples[None]) ** 2).sum(-1).min(axis=1))
    assert np.all(want["distance"] <= nearest_sample + 1e-12)
    gap = nearest_sample - want["distance"]
    assert np.median(gap) < 0.01 and gap.max() < 0.1, "the samples are dense enough to come close"
    c = corners[want["triangle"]]
    on_triangle = c[:, 0] + want["u"][:, None] * (c[:, 1] - c[:, 0]) + want["v"][:, None] * (c[:, 2] - c[:, 0])
    np.testing.assert_allclose(on_triangle, want["point"], atol=1e-12)


def test_intersect_matches_the_oracle(world):
    got = world.scene.intersect(world.origins, world.directions)
    for key, dtype in [("t", np.float32), ("triangle", np.int32), ("geometry", np.int32), ("u", np.float32),
                       ("v", np.float32)]:
        assert got[key].shape == (RAYS,) and got[key].dtype == dtype, key
    assert got["normal"].shape == (RAYS, 3) and got["normal"].dtype == np.float32
    assert set(got["geometry"]) == {-1, 0, 1, 2}, "every geometry is hit, and some rays miss"
    expect_closest(world, world.hits, got, (world.origins, world.directions))


def test_occluded_matches_the_oracle(world):
    got = world.scene.occluded(world.origins, world.directions)
    assert got.shape == (RAYS,) and got.dtype == np.bool_
    sure = ~world.hits["uncertain"]
    want = bf.hit_counts(world.hits) > 0
    assert np.array_equal(got[sure], want[sure])


def test_count_intersections_matches_the_oracle(world):
    got = world.scene.count_intersections(world.origins, world.directions)
    assert got.shape == (RAYS,) and got.dtype == np.int32
    sure = ~world.hits["uncertain"]
    want = bf.hit_counts(world.hits)
    assert want[sure].max() >= 4, "some rays cross several surfaces"
    assert np.array_equal(got[sure], want[sure])


def test_list_intersections_matches_the_oracle(world):
    got = world.scene.list_intersections(world.origins, world.directions)
    hits = world.hits
    assert got["offsets"].shape == (RAYS + 1,) and got["offsets"].dtype == np.int64 and got["offsets"][0] == 0
    counts = np.diff(got["offsets"])
    assert np.array_equal(counts, world.scene.count_intersections(world.origins, world.directions))
    assert np.array_equal(got["ray"], np.repeat(np.arange(RAYS), counts))
    for key, dtype in [("ray", np.int64), ("t", np.float32), ("triangle", np.int32), ("geometry", np.int32),
                       ("u", np.float32), ("v", np.float32)]:
        assert got[key].shape == (got["offsets"][-1],) and got[key].dtype == dtype, key
    same_ray = got["ray"][1:] == got["ray"][:-1]
    assert np.all(np.diff(got["t"])[same_ray] >= 0), "each ray's hits are ordered by t"
    # Rays the oracle is sure of have the same number of hits, so their hits line up one for one.
    sure = ~hits["uncertain"]
    assert np.array_equal(counts[sure], bf.hit_counts(hits)[sure])
    mine, theirs = sure[got["ray"]], sure[hits["ray"]]
    ordered = ~hits["tied"][hits["ray"][theirs]]  # tied hits may come in either order
    tolerance = 1e-5 * hits["t"][theirs] + t_tolerance(world, world.origins, world.directions)[hits["ray"][theirs]]
    assert np.all(np.abs(got["t"][mine] - hits["t"][theirs]) <= tolerance)
    got_global = world.global_index(got["geometry"][mine], got["triangle"][mine])
    assert np.array_equal(got_global[ordered], hits["triangle"][theirs][ordered])
    np.testing.assert_allclose(got["u"][mine][ordered], hits["u"][theirs][ordered], atol=1e-4)
    np.testing.assert_allclose(got["v"][mine][ordered], hits["v"][theirs][ordered], atol=1e-4)


def test_interval_ends_per_ray_and_as_numbers(world):
    rays = slice(0, 20_000)
    origins, directions = world.origins[rays], world.directions[rays]
    rng = np.random.default_rng(4)
    tmin = rng.uniform(0.0, 1.0, len(origins)).astype(np.float32)
    tmax = (tmin + rng.uniform(0.0, 2.0, len(origins))).astype(np.float32)
    for ends in [(tmin, tmax), (0.5, 1.5)]:
        hits = bf.all_hits(world.vertices, world.triangles, origins, directions, *ends)
        expect_closest(world, hits, world.scene.intersect(origins, directions, *ends), (origins, directions))
        sure = ~hits["uncertain"]
        want = bf.hit_counts(hits)
        assert np.array_equal(world.scene.occluded(origins, directions, *ends)[sure], want[sure] > 0)
        assert np.array_equal(world.scene.count_intersections(origins, directions, *ends)[sure], want[sure])
        listed = world.scene.list_intersections(origins, directions, *ends)
        assert np.array_equal(np.diff(listed["offsets"])[sure], want[sure])
    nothing = world.scene.intersect(origins, directions, tmin=0.0, tmax=0.0)
    assert np.all(nothing["triangle"] == -1), "the interval (0, 0] holds no hit"


def test_closest_points_match_the_oracle(world):
    points = np.random.default_rng(5).uniform(world.low - 0.2, world.high + 0.2, (POINTS, 3)).astype(np.float32)
    got = world.scene.closest_points(points)
    for key, shape, dtype in [("point", (POINTS, 3), np.float32), ("distance", (POINTS,), np.float32),
                              ("triangle", (POINTS,), np.int32), ("geometry", (POINTS,), np.int32),
                              ("u", (POINTS,), np.float32), ("v", (POINTS,), np.float32)]:
        assert got[key].shape == shape and got[key].dtype == dtype, key
    want = bf.closest_points(world.vertices, world.triangles, points)
    tolerance = 1e-6 * world.size
    np.testing.assert_allclose(got["distance"], want["distance"], rtol=0, atol=tolerance)
    np.testing.assert_allclose(world.scene.distance(points), want["distance"], rtol=0, atol=tolerance)
    # Several triangles may be as close (a shared edge or vertex, or two surfaces equally far), so the reported
    # triangle is checked for being as close as the oracle's, and the point for lying on it at (u, v).
    reported = world.global_index(got["geometry"], got["triangle"])
    assert np.all(reported >= 0)
    to_reported = bf.distance_to_triangle(world.vertices, world.triangles, points, reported)
    np.testing.assert_allclose(to_reported, want["distance"], rtol=0, atol=tolerance)
    corners = bf.triangle_corners(world.vertices, world.triangles)[reported]
    u, v = got["u"][:, None].astype(np.float64), got["v"][:, None].astype(np.float64)
    at_uv = corners[:, 0] + u * (corners[:, 1] - corners[:, 0]) + v * (corners[:, 2] - corners[:, 0])
    np.testing.assert_allclose(got["point"], at_uv, rtol=0, atol=tolerance)
    np.testing.assert_allclose(np.linalg.norm(got["point"] - points.astype(np.float64), axis=1), want["distance"],
                               rtol=0, atol=tolerance)
    same = reported == want["triangle"]
    assert same.mean() > 0.9
    np.testing.assert_allclose(got["point"][same], want["point"][same], rtol=0, atol=tolerance)


def test_signed_distance_and_occupancy_inside_and_outside_closed_meshes(closed_world):
    world = closed_world
    rng = np.random.default_rng(6)
    points = rng.uniform(world.low - 0.1, world.high + 0.1, (POINTS, 3)).astype(np.float32)
    inside, decided = bf.inside_by_parity(world.vertices, world.triangles, points, seed=7)
    distance = bf.closest_points(world.vertices, world.triangles, points)["distance"]
    clear = decided & (distance > 1e-4 * world.size)  # on or next to the surface, either answer is right
    assert clear.mean() > 0.95 and 0.1 < inside[clear].mean() < 0.9
    signed = world.scene.signed_distance(points)
    occupied = world.scene.occupancy(points)
    assert signed.shape == (POINTS,) and signed.dtype == np.float32
    assert occupied.shape == (POINTS,) and occupied.dtype == np.bool_
    assert np.array_equal(occupied[clear], inside[clear])
    assert np.array_equal(signed[clear] < 0, inside[clear])
    np.testing.assert_allclose(np.abs(signed[clear]), distance[clear], rtol=0, atol=1e-6 * world.size)


def all_answers(scene, rays, directions=None, tmin=0.0, tmax=np.inf):
    """Every ray query's answer on one batch, by name."""
    return {"intersect": scene.intersect(rays, directions, tmin, tmax),
            "occluded": scene.occluded(rays, directions, tmin, tmax),
            "count": scene.count_intersections(rays, directions, tmin, tmax),
            "list": scene.list_intersections(rays, directions, tmin, tmax)}


def assert_same_answers(got, want):
    """Exactly equal answers, key by key, including dtypes."""
    assert got.keys() == want.keys()
    for name in want:
        a, b = (got[name], want[name]) if isinstance(want[name], dict) else ({"": got[name]}, {"": want[name]})
        assert a.keys() == b.keys(), name
        for key in b:
            assert a[key].dtype == b[key].dtype and np.array_equal(a[key], b[key]), (name, key)


def test_float64_and_float32_input_give_the_same_answers(world):
    origins, directions = world.origins[:5000], world.directions[:5000]
    tmin = np.full(len(origins), 0.25, np.float32)
    want = all_answers(world.scene, origins, directions, tmin)
    assert_same_answers(all_answers(world.scene, origins.astype(np.float64), directions.astype(np.float64),
                                    tmin.astype(np.float64)), want)
    points = origins
    for query in ["closest_points", "distance", "signed_distance", "occupancy"]:
        a, b = getattr(world.scene, query)(points), getattr(world.scene, query)(points.astype(np.float64))
        assert_same_answers({query: a}, {query: b})


def test_rays_of_six_and_separate_origins_and_directions_agree(world):
    origins, directions = world.origins[:5000], world.directions[:5000]
    rays = np.concatenate([origins, directions], axis=1)
    assert_same_answers(all_answers(world.scene, rays, tmax=3.0),
                        all_answers(world.scene, origins, directions, tmax=3.0))


def test_image_shaped_batches_keep_their_shape(world):
    height, width = 40, 50
    origins, directions = world.origins[:height * width], world.directions[:height * width]
    rays = np.concatenate([origins, directions], axis=1)
    tmax = np.full((height, width), 2.0, np.float32)
    image = all_answers(world.scene, rays.reshape(height, width, 6), tmax=tmax)
    flat = all_answers(world.scene, rays, tmax=tmax.ravel())
    for key, value in image["intersect"].items():
        assert value.shape == (height, width) + flat["intersect"][key].shape[1:], key
        assert np.array_equal(value.reshape(flat["intersect"][key].shape), flat["intersect"][key]), key
    assert image["occluded"].shape == image["count"].shape == (height, width)
    assert np.array_equal(image["occluded"].ravel(), flat["occluded"])
    assert np.array_equal(image["count"].ravel(), flat["count"])
    assert_same_answers({"list": image["list"]}, {"list": flat["list"]})  # offsets over the flattened rays
    separate = world.scene.intersect(origins.reshape(height, width, 3), directions.reshape(height, width, 3), tmax=tmax)
    assert separate["t"].shape == (height, width) and np.array_equal(separate["t"], image["intersect"]["t"])
    points = origins.reshape(height, width, 3)
    closest = world.scene.closest_points(points)
    assert closest["point"].shape == (height, width, 3) and closest["distance"].shape == (height, width)
    assert np.array_equal(closest["distance"].ravel(), world.scene.closest_points(origins)["distance"])
    for query in ["distance", "signed_distance", "occupancy"]:
        answer = getattr(world.scene, query)(points)
        assert answer.shape == (height, width), query
        assert np.array_equal(answer.ravel(), getattr(world.scene, query)(origins)), query


@pytest.mark.parametrize("batch", [(0,), (3, 0)])
def test_empty_batches_return_empty_arrays(world, batch):
    rays = np.zeros(batch + (6,), np.float32)
    got = all_answers(world.scene, rays)
    for key, dtype in [("t", np.float32), ("triangle", np.int32), ("geometry", np.int32), ("u", np.float32),
                       ("v", np.float32)]:
        assert got["intersect"][key].shape == batch and got["intersect"][key].dtype == dtype, key
    assert got["intersect"]["normal"].shape == batch + (3,) and got["intersect"]["normal"].dtype == np.float32
    assert got["occluded"].shape == batch and got["occluded"].dtype == np.bool_
    assert got["count"].shape == batch and got["count"].dtype == np.int32
    assert np.array_equal(got["list"]["offsets"], np.zeros(1, np.int64)) and got["list"]["offsets"].dtype == np.int64
    for key, dtype in [("ray", np.int64), ("t", np.float32), ("triangle", np.int32), ("geometry", np.int32),
                       ("u", np.float32), ("v", np.float32)]:
        assert got["list"][key].shape == (0,) and got["list"][key].dtype == dtype, key
    separate = world.scene.intersect(np.zeros(batch + (3,), np.float64), np.zeros(batch + (3,), np.float64))
    assert separate["t"].shape == batch and separate["t"].dtype == np.float32
    points = np.zeros(batch + (3,), np.float32)
    closest = world.scene.closest_points(points)
    assert closest["point"].shape == batch + (3,) and closest["point"].dtype == np.float32
    for key, dtype in [("distance", np.float32), ("triangle", np.int32), ("geometry", np.int32)]:
        assert closest[key].shape == batch and closest[key].dtype == dtype, key
    for query, dtype in [("distance", np.float32), ("signed_distance", np.float32), ("occupancy", np.bool_)]:
        answer = getattr(world.scene, query)(points)
        assert answer.shape == batch and answer.dtype == dtype, query


def with_non_finite_rays(rays):
    """A copy with a NaN origin, an infinite direction and a NaN direction in three rays; their indices."""
    rays = rays.copy()
    broken = np.array([10, 20, 30])
    rays[10, 0], rays[20, 4], rays[30, 5] = np.nan, np.inf, np.nan
    return rays, broken


def test_a_non_finite_ray_misses_and_the_others_hit_as_before(world):
    count = 2000
    rays, broken = with_non_finite_rays(np.concatenate([world.origins[:count], world.directions[:count]], axis=1))
    got = all_answers(world.scene, rays)
    assert np.all(got["intersect"]["triangle"][broken] == -1) and np.all(np.isinf(got["intersect"]["t"][broken]))
    assert not got["occluded"][broken].any() and np.all(got["count"][broken] == 0)
    assert np.all(np.diff(got["list"]["offsets"])[broken] == 0)
    fine = np.setdiff1d(np.arange(count), broken)
    want = all_answers(world.scene, rays[fine])
    for name in ["occluded", "count"]:
        assert np.array_equal(got[name][fine], want[name]), name
    for key in want["intersect"]:
        assert np.array_equal(got["intersect"][key][fine], want["intersect"][key]), key
    hits = bf.all_hits(world.vertices, world.triangles, rays[:, :3], rays[:, 3:])
    expect_closest(world, hits, got["intersect"], (rays[:, :3], rays[:, 3:]))


@pytest.mark.parametrize("query", ["intersect", "occluded", "count_intersections", "list_intersections"])
def test_strict_mode_raises_value_errors_naming_the_argument(world, query):
    call = getattr(world.scene, query)
    rays = np.concatenate([world.origins[:100], world.directions[:100]], axis=1)
    bad_rays, _ = with_non_finite_rays(rays)
    with pytest.raises(ValueError, match="rays"):
        call(bad_rays, strict=True)
    with pytest.raises(ValueError, match="origins"):
        call(bad_rays[:, :3], rays[:, 3:], strict=True)
    with pytest.raises(ValueError, match="directions"):
        call(rays[:, :3], bad_rays[:, 3:], strict=True)
    with pytest.raises(ValueError, match="tmin"):
        call(rays, tmin=np.where(np.arange(100) == 7, np.nan, 0.0), strict=True)
    strict, lenient = call(rays, strict=True), call(rays)
    assert_same_answers({query: strict}, {query: lenient})


def test_an_empty_mesh_is_a_geometry_that_nothing_hits(world):
    empty = (np.zeros((0, 3), np.float32), np.zeros((0, 3), np.uint32))
    origins, directions = world.origins[:5000], world.directions[:5000]
    nothing = scene_of([empty])
    got = all_answers(nothing, origins, directions)
    assert np.all(got["intersect"]["triangle"] == -1) and np.all(got["intersect"]["geometry"] == -1)
    assert np.all(np.isinf(got["intersect"]["t"]))
    assert not got["occluded"].any() and not got["count"].any() and got["list"]["offsets"][-1] == 0
    # Before another mesh it takes id 0, and the other's hits name id 1.
    torus = World([bf.torus()])
    after_empty = scene_of([empty, torus.meshes[0]])
    alone = torus.scene.intersect(origins, directions)
    behind = after_empty.intersect(origins, directions)
    assert np.array_equal(behind["geometry"], np.where(alone["triangle"] >= 0, 1, -1))
    assert np.array_equal(behind["triangle"], alone["triangle"]) and np.array_equal(behind["t"], alone["t"])
