"""Floating-point helpers shared by every compiled kernel.

Kernels are compiled once per precision (float32 and float64).  A bare Python literal such as
``0.5`` is a float64 in Numba and silently promotes float32 arithmetic to float64, so constants
inside kernels go through :func:`like`, which casts them to the precision of a given value.
"""

import numpy as np
from numba import types
from numba.extending import overload


def like(x, value):
    """Return ``value`` cast to the floating-point type of ``x`` (usable inside kernels)."""
    return type(x)(value)


@overload(like, jit_options={"forceinline": True})
def _like(x, value):
    precision = x

    def impl(x, value):
        return precision(value)

    return impl


def unit_roundoff(x):
    """Return the unit roundoff u of ``x``'s precision: 2**-24 for float32, 2**-53 for float64."""
    return np.finfo(type(x)).eps / 2


@overload(unit_roundoff, jit_options={"forceinline": True})
def _unit_roundoff(x):
    precision = x
    u = 2.0**-24 if x == types.float32 else 2.0**-53

    def impl(x):
        return precision(u)

    return impl


def gamma(n, x):
    """Return pbrt's error bound γ(n) = n·u / (1 − n·u) in the precision of ``x``.

    A sum or product of n rounded operations is within a factor (1 ± γ(n)) of the exact value
    (Higham 2002, §3.1); conservative box and triangle tests widen their results by it.
    """
    u = unit_roundoff(x)
    return n * u / (1 - n * u)


@overload(gamma, jit_options={"forceinline": True})
def _gamma(n, x):
    precision = x
    u = 2.0**-24 if x == types.float32 else 2.0**-53

    def impl(n, x):
        return precision(n * u / (1.0 - n * u))

    return impl
