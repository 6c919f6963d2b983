"""Float64 numpy oracles for canopy's ray and point queries, and meshes generated in numpy to run them on.

- all_hits: every hit of every ray on every triangle (t, triangle, u, v), ordered by t along each ray, with the rays
  whose answer a float32 kernel may round either way flagged: a triangle edge within EDGE_MARGIN (barycentric) of
  the ray, a hit within T_MARGIN of tmin or tmax, or two hits so close that their order is a toss-up.
- closest_points: the closest point on any triangle to each point (Ericson, Real-Time Collision Detection, 5.1.5).
- inside_by_parity: whether points are inside closed meshes, by counting crossings along random rays.
- torus, icosphere, scattered_triangles, stack_meshes: small scenes; torus and icosphere are closed and outward.

Everything is vectorised over chunks, so that a few thousand triangles against 100 k rays or points take seconds.
Nothing here imports canopy: this is what canopy is checked against."""
import numpy as np

EDGE_MARGIN = 1e-4  # barycentric distance from an edge below which float32 kernels may decide either way
T_MARGIN = 1e-4  # relative distance (to the ray's scale) from tmin, tmax or another hit that is a toss-up
GRAZING_COSINE = 1e-2  # below this |cos| between ray and normal, float32 barycentrics lose digits: widen the margin
CANDIDATE_MARGIN = 1e-2  # the widest edge margin a grazing ray gets; pairs further outside are plain misses


def as_rays(origins, directions):
    """(n, 3) float64 origins and directions from anything shaped (..., 3)."""
    origins = np.asarray(origins, np.float64).reshape(-1, 3)
    directions = np.asarray(directions, np.float64).reshape(-1, 3)
    if origins.shape != directions.shape:
        raise ValueError(f"origins {origins.shape} and directions {directions.shape} differ")
    return origins, directions


def triangle_corners(vertices, triangles):
    """(m, 3, 3) float64 corners of the triangles."""
    return np.asarray(vertices, np.float64)[np.asarray(triangles, np.int64).reshape(-1, 3)]


def edge_lines(corners):
    """(3, m, 6) Plücker lines [a x b, b - a] of the edge opposite each vertex (v1->v2, v2->v0, v0->v1).

    A ray's [d, o x d] dotted with the line opposite vertex i is d . ((a - x) x (b - x)) for any point x on the ray:
    proportional to the barycentric weight of vertex i where the ray meets the plane, the same factor for all three."""
    lines = []
    for i in range(3):
        a, b = corners[:, (i + 1) % 3], corners[:, (i + 2) % 3]
        lines.append(np.concatenate([np.cross(a, b), b - a], axis=1))
    return np.stack(lines)


def ray_lines(origins, directions):
    """(n, 6) Plücker coordinates [d, o x d] of the rays."""
    return np.concatenate([directions, np.cross(origins, directions)], axis=1)


def candidate_pairs(rays6, lines, margin=CANDIDATE_MARGIN):
    """Ray and triangle indices, and the three barycentric weights, of pairs whose line meets the triangle or passes
    within `margin` (barycentric) of it: three matrix products, then one sparse selection. In place where it can be:
    the arrays are rays x triangles."""
    with np.errstate(divide="ignore", invalid="ignore"):  # NaN from a non-finite ray, inf from a parallel plane
        sides = [rays6 @ lines[i].T for i in range(3)]
        scale = sides[0] + sides[1]
        scale += sides[2]
        np.divide(1.0, scale, out=scale)
        for side in sides:
            side *= scale
        smallest = np.minimum(sides[0], sides[1])
        np.minimum(smallest, sides[2], out=smallest)
        ray, triangle = np.nonzero(smallest > -margin)  # NaN is never selected
    return ray, triangle, np.stack([side[ray, triangle] for side in sides], axis=1)


