"""raycore: ray casting over analytic primitives and triangle meshes.

NumPy arrays in and out, compiled (Numba) kernels inside.
"""

from raycore._cache import drop_stale_kernels

drop_stale_kernels()  # before any kernel is loaded from the cache

from raycore.hits import AllHits, Hits  # noqa: E402
from raycore.offset import offset_ray_origin  # noqa: E402
from raycore.scene import Scene  # noqa: E402

__all__ = ["AllHits", "Hits", "Scene", "offset_ray_origin"]
