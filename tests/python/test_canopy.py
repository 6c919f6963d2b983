"""The Python module against a numpy brute-force oracle, and every kind of bad input.

Run by CTest (python_canopy) with PYTHONPATH set to the build's python directory."""
import numpy as np
import pytest

import canopy

KERNELS = ["bvh2", "bvh4", "bvh8"]


def random_scene(seed, scattered=300, grid=12):
    """Small triangles of random orientation in [-1, 1]^3, and a bumpy grid whose triangles share edges."""
    rng = np.random.default_rng(seed)
    corners = rng.uniform(-1, 1, (scattered, 1, 3)) + rng.normal(0, 0.15, (scattered, 3, 3))
    xs = np.linspace(-1, 1, grid + 1)
    gx, gz = np.meshgrid(xs, xs)
    heights = -0.5 + 0.1 * rng.standard_normal(gx.shape)
    grid_vertices = np.stack([gx, heights, gz], axis=-1).reshape(-1, 3)
    quads = np.array([(r * (grid + 1) + c) for r in range(grid) for c in range(grid)])
    grid_triangles = np.concatenate([np.stack([quads, quads + 1, quads + grid + 2], axis=1),
                                     np.stack([quads, quads + grid + 2, quads + grid + 1], axis=1)])
    vertices = np.concatenate([corners.reshape(-1, 3), grid_vertices]).astype(np.float32)
    triangles = np.concatenate([np.arange(3 * scattered).reshape(-1, 3), grid_triangles + 3 * scattered])
    return vertices, triangles.astype(np.uint32)


def random_rays(seed, count=2000):
    rng = np.random.default_rng(seed)
    origins = rng.uniform(-1.5, 1.5, (count, 3)).astype(np.float32)
    directions = rng.normal(size=(count, 3)).astype(np.float32)
    return origins, directions


def brute_force(vertices, triangles, origins, directions, tmin=0.0, tmax=np.inf):
    """Closest hits by Möller–Trumbore in float64 over every ray and triangle: t, triangle, u, v, and whether each
    ray's answer is certain: no triangle within 1e-4 (barycentric) of its edge on the ray, and no second hit within
    1e-4 (relative) of the closest. Only certain rays are compared: float32 kernels may round the others either way."""
    parts = [brute_force_chunk(vertices, triangles, origins[i:i + 256], directions[i:i + 256], tmin, tmax)
             for i in range(0, len(origins), 256)]
    return tuple(np.concatenate(column) for column in zip(*parts))


def brute_force_chunk(vertices, triangles, origins, directions, tmin, tmax):
    def dot(a, b):
        return np.sum(a * b, axis=-1)
    v = vertices.astype(np.float64)[triangles.astype(np.int64)][None]
    o = origins.astype(np.float64)[:, None, :]
    d = directions.astype(np.float64)[:, None, :]
    e1, e2 = v[:, :, 1] - v[:, :, 0], v[:, :, 2] - v[:, :, 0]
    s = o - v[:, :, 0]
    p, q = np.cross(d, e2), np.cross(s, e1)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / dot(e1, p)
        u, w, t = dot(s, p) * inv, dot(d, q) * inv, dot(e2, q) * inv
    edge = np.minimum(np.minimum(u, w), 1 - u - w)
    inside = (edge > 0) & (t > tmin) & (t <= tmax) & np.isfinite(t)
    close_to_edge = (np.abs(edge) < 1e-4) & (t > tmin - 1e-4) & (t <= tmax * (1 + 1e-4))
    hit_t = np.where(inside, t, np.inf)
    order = np.argsort(hit_t, axis=1)
    rows = np.arange(len(origins))
    best, second = order[:, 0], order[:, 1]
    closest, next_closest = hit_t[rows, best], hit_t[rows, second]
    found = np.isfinite(closest)
    with np.errstate(invalid="ignore"):  # inf - inf where no second triangle is hit
        separated = ~found | (next_closest - closest > 1e-4 * np.maximum(closest, 1e-3))
    certain = ~close_to_edge.any(axis=1) & separated & (~found | (closest > tmin + 1e-4))
    return (np.where(found, closest, np.inf), np.where(found, best, -1), np.where(found, u[rows, best], 0.0),
            np.where(found, w[rows, best], 0.0), certain)


