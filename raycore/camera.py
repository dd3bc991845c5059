"""Camera rays: one ray per pixel centre, in scanline order (row 0 at the top of the image), or
several per pixel, jittered within strata of it, for anti-aliasing.

The camera looks from ``position`` towards ``look_at``; ``up`` fixes the roll (it need not be
perpendicular to the view direction, only not parallel to it).  Image x grows to the right of
the view, image y grows downwards.
"""

import math
from typing import NamedTuple

import numpy as np
from numba import get_num_threads, get_thread_id, njit, prange

from raycore._memory import empty_aligned
from raycore.primitives._common import as_unit
from raycore.rays import as_float_array, as_real_array, integer, real_number, resolve_dtype


def _frame(position, look_at, up):
    """Camera position and its orthonormal (right, true up, forward) axes, each (3,) float64.

    Lengths through :func:`~raycore.primitives._common.as_unit`, whose squares neither
    overflow nor vanish: with ``np.linalg.norm``, a look_at 1e200 away or an up of 1e300 was
    refused as parallel, and position and look_at near float64's largest made NaN rays.
    """
    position = as_float_array(position, "position", np.float64, (3,))
    look_at = as_float_array(look_at, "look_at", np.float64, (3,))
    up = as_float_array(up, "up", np.float64, (3,))
    with np.errstate(over="ignore"):
        forward = look_at - position
    if not np.all(np.isfinite(forward)):  # both near float64's largest: halved first (exactly)
        forward = look_at / 2 - position / 2
    forward = as_unit(forward, "look_at", "must differ from position")[0]
    up = as_unit(up, "up", "must not be zero")[0]
    right = as_unit(np.cross(forward, up), "up", "must not be parallel to the view direction",
                    shortest=1e-9)[0]
    return position, right, np.cross(right, forward), forward


def half_tan(fov):
    """tan(fov / 2) of an angle in degrees, with the same bits on every x86-64 CPU.

    Not ``np.tan``: NumPy's float64 tan runs SVML's loop on CPUs with AVX-512, whose last bit
    differed from its AVX2 loop's for about one angle in 200 (``tests/scene/test_other_cpu.py``),
    and a camera's rays with it.  ``math.tan`` is the C library's, one code on every CPU of
    raycore's levels.
    """
    return math.tan(math.radians(fov) / 2)


#: Pixels of an image side at most: a side that NumPy could not have made an axis of (width
#: 1e30 raised its "Maximum allowed dimension exceeded") is refused by name.
MAX_SIDE = 2**31 - 1


def check_size(width, height, names=("width", "height")):
    """``ValueError`` naming ``width`` or ``height`` (or the caller's ``names`` for them) unless
    both are integers in [1, MAX_SIDE]."""
    integer(width, names[0], 1, MAX_SIDE)
    integer(height, names[1], 1, MAX_SIDE)


def _pixel_grid(width, height):
    """Pixel centres in [-1, 1]: x of each column (to the right), y of each row (upwards), of
    a size :func:`check_size` accepts."""
    x = (np.arange(width) + 0.5) / width * 2 - 1
    y = 1 - (np.arange(height) + 0.5) / height * 2
    return x, y


#: Most rays per pixel that a camera makes.
MAX_SAMPLES = 64


