"""canopy: BVH builders and ray and point queries over numpy arrays.

Scene holds several meshes and answers closest hits, any hits, every hit along a ray, closest points, distances,
signed distances and occupancy; Accel is one mesh (or its instances) with closest and any hits. builders() lists
the BVH builders a Scene or an Accel takes by name. load_rays and save_rays read and write the ray files of
`canopy rays record` and `canopy bench --rays`.
"""
from ._canopy import *  # noqa: F401,F403
from ._canopy import __version__  # noqa: F401
from .rays import RAY_DTYPE, NO_HIT, load_rays, make_rays, save_rays  # noqa: F401,E402