def assert_matches_oracle(hits, oracle):
    t, triangle, u, v = hits
    want_t, want_triangle, want_u, want_v, certain = oracle
    assert certain.mean() > 0.9, "the oracle should decide most rays"
    assert np.array_equal(triangle[certain], want_triangle[certain])
    found = certain & (want_triangle >= 0)
    assert found.sum() > 100, "enough rays should hit"
    np.testing.assert_allclose(t[found], want_t[found], rtol=1e-4)
    np.testing.assert_allclose(u[found], want_u[found], atol=1e-3)
    np.testing.assert_allclose(v[found], want_v[found], atol=1e-3)
    assert np.all(np.isinf(t[triangle == -1])) and np.all(u[triangle == -1] == 0)


@pytest.fixture(scope="module")
def scene():
    vertices, triangles = random_scene(1)
    origins, directions = random_rays(2)
    return vertices, triangles, origins, directions, brute_force(vertices, triangles, origins, directions)


def test_builders_lists_the_registry():
    builders = canopy.builders()
    assert {"binned", "sweep", "lbvh", "sbvh", "bittner"} <= set(builders)
    assert all(b["description"] for b in builders.values())
    assert builders["sbvh"]["params"]["alpha"]["default"] == "0.001"
    assert builders["binned"]["params"] == {}


def test_builder_parameters_are_taken_and_checked(scene):
    vertices, triangles, origins, directions, oracle = scene
    accel = canopy.Accel(vertices, triangles, builder="esc:sa_max=8x")
    assert accel.stats()["builder"] == "esc:sa_max=8x"
    assert_matches_oracle(accel.intersect(origins, directions), oracle)
    with pytest.raises(ValueError, match="builder 'esc' has no parameter 'alpha'"):
        canopy.Accel(vertices, triangles, builder="esc:alpha=1")


@pytest.mark.parametrize("kernel", KERNELS)
@pytest.mark.parametrize("builder", [*canopy.builders(), "auto"])
def test_every_builder_and_kernel_finds_the_oracles_hits(scene, builder, kernel):
    vertices, triangles, origins, directions, oracle = scene
    accel = canopy.Accel(vertices, triangles, builder=builder, kernel=kernel)
    assert_matches_oracle(accel.intersect(origins, directions), oracle)


@pytest.mark.parametrize("robust", [True, False])
@pytest.mark.parametrize("watertight", [True, False])
def test_every_mode_finds_the_oracles_hits(scene, robust, watertight):
    vertices, triangles, origins, directions, oracle = scene
    accel = canopy.Accel(vertices, triangles, builder="binned", robust=robust, watertight=watertight)
    assert_matches_oracle(accel.intersect(origins, directions), oracle)


@pytest.mark.parametrize("seed", [3, 4, 5])
def test_other_random_scenes_and_rays(seed):
    vertices, triangles = random_scene(seed, scattered=500, grid=20)
    origins, directions = random_rays(seed + 100, 1500)
    accel = canopy.Accel(vertices, triangles, builder="sbvh", threads=1)
    assert_matches_oracle(accel.intersect(origins, directions), brute_force(vertices, triangles, origins, directions))


def rotation(axis, angle):
    x, y, z = np.asarray(axis) / np.linalg.norm(axis)
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c + x * x * (1 - c), x * y * (1 - c) - z * s, x * z * (1 - c) + y * s],
                     [y * x * (1 - c) + z * s, c + y * y * (1 - c), y * z * (1 - c) - x * s],
                     [z * x * (1 - c) - y * s, z * y * (1 - c) + x * s, c + z * z * (1 - c)]])


