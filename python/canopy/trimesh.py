"""trimesh's ray interface over a canopy Scene, for any object with `vertices` (n, 3) and `faces` (m, 3) arrays.

    import canopy.trimesh
    mesh.ray = canopy.trimesh.RayMeshIntersector(mesh)   # a trimesh.Trimesh, or anything with vertices and faces
    index_tri = mesh.ray.intersects_first(origins, directions)

The calls and their results follow trimesh.ray.ray_triangle and trimesh.ray.ray_pyembree: index arrays are int64
(as the pure-Python intersector returns them), locations (k, 3) float64, and several hits along a ray come in the
order they lie along it, the rays in ascending order. Rays cross the whole line from t = 0 on; directions need not be
unit length. Unlike trimesh's embree intersector, which moves each ray past a hit by a small offset and may so skip
a second surface very close behind the first, every triangle the ray crosses is reported. This module does not
import trimesh."""
import numpy as np

# trimesh merges hit locations that agree to 8 decimals (tol.merge = 1e-8) in intersects_location.
LOCATION_DECIMALS = 8


class RayMeshIntersector:
    """Ray queries on a mesh through canopy.Scene, with trimesh's RayMeshIntersector methods.

    The Scene is built on the first query and rebuilt when the mesh's hash (trimesh: its content), or its vertices
    or faces array, changes; other keyword arguments (builder, kernel, threads, ...) go to canopy.Scene."""

    def __init__(self, mesh, **scene_options):
        self.mesh = mesh
        self._scene_options = scene_options
        self._scene = None
        self._scene_key = None

    @property
    def scene(self):
        """The canopy.Scene over the mesh, built now if the mesh is new or has changed."""
        key = _mesh_key(self.mesh)
        if self._scene is None or key != self._scene_key:
            from ._canopy import Scene  # the compiled module; imported late so that this file loads on its own
            scene = Scene(**self._scene_options)
            scene.add_mesh(np.asarray(self.mesh.vertices, np.float64), np.asarray(self.mesh.faces, np.int64))
            self._scene, self._scene_key = scene, key
        return self._scene

    def intersects_first(self, ray_origins, ray_directions):
        """The index of the first triangle each ray hits.

        ray_origins, ray_directions: (n, 3) float. Returns (n,) int64, -1 where a ray hits nothing."""
        origins, directions = _rays(ray_origins, ray_directions)
        return self.scene.intersect(origins, directions)["triangle"].astype(np.int64)

    def intersects_any(self, ray_origins, ray_directions):
        """Whether each ray hits any triangle.

        ray_origins, ray_directions: (n, 3) float. Returns (n,) bool."""
        origins, directions = _rays(ray_origins, ray_directions)
        return np.asarray(self.scene.occluded(origins, directions), bool)

    def intersects_id(self, ray_origins, ray_directions, multiple_hits=True, max_hits=20, return_locations=False):
        """The triangles the rays hit.

        ray_origins, ray_directions: (n, 3) float; multiple_hits: every hit along each ray (True) or only the first;
        max_hits: at most this many hits a ray (None: no limit); return_locations: also return where the hits are.
        Returns index_tri (h,) int64, index_ray (h,) int64[, locations (h, 3) float64]: grouped by ray in ascending
        order, each ray's hits ordered along it. As trimesh's intersector does, a location shared by two triangles
        on one ray (a ray through an edge) is given once when locations are returned, and may be given for both
        triangles when they are not."""
        origins, directions = _rays(ray_origins, ray_directions)
        if multiple_hits:
            listed = self.scene.list_intersections(origins, directions)
            index_ray = listed["ray"].astype(np.int64)
            index_tri = listed["triangle"].astype(np.int64)
            t = listed["t"]
        else:
            closest = self.scene.intersect(origins, directions)
            index_ray = np.flatnonzero(closest["triangle"] >= 0).astype(np.int64)
            index_tri = closest["triangle"][index_ray].astype(np.int64)
            t = closest["t"][index_ray]
        locations = None
        if return_locations:
            locations = self._locations(origins, directions, index_ray, index_tri, t)
            keep = _first_of_each_location(locations, index_ray)
            index_ray, index_tri, locations = index_ray[keep], index_tri[keep], locations[keep]
        if max_hits is not None:
            keep = _rank_along_ray(index_ray) < max_hits
            index_ray, index_tri = index_ray[keep], index_tri[keep]
            locations = None if locations is None else locations[keep]
        return (index_tri, index_ray) if locations is None else (index_tri, index_ray, locations)

    def intersects_location(self, ray_origins, ray_directions, multiple_hits=True):
        """Where the rays hit the mesh, each location once a ray.

        Returns locations (h, 3) float64, index_ray (h,) int64, index_tri (h,) int64, ordered as intersects_id."""
        index_tri, index_ray, locations = self.intersects_id(ray_origins, ray_directions, multiple_hits=multiple_hits,
                                                             max_hits=None, return_locations=True)
        return locations, index_ray, index_tri

    def contains_points(self, points):
        """Whether each point is inside the mesh (by the parity of a ray's crossings; meaningful for closed meshes,
        undefined on the surface). points: (n, 3) float. Returns (n,) bool."""
        points = np.asarray(points, np.float64)
        if points.ndim != 2 or points.shape[1] != 3:
            raise ValueError(f"points must be (n, 3), not {points.shape}")
        return np.asarray(self.scene.occupancy(points), bool)

    def _locations(self, origins, directions, index_ray, index_tri, t):
        """Hit points in float64: each ray met with its triangle's plane, on the ray and in the plane to float64
        rounding (so the two triangles of an edge give the same point); canopy's float32 t where that fails."""
        vertices = np.asarray(self.mesh.vertices, np.float64)
        corners = vertices[np.asarray(self.mesh.faces, np.int64)[index_tri]]
        normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        o, d = origins[index_ray], directions[index_ray]
        with np.errstate(divide="ignore", invalid="ignore"):
            along = np.einsum("ij,ij->i", normals, corners[:, 0] - o) / np.einsum("ij,ij->i", normals, d)
        along = np.where(np.isfinite(along), along, t)
        return o + along[:, None] * d