def ray_scale(origins, directions, extent):
    """The size of float32 rounding in t, up to a constant: coordinates' magnitude over the direction's length."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return (np.linalg.norm(origins, axis=1) + extent) / np.linalg.norm(directions, axis=1)


def all_hits(vertices, triangles, origins, directions, tmin=0.0, tmax=np.inf, chunk=1024):
    """Every hit in (tmin, tmax] of every ray on every triangle, by Plücker edge tests and plane distances in float64.

    Returns a dict: 'offsets' (n+1,) int64 into the hits; per hit 'ray', 'triangle' int64 and 't', 'u', 'v' float64
    (u, v: the weights of each triangle's 2nd and 3rd vertex), ordered by ray, then t; per ray 'uncertain' (a float32
    kernel may find or miss one of its hits: an edge within EDGE_MARGIN, or a hit within T_MARGIN of tmin or tmax)
    and 'tied' (two of its hits within T_MARGIN of each other: their order, and so the closest triangle, is a
    toss-up). A ray with a non-finite component hits nothing and is certain."""
    origins, directions = as_rays(origins, directions)
    count = len(origins)
    rays = {"origins": origins, "directions": directions,
            "tmin": np.broadcast_to(np.ravel(np.asarray(tmin, np.float64)), (count,)),
            "tmax": np.broadcast_to(np.ravel(np.asarray(tmax, np.float64)), (count,))}
    corners = triangle_corners(vertices, triangles)
    mesh = {"corners": corners, "lines": edge_lines(corners),
            "normals": np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])}
    extent = float(np.abs(corners).max()) if len(corners) else 1.0
    rays["margin_t"] = T_MARGIN * ray_scale(origins, directions, extent)
    uncertain = np.zeros(count, bool)
    parts = []
    for start in range(0, count, chunk):
        hits, unsure = hits_in_chunk(mesh, rays, start, min(start + chunk, count))
        parts.append(hits)
        uncertain[unsure] = True
    ray, triangle, t, u, v = (np.concatenate(column) for column in zip(*parts)) if parts else [np.zeros(0)] * 5
    order = np.lexsort((t, ray))
    ray, triangle, t, u, v = ray[order].astype(np.int64), triangle[order].astype(np.int64), t[order], u[order], v[order]
    offsets = np.searchsorted(ray, np.arange(count + 1)).astype(np.int64)
    same_ray = ray[1:] == ray[:-1]
    tied = np.zeros(count, bool)
    tied[ray[1:][same_ray & (t[1:] - t[:-1] <= rays["margin_t"][ray[1:]])]] = True
    return {"offsets": offsets, "ray": ray, "triangle": triangle, "t": t, "u": u, "v": v,
            "uncertain": uncertain, "tied": tied}


def hits_in_chunk(mesh, rays, start, stop):
    """The hits (ray, triangle, t, u, v) of rays start to stop, and the indices of those of them that are uncertain."""
    ray, triangle, weights = candidate_pairs(
        ray_lines(rays["origins"][start:stop], rays["directions"][start:stop]), mesh["lines"])
    ray += start
    o, d, n = rays["origins"][ray], rays["directions"][ray], mesh["normals"][triangle]
    tmin, tmax, margin_t = rays["tmin"][ray], rays["tmax"][ray], rays["margin_t"][ray]
    facing = np.sum(n * d, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):  # a ray in a triangle's plane: t and cosine are inf, 0
        t = np.sum(n * (mesh["corners"][triangle, 0] - o), axis=1) / facing
        cosine = np.abs(facing) / (np.linalg.norm(n, axis=1) * np.linalg.norm(d, axis=1))
        edge_margin = np.minimum(EDGE_MARGIN * np.maximum(1.0, GRAZING_COSINE / cosine), CANDIDATE_MARGIN)
    smallest = weights.min(axis=1)
    near_range = (t > tmin - margin_t) & (t <= tmax + margin_t)
    near_end = (np.abs(t - tmin) <= margin_t) | (np.abs(t - tmax) <= margin_t)
    grazing = (np.abs(smallest) < edge_margin) | ((smallest > 0) & near_end)
    hit = (smallest > 0) & (t > tmin) & (t <= tmax)
    return (ray[hit], triangle[hit], t[hit], weights[hit, 1], weights[hit, 2]), ray[grazing & near_range]


def hit_counts(hits):
    """How many hits each ray has."""
    return np.diff(hits["offsets"])


def closest_hits(hits):
    """Each ray's first hit: t (inf for a miss), triangle (-1), u, v (0)."""
    count = len(hits["offsets"]) - 1
    has = hit_counts(hits) > 0
    first = hits["offsets"][:-1][has]
    t, triangle = np.full(count, np.inf), np.full(count, -1, np.int64)
    u, v = np.zeros(count), np.zeros(count)
    t[has], triangle[has], u[has], v[has] = (hits[k][first] for k in ("t", "triangle", "u", "v"))
    return {"t": t, "triangle": triangle, "u": u, "v": v}