@pytest.mark.parametrize("toplevel", ["flat", "two-level", "rebraid"])
def test_instances_report_the_instance_and_its_mesh_triangle(toplevel):
    vertices, triangles = random_scene(6, scattered=100, grid=6)
    transforms = np.stack([np.hstack([0.6 * rotation((1, 2, 3), a), np.array([[dx], [0.2 * dx], [0.0]])])
                           for a, dx in [(0.0, -1.2), (0.7, 0.0), (2.0, 1.1)]]).astype(np.float32)
    world = [vertices.astype(np.float64) @ m[:, :3].T.astype(np.float64) + m[:, 3] for m in transforms]
    world_vertices = np.concatenate(world).astype(np.float32)
    world_triangles = np.concatenate([triangles + i * len(vertices) for i in range(len(transforms))])
    origins, directions = random_rays(7)
    origins *= 1.5
    want_t, want_world, want_u, want_v, certain = brute_force(world_vertices, world_triangles, origins, directions)
    accel = canopy.Accel(vertices, triangles, builder="binned", instances=transforms, toplevel=toplevel)
    t, triangle, u, v, instance = accel.intersect(origins, directions, with_instance=True)
    found = want_world >= 0
    assert certain.mean() > 0.9 and (certain & found).sum() > 100
    assert np.array_equal(instance[certain], np.where(found, want_world // len(triangles), -1)[certain])
    assert np.array_equal(triangle[certain], np.where(found, want_world % len(triangles), -1)[certain])
    np.testing.assert_allclose(t[certain & found], want_t[certain & found], rtol=1e-4)


def test_occluded_and_intervals_agree_with_closest_hits(scene):
    vertices, triangles, origins, directions, _ = scene
    accel = canopy.Accel(vertices, triangles, builder="binned")
    t, triangle, _, _ = accel.intersect(origins, directions)
    hit = triangle >= 0
    assert np.array_equal(accel.occluded(origins, directions), hit)
    # Nothing lies in front of a closest hit; the hit itself lies within an interval that reaches it.
    assert not accel.occluded(origins[hit], directions[hit], tmax=t[hit] * 0.999).any()
    assert accel.occluded(origins[hit], directions[hit], tmax=t[hit]).all()
    beyond = accel.intersect(origins[hit], directions[hit], tmin=t[hit])[0]
    assert np.all(beyond > t[hit])
    none = accel.intersect(origins, directions, tmax=0.0)[1]
    assert np.all(none == -1)


def test_every_input_layout_gives_the_same_hits(scene):
    vertices, triangles, origins, directions, _ = scene
    want = canopy.Accel(vertices, triangles, builder="binned").intersect(origins, directions)
    layouts = [(vertices.astype(np.float64), triangles.astype(np.int64)),
               (vertices, triangles.astype(np.int32)),
               (np.asfortranarray(vertices), triangles.astype(np.uint64)),
               (vertices.tolist(), triangles.tolist())]
    for v, tr in layouts:
        accel = canopy.Accel(v, tr, builder="binned")
        for o, d in [(origins, directions), (origins.astype(np.float64), np.asfortranarray(directions)),
                     (np.repeat(origins, 2, axis=0)[::2], directions)]:
            for got, expected in zip(accel.intersect(o, d), want):
                assert np.array_equal(got, expected)


def test_compressed_nodes_find_the_same_distances(scene):
    vertices, triangles, origins, directions, _ = scene
    standard = canopy.Accel(vertices, triangles, builder="binned", kernel="bvh8")
    compressed = canopy.Accel(vertices, triangles, builder="binned", kernel="bvh8", layout="compressed")
    t_standard, t_compressed = standard.intersect(origins, directions)[0], compressed.intersect(origins, directions)[0]
    assert np.array_equal(t_standard, t_compressed)
    assert compressed.stats()["bytes"] < standard.stats()["bytes"]


def test_lbvh_builds_the_direct_tree_unless_asked_to_collapse(scene):
    vertices, triangles, origins, directions, _ = scene
    direct = canopy.Accel(vertices, triangles, builder="lbvh", kernel="bvh8")
    collapsed = canopy.Accel(vertices, triangles, builder="lbvh", kernel="bvh8", collapse="optimal")
    assert direct.stats()["kernel"] == "bvh8 direct" and direct.stats()["sah"] is None
    assert collapsed.stats()["kernel"] == "bvh8" and collapsed.stats()["sah"] > 0
    assert np.array_equal(direct.intersect(origins, directions)[0], collapsed.intersect(origins, directions)[0])


def test_one_thread_and_all_threads_agree(scene):
    vertices, triangles, origins, directions, _ = scene
    one = canopy.Accel(vertices, triangles, builder="ploc", threads=1).intersect(origins, directions)
    all_threads = canopy.Accel(vertices, triangles, builder="ploc").intersect(origins, directions)
    for a, b in zip(one, all_threads):
        assert np.array_equal(a, b)


def test_stats(scene):
    vertices, triangles, *_ = scene
    stats = canopy.Accel(vertices, triangles, builder="sbvh", kernel="bvh4").stats()
    assert stats["builder"] == "sbvh" and stats["kernel"] == "bvh4"
    assert stats["triangles"] == len(triangles)
    assert stats["sah"] > 0 and stats["layout_sah"] > 0 and stats["build_ms"] > 0
    assert stats["nodes"] > 0 and stats["leaves"] > 0 and stats["bytes"] > 0
    assert stats["references_per_triangle"] >= 1 and stats["epo"] is None
    assert canopy.Accel(vertices, triangles, builder="binned").stats(epo=True)["epo"] > 0
    assert canopy.Accel(vertices, triangles).stats()["builder"] == "binned"  # the plain build by default
    chosen = canopy.Accel(vertices, triangles, builder="auto").stats()
    # "rebraid/binned", "bittner<lbvh": a top level before the builder, an optimiser's start tree after it.
    assert chosen["builder"].split("/")[-1].split("<")[0] in canopy.builders() and chosen["reason"]


def test_load_triangles(tmp_path):
    obj = tmp_path / "quad.obj"
    obj.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n")
    vertices, triangles = canopy.load_triangles(str(obj))
    assert vertices.shape == (6, 3) and vertices.dtype == np.float32
    assert triangles.shape == (2, 3) and triangles.dtype == np.uint32
    t, triangle, _, _ = canopy.Accel(vertices, triangles).intersect([[0.25, 0.5, 1.0]], [[0.0, 0.0, -1.0]])
    assert triangle[0] >= 0 and t[0] == pytest.approx(1.0)
    with pytest.raises(ValueError, match="no-such.obj"):
        canopy.load_triangles(str(tmp_path / "no-such.obj"))


GOOD_VERTICES = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
GOOD_TRIANGLES = np.array([[0, 1, 2]], np.uint32)


def build(vertices=GOOD_VERTICES, triangles=GOOD_TRIANGLES, **options):
    return canopy.Accel(vertices, triangles, **options)


def with_value(array, index, value=np.nan):
    array = array.copy()
    array[index] = value
    return array


BAD_BUILDS = [
    ({"vertices": GOOD_VERTICES[:, :2]}, r"vertices: shape \(3, 2\), expected \(n, 3\)"),
    ({"vertices": GOOD_VERTICES.ravel()}, r"vertices: shape \(9,\)"),
    ({"vertices": GOOD_VERTICES.astype(np.complex64)}, "vertices: dtype complex64"),
    ({"vertices": GOOD_VERTICES.astype(bool)}, "vertices: dtype bool"),
    ({"vertices": [["a", "b", "c"]]}, "vertices: dtype <U1"),
    ({"vertices": [[0, 0, 0], [1, 0]]}, "vertices: not an array of numbers"),
    ({"vertices": np.zeros((0, 3), np.float32)}, "vertices: empty"),
    ({"vertices": with_value(GOOD_VERTICES, (1, 2))}, r"vertices\[1\]: z is nan"),
    ({"vertices": with_value(GOOD_VERTICES, (1, 0), np.inf)}, r"vertices\[1\]: x is inf"),
    ({"triangles": GOOD_TRIANGLES.ravel()}, r"triangles: shape \(3,\), expected \(m, 3\)"),
    ({"triangles": GOOD_TRIANGLES.astype(np.float32)}, "triangles: dtype float32, expected uint32"),
    ({"triangles": np.zeros((0, 3), np.uint32)}, "triangles: empty"),
    ({"triangles": np.array([[0, 1, 3]], np.uint32)}, r"triangles\[0\]: vertex index 3 is out of range \(3 vertices\)"),
    ({"triangles": np.array([[0, 1, 2], [0, -1, 2]], np.int32)}, r"triangles\[1\]: vertex index -1 is negative"),
    ({"triangles": np.array([[0, 1, -7]], np.int64)}, r"triangles\[0\]: vertex index -7 is negative"),
    ({"triangles": np.array([[0, 1, 2**32 + 1]], np.uint64)}, r"triangles\[0\]: vertex index 4294967297 is out of range"),
    ({"triangles": np.array([[0, 1, 5]], np.int64)}, r"triangles\[0\]: vertex index 5 is out of range \(3 vertices\)"),
    ({"builder": "nosuch"}, "builder: unknown builder 'nosuch'"),
    ({"kernel": "bvh3"}, "kernel: unknown kernel 'bvh3'"),
    ({"toplevel": "treetop", "builder": "binned"}, "toplevel: unknown 'treetop'"),
    ({"toplevel": "rebraid", "builder": "auto"}, "toplevel: builder 'auto' chooses"),
    ({"threads": -1}, "threads: -1"),
    ({"layout": "tiny", "builder": "binned"}, "layout: unknown layout 'tiny'"),
    ({"collapse": "zigzag", "builder": "lbvh"}, "collapse: unknown collapse 'zigzag'"),
    ({"collapse": "direct", "builder": "binned"}, "collapse: collapse 'direct' is lbvh's wide tree"),
    ({"layout": "compressed", "builder": "binned", "kernel": "bvh4"}, "layout: compressed nodes take a named BVH builder, kernel bvh8 and a flat top level, not kernel bvh4"),
    ({"instances": np.zeros((2, 4, 4), np.float32)}, r"instances: shape \(2, 4, 4\), expected \(n, 3, 4\)"),
    ({"instances": np.zeros((0, 3, 4), np.float32)}, "instances: empty"),
    ({"instances": np.zeros((1, 3, 4), np.float32)}, r"instances\[0\].transform: singular"),
    ({"instances": with_value(np.eye(3, 4, dtype=np.float32)[None], (0, 1, 3))}, r"instances\[0\].transform: nan"),
]


@pytest.mark.parametrize("arguments, message", BAD_BUILDS)
def test_bad_builds_raise_value_errors_naming_the_argument(arguments, message):
    with pytest.raises(ValueError, match=message):
        build(**arguments)


RAYS = np.array([[0.2, 0.2, 1.0], [0.3, 0.3, 1.0]], np.float32)
DOWN = np.array([[0, 0, -1], [0, 0, -1]], np.float32)

BAD_QUERIES = [
    ({"origins": RAYS[:, :2]}, r"origins: shape \(2, 2\), expected \(n, 3\)"),
    ({"origins": np.zeros((0, 3), np.float32)}, "directions: 2 rays, origins 0"),
    ({"directions": DOWN[:1]}, "directions: 1 rays, origins 2"),
    ({"directions": DOWN.astype(np.complex128)}, "directions: dtype complex128"),
    ({"origins": with_value(RAYS, (1, 0))}, r"origins\[1\]: x is nan"),
    ({"directions": with_value(DOWN, (1, 2), -np.inf)}, r"directions\[1\]: z is -inf"),
    ({"tmin": np.nan}, "tmin: nan"),
    ({"tmax": np.array([1.0, np.nan])}, r"tmax\[1\]: nan"),
    ({"tmax": np.ones(3)}, r"tmax: shape \(3,\), expected a number or \(2,\)"),
    ({"tmin": np.ones((2, 1))}, r"tmin: shape \(2, 1\)"),
    ({"tmin": "near"}, "tmin: dtype <U4"),
]


@pytest.mark.parametrize("query", ["intersect", "occluded"])
@pytest.mark.parametrize("arguments, message", BAD_QUERIES)
def test_bad_queries_raise_value_errors_naming_the_argument(query, arguments, message):
    accel = build()
    call = {"origins": RAYS, "directions": DOWN, **arguments}
    with pytest.raises(ValueError, match=message):
        getattr(accel, query)(**call, strict=True)


def test_an_empty_batch_returns_empty_arrays(scene):
    accel = build()
    nothing = np.zeros((0, 3), np.float32)
    t, triangle, u, v = accel.intersect(nothing, nothing)
    for array, dtype in [(t, np.float32), (triangle, np.int32), (u, np.float32), (v, np.float32)]:
        assert array.shape == (0,) and array.dtype == dtype
    hit = accel.occluded(nothing, nothing, tmax=np.zeros(0, np.float32))
    assert hit.shape == (0,) and hit.dtype == np.bool_


@pytest.mark.parametrize("query", ["intersect", "occluded", "count_intersections", "list_intersections"])
def test_a_batch_too_large_for_memory_raises_a_value_error_naming_the_argument(query):
    scene = canopy.Scene()
    scene.add_mesh(GOOD_VERTICES, GOOD_TRIANGLES)
    rays = np.broadcast_to(np.zeros(6, np.float32), (3_000_000_000, 6))  # 72 GB once made contiguous
    with pytest.raises(ValueError, match=r"rays: cannot allocate a C-order float32 copy of shape \(3000000000, 6\)"):
        getattr(scene, query)(rays)
    origins = np.broadcast_to(np.zeros(3, np.float32), (3_000_000_000, 3))
    with pytest.raises(ValueError, match="origins: cannot allocate"):
        build().intersect(origins, origins)


def test_threads_share_a_scene_while_another_adds_meshes():
    """Concurrent first queries build once or more but answer alike; a mesh added meanwhile changes later answers
    only, and nothing a running query uses is freed under it."""
    from concurrent.futures import ThreadPoolExecutor
    vertices, triangles = random_scene(11)
    origins, directions = random_rays(12, count=20000)
    scene = canopy.Scene()
    scene.add_mesh(vertices, triangles)
    with ThreadPoolExecutor(4) as pool:
        first = list(pool.map(lambda _: scene.intersect(origins, directions)["t"], range(4)))
    for t in first[1:]:
        assert np.array_equal(t, first[0])
    moved = vertices + np.float32(0.01)

    def query_or_add(i):
        if i % 3 == 2:
            return scene.add_mesh(moved, triangles)
        return scene.intersect(origins, directions)["t"]

    with ThreadPoolExecutor(4) as pool:
        answers = list(pool.map(query_or_add, range(12)))
    for t in answers:
        if isinstance(t, np.ndarray):  # a closer hit can only appear where a mesh was added, never vanish
            assert np.all(t <= first[0])
    assert scene.meshes == 5