def _mesh_key(mesh):
    """What tells that the mesh changed: trimesh's content hash where the mesh has one, and the vertices and faces
    arrays themselves (compared by identity; an array edited in place, in a mesh without a content hash, goes
    unnoticed). Holding the arrays keeps them alive, so that a new array cannot take an old one's identity."""
    try:
        content = hash(mesh)
    except TypeError:  # an unhashable container of arrays
        content = None
    return _MeshKey(content, mesh.vertices, mesh.faces)


class _MeshKey:
    """A mesh's content hash and arrays, equal to another when the hash is equal and the arrays are the same objects."""

    def __init__(self, content, vertices, faces):
        self.content, self.vertices, self.faces = content, vertices, faces

    def __eq__(self, other):
        return (self.content == other.content and self.vertices is other.vertices and self.faces is other.faces)


def _rays(ray_origins, ray_directions):
    """(n, 3) float64 origins and directions, checked to match."""
    origins = np.asarray(ray_origins, np.float64)
    directions = np.asarray(ray_directions, np.float64)
    if origins.ndim != 2 or origins.shape[1] != 3 or origins.shape != directions.shape:
        raise ValueError(f"ray origins {origins.shape} and directions {directions.shape} must both be (n, 3)")
    return origins, directions


def _rank_along_ray(index_ray):
    """Each hit's position among its ray's hits (0 for the first), for hits grouped by ray."""
    if len(index_ray) == 0:
        return np.zeros(0, np.int64)
    starts = np.flatnonzero(np.r_[True, index_ray[1:] != index_ray[:-1]])
    return np.arange(len(index_ray)) - np.repeat(starts, np.diff(np.r_[starts, len(index_ray)]))


def _first_of_each_location(locations, index_ray):
    """Indices of the hits to keep: the first of each (location to LOCATION_DECIMALS, ray), in their order."""
    if len(index_ray) == 0:
        return np.zeros(0, np.int64)
    # + 0.0 turns -0.0 into 0.0, so that the two zeros are one location.
    rows = np.column_stack([np.round(locations * 10.0 ** LOCATION_DECIMALS) + 0.0, index_ray.astype(np.float64)])
    _, first = np.unique(rows, axis=0, return_index=True)
    return np.sort(first)