def strata(samples):
    """How ``samples`` rays split a pixel: rows of equal height, each cut into equal cells.

    ``ceil(sqrt(samples))`` cells a row; the last row holds what is left, so that every
    sample has a stratum of its own and the strata tile the pixel.

    Returns
    -------
    rows : int
    columns : int
        Cells of every row but the last.
    weights : ndarray of float64, shape (samples,)
        Each sample's stratum's area: the weights of an unbiased pixel mean.
    """
    integer(samples, "samples", 1, MAX_SAMPLES)
    columns = int(np.ceil(np.sqrt(samples)))
    rows = -(-samples // columns)
    last = samples - columns * (rows - 1)
    weights = np.full(samples, 1.0 / (rows * columns))
    weights[columns * (rows - 1):] = 1.0 / (rows * last)
    return rows, columns, weights


@njit(inline="always")
def _seed_keys(seed):
    """Two 32-bit keys of a 64-bit ``seed``, one for each axis of the jitter: the halves of
    splitmix64's first output for it, so that nearby seeds give unrelated keys."""
    z = seed + np.uint64(0x9E3779B97F4A7C15)
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    z = z ^ (z >> np.uint64(31))
    return np.uint32(z & np.uint64(0xFFFFFFFF)), np.uint32(z >> np.uint64(32))


@njit(inline="always")
def _hash01(key):
    """A uniform number in [0, 1), a multiple of 2^-31, from a 32-bit integer hash of ``key``
    (Wellons's lowbias32): the same jitter for the same ray on every run and thread.

    32-bit, not 64: x86-64-v3 (AVX2) has neither a vector 64-bit multiply nor a conversion of
    64-bit integers to floats, and LLVM emulated both, lane by lane for the conversion; a
    512x512, 4-sample camera took 2.9 ms there (1.4 with AVX-512), 2.2 ms now."""
    # Numba computes uint32 products in 64 bits: each is cut back to 32
    z = np.uint32((key ^ (key >> np.uint32(16))) * np.uint32(0x21F0AAAD))
    z = np.uint32((z ^ (z >> np.uint32(15))) * np.uint32(0x735A2D97))
    z = z ^ (z >> np.uint32(15))
    return float(np.int32(z >> np.uint32(1))) * (1.0 / 2147483648.0)


@njit(inline="always")
def _unit(x, y, z):
    """(x, y, z) scaled to unit length, by one division and three products rather than three
    divisions: float64 division and square root bound the camera loops (1024x1024 rays, one
    thread: 6.8 -> 4.1 ms); the direction moves by an ulp at most."""
    scale = 1.0 / np.sqrt(x * x + y * y + z * z)
    return x * scale, y * scale, z * scale


@njit(cache=True, parallel=True, _nrt=False)
def _sample_rays_kernel(center, right, up, x_scale, y_scale, width, height, first_row,
                        samples, rows, columns, seed, unit, constant, scratch, points, constants):
    """:func:`_plane_rays_kernel` for ``samples`` jittered rays per pixel, pixel by pixel, of
    image rows ``first_row`` on (as many as ``points`` holds): ray ``(h * width + w) * samples
    + s`` of the image goes through a random point of sample ``s``'s stratum (see
    :func:`strata`), whichever rows are made at once; image coordinates in [-1, 1] are scaled
    by ``x_scale``, ``y_scale``.

    Divisions by the image size and the strata are multiplications by their reciprocals: the
    same rays where those are powers of two (512 pixels, 2x2 strata), else unit directions
    within 2 float64 epsilons of the divided ones (float32 rays came out the same in every size
    tried).  The strata are walked row by row (no integer division per ray) and the camera's
    vectors read once into scalars: 7.0 -> 5.2 ms for 512x512 pixels of 4 samples, alone.  A
    row's rays of one sample are made for all its pixels at once, into the calling thread's
    ``scratch`` row ((threads, 3, width) of the rays' precision), then put in place: LLVM makes
    vector code of that loop, which it did not of one over a pixel's samples, whose rays lie
    next to each other (the same rays, 15-30 % faster).
    """
    last = samples - columns * (rows - 1)
    to_x, to_y = 1.0 / width, 1.0 / height
    per_column, per_last, per_row = 1.0 / columns, 1.0 / last, 1.0 / rows
    center_x, center_y, center_z = center[0], center[1], center[2]
    right_x, right_y, right_z = right[0], right[1], right[2]
    up_x, up_y, up_z = up[0], up[1], up[2]
    constant_x, constant_y, constant_z = constant[0], constant[1], constant[2]
    band = first_row * width * samples  # the image's first ray in points
    key_x, key_y = _seed_keys(seed)
    for h in prange(first_row, first_row + len(points) // (width * samples)):
        made = scratch[get_thread_id()]
        sample = 0
        for row in range(rows):
            cells, per_cell = (columns, per_column) if row < rows - 1 else (last, per_last)
            for cell in range(cells):
                for w in range(width):
                    # the ray's index modulo 2^32 (rays 2^32 apart share their jitter), and the
                    # column as an int32 (see _hash01)
                    ray = np.uint32((h * width + w) * samples + sample)
                    sx = (cell + _hash01(ray ^ key_x)) * per_cell
                    sy = (row + _hash01(ray ^ key_y)) * per_row
                    across = ((np.int32(w) + sx) * to_x * 2 - 1) * x_scale
                    rise = (1 - (h + sy) * to_y * 2) * y_scale
                    x = center_x + across * right_x + rise * up_x
                    y = center_y + across * right_y + rise * up_y
                    z = center_z + across * right_z + rise * up_z
                    if unit:
                        x, y, z = _unit(x, y, z)
                    made[0, w] = x
                    made[1, w] = y
                    made[2, w] = z
                for w in range(width):
                    ray = (h * width + w) * samples + sample - band
                    points[ray, 0] = made[0, w]
                    points[ray, 1] = made[1, w]
                    points[ray, 2] = made[2, w]
                sample += 1
        for ray in range(h * width * samples - band, (h + 1) * width * samples - band):
            constants[ray, 0] = constant_x
            constants[ray, 1] = constant_y
            constants[ray, 2] = constant_z


class Camera(NamedTuple):
    """A camera's image plane, which makes the camera's rays a band of image rows at a time
    (:meth:`rays`): a render traces and shades a large image in bands, each of whose rays are
    made when it is reached (:func:`raycore.render.render_camera`).  Made by
    :func:`perspective_camera` and :func:`orthographic_camera`.

    The rays' varying ends (perspective: directions; orthographic: origins) are the points
    ``center + x * x_scale * right + y * y_scale * up`` of image coordinates x, y in [-1, 1],
    scaled to unit length when ``unit``; their other ends all equal ``constant``.
    """

    center: np.ndarray
    right: np.ndarray
    up: np.ndarray
    x_scale: float
    y_scale: float
    width: int
    height: int
    constant: np.ndarray
    #: Perspective: the points are directions (unit length), ``constant`` the origin.
    unit: bool

    def rays(self, dtype="float64", samples=1, seed=0, rows=None, out=None):
        """The camera's rays, one per pixel centre or ``samples`` per pixel (see
        :func:`_plane_rays_kernel` and :func:`_sample_rays_kernel`), of every image row or of rows
        ``rows[0]`` to ``rows[1] - 1``: the same rays either way.

        ``out``, a pair of C-contiguous arrays of ``dtype`` and the rays' shape, receives them
        (a render's bands reuse one pair: :func:`raycore.render.render_camera`).

        Returns
        -------
        origins, directions : ndarray, shape (rows * width * samples, 3)
            Pixel by pixel in scanline order, a pixel's samples together.
        """
        seed = _check_seed(seed)
        band = (0, self.height) if rows is None else rows
        # checked before it is unpacked (a number raised TypeError), a bool is not a row
        if not (isinstance(band, (tuple, list)) and len(band) == 2
                and all(isinstance(row, (int, np.integer)) and not isinstance(row, bool)
                        for row in band) and 0 <= band[0] < band[1] <= self.height):
            raise ValueError(f"rows must be two integers in [0, {self.height}], first < last, "
                             f"got {rows!r}")
        first, last = band
        dtype = resolve_dtype(dtype)
        self._check_reach(dtype)
        strata_rows, columns, _ = strata(samples)
        shape = ((last - first) * self.width * samples, 3)
        if out is None:
            out = empty_aligned(shape, dtype), empty_aligned(shape, dtype)
        elif not isinstance(out, (tuple, list)) or len(out) != 2 or any(
                not isinstance(a, np.ndarray) or a.shape != shape or a.dtype != dtype
                or not a.flags.c_contiguous or not a.flags.writeable for a in out):
            raise ValueError(f"out must be two writable C-contiguous {np.dtype(dtype).name} "
                             f"arrays of shape {shape}")
        # the varying ends are the directions of a perspective camera, the origins otherwise
        constants, points = out if self.unit else out[::-1]
        if samples == 1:  # pixel centres, not jittered
            x, y = _pixel_grid(self.width, self.height)
            _plane_rays_kernel(self.center, self.right, self.up, x * self.x_scale,
                               y[first:last] * self.y_scale, self.unit, self.constant, points,
                               constants)
        else:
            _sample_rays_kernel(self.center, self.right, self.up, float(self.x_scale),
                                float(self.y_scale), self.width, self.height, first, samples,
                                strata_rows, columns, seed, self.unit, self.constant,
                                np.empty((get_num_threads(), 3, self.width), dtype), points,
                                constants)
        return out

    def _check_reach(self, dtype):
        """``ValueError`` unless the rays' coordinates fit ``dtype``: the origin (perspective), or
        the view plane, ``center`` to ``x_scale`` and ``y_scale`` along right and up, within
        its largest value (an overflow gave rays of inf, which miss everything)."""
        with np.errstate(over="ignore", invalid="ignore"):  # inf * 0: NaN, refused below
            reach = np.abs(self.constant) if self.unit else (
                np.abs(self.center) + self.x_scale * np.abs(self.right)
                + self.y_scale * np.abs(self.up))
        largest = np.finfo(dtype).max
        if not np.all(reach <= largest):
            names = "position" if self.unit else "position and view_height"
            raise ValueError(f"{names} put the rays beyond {np.dtype(dtype).name}'s range "
                             f"({largest:.4g})")


@njit(cache=True, parallel=True)
def _plane_rays_kernel(center, right, up, across, rise, unit, constant, points, constants):
    """Rays of an image plane, in scanline order, into ``points`` and ``constants`` ((H*W, 3)):
    the points ``center + across[w] * right + rise[h] * up`` (computed in float64, rounded
    once, scaled to unit length when ``unit``), and rows that all equal ``constant``, written in
    the same pass."""
    width = len(across)
    for h in prange(len(rise)):
        for w in range(width):
            x = center[0] + across[w] * right[0] + rise[h] * up[0]
            y = center[1] + across[w] * right[1] + rise[h] * up[1]
            z = center[2] + across[w] * right[2] + rise[h] * up[2]
            if unit:
                x, y, z = _unit(x, y, z)
            row = h * width + w
            points[row, 0] = x
            points[row, 1] = y
            points[row, 2] = z
            for k in range(3):
                constants[row, k] = constant[k]


def _check_fov(fov):
    if not 0 < real_number(fov, "fov") < 180:
        raise ValueError(f"fov must be in (0, 180) degrees, got {fov!r}")


def _check_seed(seed):
    """``seed`` as the np.uint64 the jitter takes: an integer in [0, 2^64)."""
    return np.uint64(integer(seed, "seed", 0, 2**64 - 1))


def perspective_rays(position, look_at, up, fov, width, height, dtype="float64", samples=1,
                     seed=0):
    """Pinhole camera rays.

    Parameters
    ----------
    position, look_at, up : array_like, shape (3,)
    fov : float
        Vertical field of view in degrees, in (0, 180).
    width, height : int
        Image size in pixels.
    dtype : {"float64", "float32"}
        Precision of the rays: that of the scene they go to saves it a conversion.
    samples : int
        Rays per pixel, in [1, MAX_SAMPLES]: one through its centre, or each through a random
        point of its own stratum of the pixel (:func:`strata`).
    seed : int
        Of the jitter: the same seed gives the same rays.

    Returns
    -------
    origins, directions : ndarray, shape (height * width * samples, 3)
        Every origin is ``position``; directions are unit length.  Pixel by pixel, a pixel's
        samples together.

    Raises
    ------
    ValueError
        Naming the argument that is out of range or degenerate.
    """
    return perspective_camera(position, look_at, up, fov, width, height).rays(dtype, samples,
                                                                              seed)


def perspective_camera(position, look_at, up, fov, width, height):
    """The :class:`Camera` of :func:`perspective_rays` (see there for the arguments)."""
    _check_fov(fov)
    check_size(width, height)
    position, right, true_up, forward = _frame(position, look_at, up)
    # the image plane at distance 1
    half_height = half_tan(fov)
    return Camera(forward, right, true_up, half_height * width / height, half_height, width,
                  height, position, unit=True)


def orthographic_rays(position, look_at, up, view_height, width, height, dtype="float64",
                      samples=1, seed=0):
    """Parallel rays from a view plane through ``position``, perpendicular to it.

    Parameters
    ----------
    position, look_at, up : array_like, shape (3,)
    view_height : float
        Height of the view in scene units (its width follows the image's aspect ratio).
    width, height : int
        Image size in pixels.
    dtype : {"float64", "float32"}
        Precision of the rays.
    samples, seed : int
        Rays per pixel and their jitter, as for :func:`perspective_rays`.

    Returns
    -------
    origins, directions : ndarray, shape (height * width * samples, 3)
        Origins on the view plane; every direction is the unit view direction.

    Raises
    ------
    ValueError
        Naming the argument that is out of range or degenerate.
    """
    return orthographic_camera(position, look_at, up, view_height, width, height).rays(
        dtype, samples, seed)


def orthographic_camera(position, look_at, up, view_height, width, height):
    """The :class:`Camera` of :func:`orthographic_rays` (see there for the arguments)."""
    if not (np.isfinite(real_number(view_height, "view_height")) and view_height > 0):
        raise ValueError(f"view_height must be positive and finite, got {view_height!r}")
    check_size(width, height)
    position, right, true_up, forward = _frame(position, look_at, up)
    return Camera(position, right, true_up, view_height / 2 * width / height, view_height / 2,
                  width, height, forward, unit=False)


#: Where the framing camera looks from, seen from the scene's centre: in front (+z), to the right
#: (+x) and above (+y), the three-quarter view in which y-up models (OBJ's convention) are
#: usually shown; the default light (:data:`raycore.render.DEFAULT_LIGHT`) falls on that side.
THREE_QUARTER = (1.0, 0.75, 1.6)


def frame_box(lo, hi, width, height, *, fov=45.0, position=None, look_at=None,
              up=(0.0, 1.0, 0.0), fill=0.9):
    """A camera that sees the whole box ``lo``..``hi``, for what a caller leaves out.

    ``look_at`` defaults to the box's centre; ``position`` to a point in the
    :data:`THREE_QUARTER` direction from ``look_at``, as near as lets a perspective camera of
    vertical field of view ``fov`` see every corner of the box; the returned view height frames
    the box for an orthographic camera at the final position.

    Parameters
    ----------
    lo, hi : array_like, shape (3,)
        The box; an empty one (some ``lo`` above its ``hi``, e.g. a scene of planes only) is
        taken as the cube from -1 to 1.
    width, height : int
        Image size in pixels (its aspect ratio).
    fov : float
        Vertical field of view in degrees, in (0, 180).
    position, look_at : array_like, shape (3,), optional
    up : array_like, shape (3,)
    fill : float
        Fraction of the half image, in (0, 1], that the box's farthest corner reaches.

    Returns
    -------
    position, look_at : ndarray of float64, shape (3,)
    view_height : float
        For :func:`orthographic_rays` from ``position`` towards ``look_at``.

    Raises
    ------
    ValueError
        Naming the argument that is out of range or degenerate.
    """
    _check_fov(fov)
    if not 0 < real_number(fill, "fill") <= 1:
        raise ValueError(f"fill must be in (0, 1], got {fill!r}")
    check_size(width, height)
    # an empty box is as Scene.bounds gives it, inf above -inf: it may be infinite
    lo = as_real_array(lo, "lo", np.float64, (3,))
    hi = as_real_array(hi, "hi", np.float64, (3,))
    if np.any(lo > hi):
        lo, hi = np.full(3, -1.0), np.full(3, 1.0)
    lo, hi = as_float_array(lo, "lo", np.float64), as_float_array(hi, "hi", np.float64)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                        for z in (lo[2], hi[2])])
    look_at = (lo + hi) / 2 if look_at is None else as_float_array(look_at, "look_at",
                                                                   np.float64, (3,))
    # half the image's extent at distance 1, vertically and horizontally, shrunk by fill
    tan_v = half_tan(fov) * fill
    tan_h = tan_v * width / height
    if position is None:
        toward = np.asarray(THREE_QUARTER) / np.linalg.norm(THREE_QUARTER)
        _, right, true_up, forward = _frame(look_at + toward, look_at, up)
        relative = corners - look_at
        # a corner at depth (distance - its offset towards the camera) is in view once its
        # sideways offsets fit within the view's half extents at that depth
        depth_offset = relative @ toward
        needed = depth_offset + np.maximum(np.abs(relative @ right) / tan_h,
                                           np.abs(relative @ true_up) / tan_v)
        size = max(float(np.linalg.norm(hi - lo)), 1e-12)
        # in front of every corner, also for a flat box seen edge-on
        distance = max(needed.max(), depth_offset.max() + 1e-3 * size, 1e-3 * size)
        position = look_at + distance * toward
    else:
        position = as_float_array(position, "position", np.float64, (3,))
    position, right, true_up, forward = _frame(position, look_at, up)
    relative = corners - position
    half = max(np.abs(relative @ true_up).max(),
               np.abs(relative @ right).max() * height / width) / fill
    return position, look_at, float(max(2 * half, 1e-12))
