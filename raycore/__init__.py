"""raycore: ray casting over analytic primitives and triangle meshes.

NumPy arrays in and out, compiled (Numba) kernels inside.
"""

from raycore._target import choose_target

choose_target()  # before any kernel is declared, and before the layer (it reloads Numba's config)

from raycore._threading import choose_layer  # noqa: E402

choose_layer()  # before any parallel kernel is linked: TBB, else workqueue, never OpenMP

from raycore._cache import drop_stale_kernels  # noqa: E402

drop_stale_kernels()  # before any kernel is loaded from the cache

from raycore._compile_notice import announce_compiles  # noqa: E402

announce_compiles()

from raycore import sensors  # noqa: E402
from raycore._info import info  # noqa: E402
from raycore.hits import AllHits, Hits, TooManyHits  # noqa: E402
from raycore.offset import offset_ray_origin  # noqa: E402
from raycore.scene import Scene  # noqa: E402

__all__ = ["AllHits", "Hits", "Scene", "TooManyHits", "info", "offset_ray_origin", "sensors"]
