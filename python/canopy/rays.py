"""Ray files of `canopy rays record` and `canopy bench --rays`, as numpy structured arrays (docs/workloads.md).

Each record is one ray: origin, direction, interval, whether it asks any hit or the closest, and the hit it got when
it was recorded (prim 4294967295 for none). A renderer writes its own rays with save_rays and asks canopy's bench
which structure traces them fastest.
"""
import numpy as np

RAY_DTYPE = np.dtype([("org", "<f4", (3,)), ("dir", "<f4", (3,)), ("tmin", "<f4"), ("tmax", "<f4"), ("any", "u1"),
                      ("t", "<f4"), ("prim", "<u4"), ("u", "<f4"), ("v", "<f4")])
NO_HIT = np.uint32(0xFFFFFFFF)


def load_rays(path):
    """The rays of a ray file as a structured array of RAY_DTYPE (fields org, dir, tmin, tmax, any, t, prim, u, v)."""
    rays = np.load(path, allow_pickle=False)
    if rays.dtype != RAY_DTYPE or rays.ndim != 1:
        raise ValueError(f"{path}: not a ray file of canopy's: dtype {rays.dtype} shape {rays.shape}, "
                         f"expected one dimension of {RAY_DTYPE}")
    return rays


def make_rays(origins, directions, tmin=0.0, tmax=np.inf, any_hit=False):
    """A structured array of RAY_DTYPE from (n, 3) origins and directions, with no recorded hits (prim NO_HIT, t the
    ray's tmax): what save_rays writes for a renderer's own rays."""
    origins = np.asarray(origins, dtype=np.float32).reshape(-1, 3)
    directions = np.asarray(directions, dtype=np.float32).reshape(-1, 3)
    if origins.shape != directions.shape:
        raise ValueError(f"origins: {origins.shape[0]} rays, directions: {directions.shape[0]}")
    rays = np.zeros(origins.shape[0], dtype=RAY_DTYPE)
    rays["org"], rays["dir"] = origins, directions
    rays["tmin"], rays["tmax"] = tmin, tmax
    rays["any"] = np.asarray(any_hit, dtype=np.uint8)
    rays["t"], rays["prim"] = rays["tmax"], NO_HIT
    return rays


def save_rays(path, rays):
    """Writes a structured array of RAY_DTYPE as a ray file that `canopy bench --rays` replays."""
    rays = np.asarray(rays)
    if rays.dtype != RAY_DTYPE or rays.ndim != 1:
        raise ValueError(f"rays: dtype {rays.dtype} shape {rays.shape}, expected one dimension of {RAY_DTYPE}")
    np.save(path, np.ascontiguousarray(rays), allow_pickle=False)
