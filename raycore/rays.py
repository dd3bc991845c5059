"""Validation and normalisation of ray batches at the library's edge.

Kernels trust their inputs; everything a caller can get wrong is caught here, once, with a
``ValueError`` that names the offending argument.
"""

import numpy as np
from numba import njit, prange

DTYPES = {"float32": np.float32, "float64": np.float64}


def real_number(value, name):
    """``value`` as a float if it is one real number (a bool is not), else ``ValueError``
    naming ``name``: a comparison with None or a string raised TypeError, with an array NumPy's,
    and ``np.isfinite`` of an int past int64's range TypeError."""
    if isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool):
        try:
            return float(value)
        except OverflowError:  # an int past float64's range
            pass
    raise ValueError(f"{name} must be a real number, got {value!r}")


def flag(value, name):
    """``value`` as a bool if it is one (Python's or NumPy's), else ``ValueError`` naming
    ``name``: ``bool()`` takes any object ("no" is true), and raises NumPy's own unnamed error
    for an array."""
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    raise ValueError(f"{name} must be True or False, got {value!r}")


def integer(value, name, low, high):
    """``value`` if it is an integer (a bool is not) in [low, high], else ``ValueError`` naming
    ``name``."""
    if isinstance(value, (int, np.integer)) and not isinstance(value, bool) \
            and low <= value <= high:
        return value
    raise ValueError(f"{name} must be an integer in [{low}, {high}], got {value!r}")


def resolve_dtype(dtype):
    """Return ``np.float32`` or ``np.float64`` for a dtype-like, else raise ``ValueError``."""
    if dtype is None:  # which NumPy takes as float64
        raise ValueError("dtype must be 'float32' or 'float64', got None")
    try:
        resolved = np.dtype(dtype).type
    except TypeError as error:
        raise ValueError(f"dtype must be 'float32' or 'float64', got {dtype!r}") from error
    if resolved not in (np.float32, np.float64):
        raise ValueError(f"dtype must be 'float32' or 'float64', got {dtype!r}")
    return resolved


def as_real_array(value, name, dtype, shape=None):
    """Convert ``value`` to a C-contiguous array of ``dtype`` (no copy when it already is one).

    Parameters
    ----------
    value : array_like
        Real numbers (bool, int or float); objects, strings and complex numbers are refused.
    name : str
        The argument's name, used in error messages.
    dtype : numpy float type
    shape : tuple of (int or None), optional
        Expected shape; ``None`` entries match any length.

    Raises
    ------
    ValueError
        On a non-numeric value or a shape mismatch.
    """
    return _converted(_real_array(value, name, shape), dtype)


def _real_array(value, name, shape):
    """``value`` as an array of real numbers of ``shape``, as it is (see :func:`as_real_array`)."""
    try:
        array = np.asarray(value)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{name} must be an array of real numbers: {error}") from error
    if array.dtype.kind not in "biuf":
        raise ValueError(f"{name} must hold real numbers, got dtype {array.dtype}")
    if shape is not None and (
        array.ndim != len(shape)
        or any(want not in (None, got) for got, want in zip(array.shape, shape, strict=True))
    ):
        expected = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
        raise ValueError(f"{name} must have shape {expected}, got {array.shape}")
    return array


def _converted(array, dtype):
    """A C-contiguous ``dtype`` copy of ``array``, or ``array`` itself when it is one."""
    # values beyond float32's range become inf here; callers refuse them as non-finite
    with np.errstate(over="ignore"):
        return np.ascontiguousarray(array, dtype=dtype)


def read_only(array):
    """A read-only view of ``array``.  Numba compiles separate code for read-only arrays (a
    caller's broadcast or memory-mapped input): passing read-only views of arrays that may be
    either keeps a kernel to one compiled version per precision and layout."""
    view = array.view()
    view.flags.writeable = False
    return view


def _kernel_array(array, dtype):
    """:func:`_converted`, copied too when read-only or misaligned: the trace kernels take
    writable, aligned arrays only, since Numba compiles a kernel again for each argument that is
    read-only (a float32 warm-up compiled the traversal six times, not three, for read-only rays
    and bounds), and the queries call the compiled version for that one layout directly
    (:func:`raycore.queries._compiled`)."""
    array = _converted(array, dtype)
    return array if array.flags.writeable and array.flags.aligned else array.copy()


def as_float_array(value, name, dtype, shape=None):
    """:func:`as_real_array`, and refuse NaN and inf entries (``ValueError`` naming ``name``)."""
    array = as_real_array(value, name, dtype, shape)
    if not _all_finite(array.reshape(-1)):
        raise ValueError(f"{name} must be finite (no NaN or inf)")
    return array


