"""raycore: ray casting over analytic primitives and triangle meshes.

NumPy arrays in and out, compiled (Numba) kernels inside.
"""

from raycore.hits import AllHits, Hits

__all__ = ["AllHits", "Hits"]
