"""raycore: ray casting over analytic primitives and triangle meshes.

NumPy arrays in and out, compiled (Numba) kernels inside.
"""

from raycore.hits import AllHits, Hits
from raycore.offset import offset_ray_origin
from raycore.scene import Scene

__all__ = ["AllHits", "Hits", "Scene", "offset_ray_origin"]