@njit(cache=True)
def _all_finite(values):
    """Whether every entry of the 1-D ``values`` is finite: one pass, which LLVM vectorises
    (no early exit).  ``np.all(np.isfinite(...))`` made a boolean array first and read it
    again: 0.25 ms of the Open3D adapter's calls on 200k rays, 2 % of each."""
    finite = True
    for i in range(len(values)):
        finite &= np.isfinite(values[i])
    return finite


def as_ray_bound(value, name, count, dtype):
    """Return a per-ray bound (``tmin`` or ``tmax``) as an (N,) array; a scalar is broadcast.

    Infinity is allowed (``tmax=np.inf`` is the usual "no limit"); NaN is not.
    """
    array = _real_bound(value, name).astype(np.float64)
    if array.ndim != 0 and array.shape != (count,):
        raise ValueError(f"{name} must be a scalar or have shape ({count},), got {array.shape}")
    if np.any(np.isnan(array)):
        raise ValueError(f"{name} must not contain NaN")
    if array.ndim == 0:
        return np.full(count, array, dtype=dtype)
    return np.ascontiguousarray(array, dtype=dtype)


# Codes of what is wrong with a ray, as found by _ray_status.
_FINE, _BAD_ORIGIN, _BAD_DIRECTION, _ZERO_DIRECTION = 0, 1, 2, 3


@njit(cache=True, inline="always")
def _status_of(origins, directions, i):
    """What is wrong with ray ``i`` (one of the codes above)."""
    finite_origin = True
    finite_direction = True
    nonzero = False
    for a in range(3):
        finite_origin &= np.isfinite(origins[i, a])
        finite_direction &= np.isfinite(directions[i, a])
        nonzero |= directions[i, a] != 0
    if not finite_origin:
        return _BAD_ORIGIN
    if not finite_direction:
        return _BAD_DIRECTION
    if not nonzero:
        return _ZERO_DIRECTION
    return _FINE


@njit(cache=True, parallel=True)
def _ray_status(origins, directions):
    """(N,) uint8: what is wrong with each ray, in one pass and without temporaries."""
    status = np.empty(len(origins), np.uint8)
    for i in prange(len(origins)):
        status[i] = _status_of(origins, directions, i)
    return status


@njit(cache=True, parallel=True)
def _gather_rays(origins, directions):
    """Contiguous copies of strided (N, 3) rays, and each ray's status, in one pass.

    NumPy copies rows of three strided numbers one short inner loop at a time: for the columns
    of an (N, 6) ray table this pass is about five times faster.
    """
    n = len(origins)
    out_origins = np.empty((n, 3), origins.dtype)
    out_directions = np.empty((n, 3), directions.dtype)
    status = np.empty(n, np.uint8)
    for i in prange(n):
        for a in range(3):
            out_origins[i, a] = origins[i, a]
            out_directions[i, a] = directions[i, a]
        status[i] = _status_of(out_origins, out_directions, i)
    return out_origins, out_directions, status


def _as_bound(value, name, count, dtype):
    """A ray bound as a (1,) or (N,) array of ``dtype``, its shape checked; NaN is left for the
    compiled pass to find.  Scalars come back as shared (1,) arrays."""
    if type(value) in _PLAIN_NUMBERS:
        shared = _SCALAR_BOUNDS[dtype]
        array = shared.get(value)
        if array is None:
            try:
                array = np.full(1, value, dtype)
            except OverflowError as error:  # an int past what a float holds (10**400)
                raise ValueError(f"{name} must be a number that a float holds") from error
            if len(shared) < 32:
                shared[value] = array
        return array
    array = _real_bound(value, name)
    if array.ndim == 0:
        return np.full(1, array, dtype)
    if array.shape != (count,):
        raise ValueError(f"{name} must be a scalar or have shape ({count},), got {array.shape}")
    return _kernel_array(array, dtype)


def _real_bound(value, name):
    """``value`` as an array of real numbers, or ``ValueError`` naming ``name``: complex ones
    (whose imaginary parts a cast to float drops), strings, objects and ints past a float's
    range (10**400) are refused."""
    if type(value) is int:  # past int64 NumPy would make an object of it
        try:
            value = float(value)
        except OverflowError as error:
            raise ValueError(f"{name} must be a number that a float holds") from error
    try:
        array = np.asarray(value)
    except (TypeError, ValueError, OverflowError) as error:
        raise ValueError(f"{name} must be a number or an (N,) array of numbers") from error
    if array.dtype.kind not in "biuf":
        raise ValueError(f"{name} must be a real number or an (N,) array of real numbers, got "
                         f"dtype {array.dtype}")
    return array