def unit_normals(vertices, triangles):
    """(m, 3) unit geometric normals (v1 - v0) x (v2 - v0)."""
    corners = triangle_corners(vertices, triangles)
    n = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def closest_point_on_triangles(p, a, b, c):
    """Closest points on triangles (a, b, c) to points p, all (k, 3) float64, pair by pair (Ericson 5.1.5, with each
    Voronoi region's test vectorised and the first region that holds winning, as in the book's early returns).
    Returns the points and the barycentric weights (u, v) of b and c."""
    ab, ac, ap, bp, cp = b - a, c - a, p - a, p - b, p - c

    def dot(x, y):
        return np.einsum("ij,ij->i", x, y)
    d1, d2, d3, d4, d5, d6 = dot(ab, ap), dot(ac, ap), dot(ab, bp), dot(ac, bp), dot(ab, cp), dot(ac, cp)
    vc, vb, va = d1 * d4 - d3 * d2, d5 * d2 - d1 * d6, d3 * d6 - d5 * d4
    with np.errstate(divide="ignore", invalid="ignore"):
        on_ab = d1 / (d1 - d3)
        on_ac = d2 / (d2 - d6)
        on_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        inside = 1.0 / (va + vb + vc)
    regions = [(d1 <= 0) & (d2 <= 0),  # vertex a
               (d3 >= 0) & (d4 <= d3),  # vertex b
               (vc <= 0) & (d1 >= 0) & (d3 <= 0),  # edge ab
               (d6 >= 0) & (d5 <= d6),  # vertex c
               (vb <= 0) & (d2 >= 0) & (d6 <= 0),  # edge ac
               (va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0)]  # edge bc
    zero, one = np.zeros_like(d1), np.ones_like(d1)
    u = np.select(regions, [zero, one, on_ab, zero, zero, 1 - on_bc], vb * inside)
    v = np.select(regions, [zero, zero, zero, one, on_ac, on_bc], vc * inside)
    return a + u[:, None] * ab + v[:, None] * ac, u, v


def closest_points(vertices, triangles, points, chunk=1024):
    """The closest point on any triangle to each point: dict 'point' (n, 3), 'distance', 'triangle' int64, 'u', 'v'.

    Pairs are pruned first: a triangle lies no closer than its centroid's distance less its radius, and the nearest
    centroid (a point on its triangle) bounds the answer from above; Ericson's test runs on the rest."""
    points = np.asarray(points, np.float64).reshape(-1, 3)
    corners = triangle_corners(vertices, triangles)
    centre = 0.5 * (corners.reshape(-1, 3).min(axis=0) + corners.reshape(-1, 3).max(axis=0))
    corners = corners - centre  # small coordinates keep |p|^2 + |c|^2 - 2 p.c accurate
    centroids = corners.mean(axis=1)
    radius = np.linalg.norm(corners - centroids[:, None], axis=2).max(axis=1)
    slack = 1e-6 * (np.abs(corners).max() + 1.0)
    squared_centroids = np.sum(centroids ** 2, axis=1)
    out = {"point": np.zeros((len(points), 3)), "distance": np.zeros(len(points)),
           "triangle": np.zeros(len(points), np.int64), "u": np.zeros(len(points)), "v": np.zeros(len(points))}
    for start in range(0, len(points), chunk):
        p = points[start:start + chunk] - centre
        squared = np.sum(p ** 2, axis=1)[:, None] + squared_centroids[None] - 2.0 * (p @ centroids.T)
        to_centroid = np.sqrt(np.maximum(squared, 0.0))
        bound = to_centroid.min(axis=1)
        which, triangle = np.nonzero(to_centroid - radius <= bound[:, None] + slack)
        c = corners[triangle]
        q, u, v = closest_point_on_triangles(p[which], c[:, 0], c[:, 1], c[:, 2])
        distance = np.linalg.norm(p[which] - q, axis=1)
        order = np.lexsort((distance, which))
        best = order[np.searchsorted(which[order], np.arange(len(p)))]
        rows = slice(start, start + len(p))
        out["point"][rows] = q[best] + centre
        out["distance"][rows], out["triangle"][rows] = distance[best], triangle[best]
        out["u"][rows], out["v"][rows] = u[best], v[best]
    return out