_SCALAR_BOUNDS = {np.dtype(np.float32): {}, np.dtype(np.float64): {}}
_PLAIN_NUMBERS = (float, int)


def ray_arrays(origins, directions, tmin, tmax, dtype):
    """The arrays a query's compiled pass takes, with only the checks NumPy makes cheaply.

    ``dtype`` is a ``numpy.dtype`` (float32 or float64).
    Arrays already C-contiguous, aligned and writable in ``dtype`` are used as they are (others
    are converted or copied: see :func:`_kernel_array`), so that every array returned has that
    one layout; bounds become (1,) arrays when scalar (shared: kernels never write them).  What
    is wrong inside the arrays (NaN, inf, zero directions, NaN bounds) is found by the compiled
    pass, which reports the first refused ray; :func:`refuse` then says what is wrong with it.

    Returns
    -------
    origins, directions : ndarray, shape (N, 3)
    tmin, tmax : ndarray, shape (N,) or (1,)

    Raises
    ------
    ValueError
        Naming the argument whose shape or dtype is wrong.
    """
    # (N, 3) arrays of dtype, of one shape, C-contiguous, aligned and writable are taken as they
    # are: checked here, not in a helper (0.05 us of a 3 us one-ray query); carray is
    # C-contiguous, aligned and writeable in one flag
    if not (type(origins) is np.ndarray and type(directions) is np.ndarray
            and origins.dtype is dtype and directions.dtype is dtype
            and origins.ndim == 2 and origins.shape[1] == 3 and directions.shape == origins.shape
            and origins.flags.carray and directions.flags.carray):
        origins, directions, _ = _contiguous_rays(origins, directions, dtype)
    count = len(origins)
    return (origins, directions, _as_bound(tmin, "tmin", count, dtype),
            _as_bound(tmax, "tmax", count, dtype))


def refuse(origins, directions, tmin, tmax, dtype):
    """Raise the ``ValueError`` that says what is wrong with a batch the compiled pass refused."""
    prepare_rays(origins, directions, tmin, tmax, dtype)
    raise AssertionError("the compiled pass refused a batch that prepare_rays accepts")


def _contiguous_rays(origins, directions, dtype):
    """``origins`` and ``directions`` checked for shape and converted to C-contiguous (N, 3)
    arrays of ``dtype``, and each ray's status when the conversion found it: strided rays of the
    right precision (the columns of an (N, 6) table) are gathered by one compiled pass that
    checks them too; other conversions leave the status None."""
    origins = _real_array(origins, "origins", (None, 3))
    directions = _real_array(directions, "directions", (len(origins), 3))
    if all(array.dtype == dtype and not array.flags.c_contiguous
           for array in (origins, directions)):
        return _gather_rays(read_only(origins), read_only(directions))
    return _kernel_array(origins, dtype), _kernel_array(directions, dtype), None


def prepare_rays(origins, directions, tmin=0.0, tmax=np.inf, dtype=np.float64):
    """Validate a ray batch and return contiguous arrays in one precision.

    Directions are not normalised: as in Embree, a hit at parameter t lies at
    ``origin + t * direction``.

    Parameters
    ----------
    origins, directions : array_like, shape (N, 3)
    tmin, tmax : float or array_like of shape (N,)
    dtype : numpy float type

    Returns
    -------
    origins, directions : ndarray, shape (N, 3)
    tmin, tmax : ndarray, shape (N,)

    Raises
    ------
    ValueError
        Naming ``origins``, ``directions``, ``tmin`` or ``tmax``: wrong shape or dtype, NaN or inf
        coordinates, zero-length directions, NaN bounds.
    """
    # finiteness is checked with the zero directions, in one compiled pass
    origins, directions, status = _contiguous_rays(origins, directions, dtype)
    if status is None:
        status = _ray_status(origins, directions)
    if status.any():
        bad = np.flatnonzero(status)
        first = int(bad[0])
        problem = {
            _BAD_ORIGIN: "origins must be finite (no NaN or inf)",
            _BAD_DIRECTION: "directions must be finite (no NaN or inf)",
            _ZERO_DIRECTION: "directions must be non-zero",
        }[int(status[first])]
        raise ValueError(f"{problem}; {len(bad)} bad ray(s), first at index {first}")
    count = len(origins)
    return (
        origins,
        directions,
        as_ray_bound(tmin, "tmin", count, dtype),
        as_ray_bound(tmax, "tmax", count, dtype),
    )