def distance_to_triangle(vertices, triangles, points, triangle):
    """Each point's distance to one given triangle (an index per point): what a reported closest triangle must give."""
    corners = triangle_corners(vertices, triangles)[np.asarray(triangle, np.int64)]
    p = np.asarray(points, np.float64).reshape(-1, 3)
    q, _, _ = closest_point_on_triangles(p, corners[:, 0], corners[:, 1], corners[:, 2])
    return np.linalg.norm(p - q, axis=1)


def random_unit_vectors(rng, count):
    """Directions uniform on the sphere."""
    d = rng.normal(size=(count, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def inside_by_parity(vertices, triangles, points, seed=0, attempts=6):
    """Whether each point is inside the closed meshes: an odd number of crossings along a random ray. A point whose
    ray grazes an edge tries another direction. Returns (inside, decided); undecided points ran out of attempts."""
    points = np.asarray(points, np.float64).reshape(-1, 3)
    rng = np.random.default_rng(seed)
    inside, decided = np.zeros(len(points), bool), np.zeros(len(points), bool)
    pending = np.arange(len(points))
    for _ in range(attempts):
        if len(pending) == 0:
            break
        hits = all_hits(vertices, triangles, points[pending], random_unit_vectors(rng, len(pending)))
        sure = ~hits["uncertain"]
        inside[pending[sure]] = hit_counts(hits)[sure] % 2 == 1
        decided[pending[sure]] = True
        pending = pending[~sure]
    return inside, decided


def signed_volume(vertices, triangles):
    """The volume a closed mesh encloses, positive when its triangles face outwards."""
    c = triangle_corners(vertices, triangles)
    return float(np.sum(c[:, 0] * np.cross(c[:, 1], c[:, 2])) / 6.0)


def is_closed_and_oriented(triangles):
    """Whether every edge is shared by exactly two triangles that run it in opposite directions."""
    t = np.asarray(triangles, np.int64)
    directed = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    unique, counts = np.unique(directed, axis=0, return_counts=True)
    if np.any(counts != 1):
        return False
    reversed_edges = {tuple(e) for e in unique[:, ::-1]}
    return reversed_edges == {tuple(e) for e in unique}


def outward(vertices, triangles):
    """The triangles of a closed mesh, reversed if they face inwards."""
    triangles = np.asarray(triangles, np.int64)
    return triangles if signed_volume(vertices, triangles) > 0 else triangles[:, ::-1].copy()


def torus(major=0.6, minor=0.25, segments=32, rings=16, centre=(0.0, 0.0, 0.0)):
    """A closed, outward torus around the z axis: (segments * rings, 3) vertices, 2 * segments * rings triangles."""
    theta = 2 * np.pi * np.arange(segments) / segments
    phi = 2 * np.pi * np.arange(rings) / rings
    th, ph = np.meshgrid(theta, phi, indexing="ij")
    ring = major + minor * np.cos(ph)
    vertices = np.stack([ring * np.cos(th), ring * np.sin(th), minor * np.sin(ph)], axis=-1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(segments), np.arange(rings), indexing="ij")
    a = i * rings + j
    b = ((i + 1) % segments) * rings + j
    c = ((i + 1) % segments) * rings + (j + 1) % rings
    d = i * rings + (j + 1) % rings
    triangles = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    vertices = vertices + np.asarray(centre)
    return vertices, outward(vertices, triangles)


ICOSAHEDRON_FACES = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2),
                     (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5),
                     (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]


def icosphere(subdivisions=2, radius=0.3, centre=(0.0, 0.0, 0.0)):
    """A closed, outward icosphere: 20 * 4**subdivisions triangles."""
    g = (1 + 5 ** 0.5) / 2
    vertices = np.array([(-1, g, 0), (1, g, 0), (-1, -g, 0), (1, -g, 0), (0, -1, g), (0, 1, g), (0, -1, -g),
                         (0, 1, -g), (g, 0, -1), (g, 0, 1), (-g, 0, -1), (-g, 0, 1)], np.float64)
    triangles = np.array(ICOSAHEDRON_FACES, np.int64)
    for _ in range(subdivisions):
        # Each edge's midpoint once: the edges as sorted pairs, numbered by np.unique.
        edges = np.sort(np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]]), axis=1)
        unique, index = np.unique(edges, axis=0, return_inverse=True)
        middle = len(vertices) + index.reshape(3, -1)
        vertices = np.concatenate([vertices, 0.5 * (vertices[unique[:, 0]] + vertices[unique[:, 1]])])
        a, b, c = triangles.T
        ab, bc, ca = middle
        triangles = np.concatenate([np.stack(f, 1) for f in [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]])
    vertices = radius * vertices / np.linalg.norm(vertices, axis=1, keepdims=True) + np.asarray(centre)
    return vertices, outward(vertices, triangles)


def scattered_triangles(seed, count=200, grid=10, low=(-1.0, -1.0, -1.0), high=(1.0, 1.0, 1.0)):
    """An open mesh: small triangles of random orientation in a box, and a bumpy grid whose triangles share edges."""
    rng = np.random.default_rng(seed)
    low, high = np.asarray(low), np.asarray(high)
    size = high - low
    corners = rng.uniform(low, high, (count, 1, 3)) + rng.normal(0, 0.07, (count, 3, 3)) * size
    xs = np.linspace(0, 1, grid + 1)
    gx, gz = np.meshgrid(xs, xs)
    heights = 0.1 + 0.05 * rng.standard_normal(gx.shape)
    grid_vertices = low + np.stack([gx, heights, gz], axis=-1).reshape(-1, 3) * size
    quads = np.array([r * (grid + 1) + c for r in range(grid) for c in range(grid)])
    grid_triangles = np.concatenate([np.stack([quads, quads + 1, quads + grid + 2], axis=1),
                                     np.stack([quads, quads + grid + 2, quads + grid + 1], axis=1)])
    vertices = np.concatenate([corners.reshape(-1, 3), grid_vertices])
    triangles = np.concatenate([np.arange(3 * count).reshape(-1, 3), grid_triangles + 3 * count])
    return vertices, triangles


def stack_meshes(meshes):
    """One mesh of several: vertices, triangles, and each triangle's geometry (mesh) id and index within its mesh."""
    vertices, triangles, geometry, local = [], [], [], []
    base = 0
    for gid, (v, t) in enumerate(meshes):
        t = np.asarray(t, np.int64).reshape(-1, 3)
        vertices.append(np.asarray(v, np.float64).reshape(-1, 3))
        triangles.append(t + base)
        geometry.append(np.full(len(t), gid, np.int64))
        local.append(np.arange(len(t), dtype=np.int64))
        base += len(vertices[-1])
    return (np.concatenate(vertices), np.concatenate(triangles), np.concatenate(geometry), np.concatenate(local))
