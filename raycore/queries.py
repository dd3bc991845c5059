"""Batch ray queries over a packed scene: one compiled entry per call, serial or parallel.

Every query goes through :func:`trace`, which hands the rays to
:func:`raycore.bvh.traverse.trace_range` with the scene's record: on the calling thread for
small batches (no parallel region to start), or in chunks over the threads.  The compiled pass
also checks the rays (finite, non-zero directions, bounds not NaN); Python checks only what
NumPy tells cheaply (shapes, dtypes), so that a one-ray call costs a few microseconds.

Scratch (traversal stacks, hit lists) is allocated once per calling thread and reused: several
Python threads may query at once, and each call numbers its worker threads from 0.
"""

import threading
from functools import partial

import numpy as np
from numba import get_num_threads, get_thread_id, njit, parallel_chunksize, prange

from raycore._fp import like
from raycore._memory import empty_aligned
from raycore.bvh.leaves import slot_value
from raycore.bvh.record import arrays_of, tabled_arrays_of
from raycore.bvh.traverse import (
    ALL,
    ANY,
    CLOSEST,
    COUNT,
    HIT_CAPACITY,
    LIST,
    MESH,
    PARITY,
    new_scratch,
    scratch_lengths,
    trace_range,
)
from raycore.hits import TooManyHits
from raycore.primitives.analytic import analytic_surface
from raycore.primitives.triangle import triangle_normal
from raycore.ray_order import gather_rays, group_order, ungroup

#: Rays per parallel work item: enough to amortise a call's set-up, few enough to balance cores.
#: A batch of fewer than ITEMS_PER_THREAD * CHUNK rays per thread is cut into smaller items, down
#: to MIN_CHUNK, so that every core gets some of it (2, 4 or 8 items per thread timed alike).
CHUNK = 1024
MIN_CHUNK = 64
ITEMS_PER_THREAD = 2

#: Batches smaller than this are traced on the calling thread: starting a parallel region costs
#: more than the rays it would share out.  Measured on nefertiti's random rays, 2 cores, with
#: work items cut down to MIN_CHUNK rays: 256 rays took 34-35 us on one thread and 31-37 on two;
#: 512 rays 64-65 and 49-52 us; 1024 rays 125-127 and 79-94 us (142 as one item of CHUNK rays).
SERIAL_BELOW = 512

#: Crossings a ray may list in :func:`all_hits`'s pass, on average over a work item: rays that
#: cross more surfaces use the room of rays that cross fewer, and those that find none left are
#: traced again.  Random rays inside a closed mesh cross it 0.7 times on average.  The room
#: takes 48 bytes a ray in float32 and 56 in float64 while the query runs (the rays themselves
#: take 24 and 48).
LIST_ROOM = 2

#: Batches from this size on are traced in a coherent order when they are incoherent
#: (:mod:`raycore.ray_order`), in pieces of PARTS_PER_THREAD per thread, if the scene's trees
#: (wide rows and leaf blocks) take GROUP_TREE_BYTES or more.  Grouping buys locality in the
#: tree, and a tree that the caches hold gains less than the grouping's passes cost.  Grouped
#: against plain, 500k random rays, 2 threads (Zen 4: 1 MiB of L2 a core, 32 MiB of L3), closest
#: hit / any hit / count: suzanne (0.05 MiB) 1.13-1.26 / 1.08-1.16 / 0.96-1.07; teapot, spot,
#: fandisk (0.3-1.1 MiB) 0.98-1.06 / 0.99-1.12 / 0.96-1.02; stanford-bunny and nefertiti in
#: float32 (3.6, 5.0 MiB) 1.01-1.03 / 1.04-1.06 / 0.98; in float64 (6.1, 8.7 MiB) 0.98-0.99 /
#: 0.97-1.0 / 0.95; nefertiti subdivided to 1.6M triangles (83, 142 MiB), 250k rays: 0.86-0.96 /
#: 0.90-0.98 / 0.95-0.96.  ``intersect_all``, whose lists are put back too: 1.15-1.40 on suzanne,
#: teapot, fandisk and stanford-bunny, 0.91 on nefertiti-1.6M.  ``contains`` is grouped on every
#: tree: its rays share one direction, so grouping their origins makes them coherent (0.85-0.97
#: on the same small meshes, 0.78 on nefertiti-1.6M).  With eight-lane leaf blocks the traversal
#: got faster and the float64 trees of 6.1 and 8.7 MiB lost too (1.06 / 1.06-1.14 / 1.01), while
#: stanford-bunny subdivided once (278k triangles, 13.7 MiB in float32, 25 in float64) gained
#: (0.84-0.94 / 0.90-0.98 / 0.84-0.88), as did nefertiti subdivided once (400k, 0.90-0.92 /
#: 0.85-0.86 / 0.79): hence 12 MiB, between the two.
GROUP_FROM = 65536
GROUP_TREE_BYTES = 12 << 20
PARTS_PER_THREAD = 2


@njit(cache=True, parallel=True, _nrt=False)
def _trace_parallel(scene, mode, test, sphere_method, origins, directions, tmin, tmax, out_t,
                    out_obj, out_prim, out_hit, out_u, out_v, out_slot, offsets, hits_t,
                    hits_obj, hits_prim, int_scratch, real_scratch, capacity, size, first_bad):
    # first_bad[chunk]: the chunk's first refused ray (a reduction would allocate)
    n = len(origins)
    for chunk in prange(len(first_bad)):
        thread = get_thread_id()
        first_bad[chunk] = trace_range(
            scene, mode, test, sphere_method, origins, directions, tmin, tmax, chunk * size,
            min(n, (chunk + 1) * size), out_t, out_obj, out_prim, out_hit, out_u, out_v,
            out_slot, offsets, hits_t, hits_obj, hits_prim, int_scratch[thread],
            real_scratch[thread], capacity)


@njit(cache=True)
def _trace_in_parallel(record, mode, test, sphere_method, origins, directions, tmin, tmax, out_t,
                       out_obj, out_prim, out_hit, out_u, out_v, out_slot, offsets, hits_t,
                       hits_obj, hits_prim, int_scratch, real_scratch, capacity, size):
    first_bad = np.empty((len(origins) + size - 1) // size, np.int64)
    _trace_parallel(tabled_arrays_of(record), mode, test, sphere_method, origins, directions,
                    tmin, tmax, out_t, out_obj, out_prim, out_hit, out_u, out_v, out_slot, offsets,
                    hits_t, hits_obj, hits_prim, int_scratch, real_scratch, capacity, size,
                    first_bad)
    return first_bad.min()


@njit(cache=True)
def _trace_here(record, mode, test, sphere_method, origins, directions, tmin, tmax, out_t,
                out_obj, out_prim, out_hit, out_u, out_v, out_slot, offsets, hits_t, hits_obj,
                hits_prim, int_scratch, real_scratch, capacity):
    # start as an int64, not a literal 0: trace_range would compile again, for this entry alone
    return trace_range(arrays_of(record), mode, test, sphere_method, origins, directions, tmin,
                       tmax, np.int64(0), len(origins), out_t, out_obj, out_prim, out_hit, out_u,
                       out_v, out_slot, offsets, hits_t, hits_obj, hits_prim, int_scratch[0],
                       real_scratch[0], capacity)


@njit(cache=True)
def _hits_here(record, mode, test, sphere_method, origins, directions, tmin, tmax, out_t, out_obj,
               out_prim, out_hit):
    """:func:`_trace_here` for batches below SERIAL_BELOW of closest hits without surface fields
    (CLOSEST), counts (COUNT, PARITY: room for HIT_CAPACITY crossings a ray), which the queries
    call directly: the fixed cost of a call is their speed (one ray: 3 us).  It takes fewer
    arguments (each costs its unboxing, even called as :func:`_compiled` does) and allocates its
    one row of scratch itself: 0.1 us, against 0.35 for looking up and passing the calling
    thread's rows."""
    int_scratch, real_scratch = _small_scratch(origins.dtype)
    return _trace_small(record, mode, test, sphere_method, origins, directions, tmin, tmax,
                        out_t, out_obj, out_prim, out_hit, int_scratch, real_scratch)


@njit(cache=True)
def _any_here(record, test, sphere_method, origins, directions, tmin, tmax, out_hit):
    """:func:`_hits_here` for any hits (ANY), without the three outputs that ANY leaves empty:
    unboxing them took 0.17 of the 2.2 us of a one-ray ``occluded``, whose Open3D counterpart
    takes 1.2."""
    int_scratch, real_scratch = _small_scratch(origins.dtype)
    no_ints = int_scratch[:0]
    return _trace_small(record, ANY, test, sphere_method, origins, directions, tmin, tmax,
                        real_scratch[:0], no_ints, no_ints, out_hit, int_scratch, real_scratch)


@njit(inline="always")
def _small_scratch(dtype):
    """A row of int and real scratch for :func:`_trace_small`, with room for HIT_CAPACITY
    crossings."""
    ints, reals = scratch_lengths(HIT_CAPACITY)
    return np.empty(ints, np.int64), np.empty(reals, dtype)


@njit(inline="always")
def _trace_small(record, mode, test, sphere_method, origins, directions, tmin, tmax, out_t,
                 out_obj, out_prim, out_hit, int_scratch, real_scratch):
    """:func:`raycore.bvh.traverse.trace_range` of every ray on the calling thread, into the
    outputs that CLOSEST, ANY, COUNT and PARITY write."""
    no_reals = out_t[:0]
    no_ints = out_obj[:0]
    return trace_range(arrays_of(record), mode, test, sphere_method, origins, directions, tmin,
                       tmax, np.int64(0), len(origins), out_t, out_obj, out_prim, out_hit,
                       no_reals, no_reals, no_ints, no_ints, no_reals, no_ints, no_ints,
                       int_scratch, real_scratch, np.int64(HIT_CAPACITY))


def _compiled(entry, record):
    """``entry``'s compiled code for a query's calls about ``record``, to be called as ``entry``
    is, without Numba's dispatch.

    Numba's dispatcher types every argument on every call to find the compiled version: 0.7 of
    the 1.6 us that a one-ray query spent in its compiled entry.  Here every argument but the
    record has one type per precision (rays and bounds as :func:`raycore.rays.ray_arrays`
    gives them, C-contiguous, aligned and writable; outputs and scratch made in this module;
    integers), so the record, whose type fixes the precision and also varies with what a scene
    holds (read-only arrays of a memory-mapped file), names the version: the entry points
    that queries called are kept per record type (``record.entry_points``, from
    :func:`entry_points_for`).  The first call of an entry goes through the dispatcher, which
    compiles or loads it; later ones, about this record or another of its type, call its entry
    point (the compiled wrapper the dispatcher itself would call), or the dispatcher where
    Numba has none.  The function is returned, not called, so that a query passes its
    arguments once (0.15 us of a one-ray call).
    """
    run = record.entry_points.get(entry)
    return run if run is not None else partial(_first_call, record, entry)


#: The entry points that queries called, per Numba type of record (see :func:`_compiled`): the
#: record of a scene built or loaded again is of a type seen before, whose entries its first
#: queries then call directly.  Through the dispatcher, which types every argument, a one-ray
#: query on a scene just built took 156-163 us against 26 for the next one (suzanne).
_ENTRY_POINTS = {}


def entry_points_for(record):
    """The dict, shared by every record of ``record``'s Numba type, in which :func:`_compiled`
    keeps the entry points that queries called (``record.entry_points``)."""
    return _ENTRY_POINTS.setdefault(record._numba_type_, {})


def _first_call(record, entry, *arguments):
    """Call ``entry`` through its dispatcher and keep its entry point in ``record.entry_points``
    (shared by every record of its type: :func:`entry_points_for`)."""
    answer = entry(*arguments)
    signature = tuple(map(entry.typeof_pyval, arguments))
    record.entry_points[entry] = getattr(entry.overloads.get(signature), "entry_point", entry)
    return answer


class _Scratch(threading.local):
    """Each calling thread's scratch rows, per precision and hit-list capacity."""

    def __init__(self):
        self.rows = {}

    def get(self, dtype, capacity, threads):
        """Scratch with at least ``threads`` rows (:func:`raycore.bvh.traverse.new_scratch`)."""
        key = (dtype.char, capacity)
        rows = self.rows.get(key)
        if rows is None or len(rows[0]) < threads:
            rows = self.rows[key] = new_scratch(threads, dtype, capacity)
        return rows


_scratch = _Scratch()
_EMPTY = {np.dtype(np.float32): np.empty(0, np.float32),
          np.dtype(np.float64): np.empty(0, np.float64)}
_NO_INTS = np.empty(0, np.int64)
_NO_FLAGS = np.empty(0, np.bool_)
_NO_OFFSETS = np.zeros(1, np.int64)
#: Output dtypes as dtype objects: np.empty takes one 40 ns faster than a scalar type.
_INT64, _BOOL = np.dtype(np.int64), np.dtype(np.bool_)


def trace(scene, mode, rays, test, sphere_method, *, out_t=None, out_obj=None, out_prim=None,
          out_hit=None, barycentrics=None, offsets=_NO_OFFSETS, hits=None,
          capacity=HIT_CAPACITY, group=True):
    """Run one query over a batch; outputs not given are passed empty.

    Parameters
    ----------
    scene : SceneRecord
    mode, test, sphere_method : int
    rays : tuple
        ``(origins, directions, tmin, tmax)`` as :func:`raycore.rays.ray_arrays` gives them.
    out_t, out_obj, out_prim, out_hit, barycentrics, offsets, hits
        As :func:`raycore.bvh.traverse.trace_range`'s outputs (``barycentrics`` the
        ``(u, v, slot)`` triple, ``hits`` the ``(t, obj, prim)`` buffers).
    group : bool
        Trace a large incoherent batch in a coherent order (:func:`grouping`); False for rays
        grouped already, and for ALL and LIST, whose crossings go where ``offsets`` says for
        each ray of the batch as given.

    Returns
    -------
    int
        A refused ray (the first, unless the batch was grouped), or N if none.
    """
    origins, directions, tmin, tmax = rays
    empty = _EMPTY[origins.dtype]
    out_t = empty if out_t is None else out_t
    out_obj = _NO_INTS if out_obj is None else out_obj
    out_prim = _NO_INTS if out_prim is None else out_prim
    out_hit = _NO_FLAGS if out_hit is None else out_hit
    serial = len(origins) < SERIAL_BELOW
    # get_num_threads costs 0.8 us: asked only for a parallel call
    threads = 1 if serial else get_num_threads()
    int_scratch, real_scratch = _scratch.get(origins.dtype, capacity, threads)
    u, v, slot = (empty, empty, _NO_INTS) if barycentrics is None else barycentrics
    hits_t, hits_obj, hits_prim = (empty, _NO_INTS, _NO_INTS) if hits is None else hits
    arguments = (scene, mode, test, sphere_method, origins, directions, tmin, tmax, out_t,
                 out_obj, out_prim, out_hit, u, v, slot, offsets, hits_t, hits_obj, hits_prim,
                 int_scratch, real_scratch, capacity)
    if serial:
        return _compiled(_trace_here, arguments[0])(*arguments)
    grouped = grouping(scene, rays, threads, mode) if group else None
    if grouped is not None:
        return _trace_grouped(*grouped, arguments, threads)
    return _trace_in_chunks(arguments, threads)


def grouping(scene, rays, threads, mode):
    """``(order, rays)``: the batch's rays in the order they trace fastest in
    (:mod:`raycore.ray_order`), and where each comes from; None for a batch that is small or
    coherent already, or, unless ``mode`` is PARITY, a scene whose trees are small (see
    GROUP_TREE_BYTES).

    Parameters
    ----------
    scene : SceneRecord
    rays : tuple
        ``(origins, directions, tmin, tmax)`` as :func:`raycore.rays.ray_arrays` gives them.
    threads : int
    mode : int
        The query's trace mode.

    Returns
    -------
    order : ndarray of int64, shape (N,)
    rays : tuple
        Copies of ``rays`` in that order; bounds shared by every ray stay shared.
    """
    origins, directions = rays[:2]
    n = len(origins)
    if n < GROUP_FROM or (mode != PARITY and scene.tree_bytes < GROUP_TREE_BYTES):
        return None
    # NumPy's arrays, not Numba's: see group_order
    order = np.empty(n, np.int64)
    if not group_order(origins, directions, PARTS_PER_THREAD * threads, order,
                       np.empty(n, np.int16)):
        return None
    return order, _gathered(rays, order)


def _gathered(rays, index):
    """Copies of the rays ``index`` (an int64 array) of ``rays`` (:func:`raycore.rays.
    ray_arrays`'s tuple), in NumPy's memory (see group_order); bounds shared by every ray stay
    shared."""
    origins, directions, tmin, tmax = rays
    n, m = len(origins), len(index)
    gathered = (np.empty((m, 3), origins.dtype), np.empty((m, 3), directions.dtype),
                np.empty(m, tmin.dtype) if len(tmin) == n else tmin,
                np.empty(m, tmax.dtype) if len(tmax) == n else tmax)
    gather_rays(index, *rays, *gathered)
    return gathered


def _trace_in_chunks(arguments, threads):
    """Run :func:`_trace_in_parallel` on ``trace``'s arguments."""
    # one chunk per scheduling step: rays cost very different amounts (a miss is ten times
    # cheaper than a hit), and static halves would leave one core idle
    size = min(CHUNK, max(MIN_CHUNK, len(arguments[4]) // (ITEMS_PER_THREAD * threads)))
    with parallel_chunksize(1):
        return _compiled(_trace_in_parallel, arguments[0])(*arguments, size)


#: Where ``trace``'s arguments hold the rays, and the per-ray outputs (out_t .. out_slot).
_RAYS, _OUTPUTS = slice(4, 8), slice(8, 15)


def _trace_grouped(order, rays, arguments, threads):
    """Trace ``rays``, the batch's in ``order`` (:func:`grouping`), into answers in that
    order, which are then put back in the batch's order."""
    outputs = arguments[_OUTPUTS]
    grouped = [np.empty_like(out) for out in outputs]
    first_bad = _trace_in_chunks((*arguments[:_RAYS.start], *rays, *grouped,
                                  *arguments[_OUTPUTS.stop:]), threads)
    for out, answer in zip(outputs, grouped, strict=True):
        if len(out):
            ungroup(order, answer, out)
    return order[first_bad] if first_bad < len(order) else len(order)


def closest_hits(scene, rays, test, sphere_method, barycentrics, out=None):
    """Closest hit of each ray; into ``out`` when given: ``(t, obj, prim, u, v, slot)``,
    arrays of the returned ones' dtypes and shapes (the last three with ``barycentrics``
    only), which a render's bands reuse.

    Returns
    -------
    first_bad : int
        The first refused ray, or N if none (then the other outputs are meaningless).
    t : ndarray, shape (N,)
        inf on a miss.
    obj, prim : ndarray of int64, shape (N,)
        Object (geometry id) and primitive id (face index; 0 for analytic shapes); -1 on a miss.
    surface : tuple of ndarray, shape (N,), or None
        ``(u, v, slot)``: barycentrics and slots of mesh hits (surface part of analytic ones),
        when ``barycentrics``.
    """
    n = len(rays[0])
    dtype = rays[0].dtype
    if out is None:
        t = np.empty(n, dtype)
        obj = np.empty(n, _INT64)
        prim = np.empty(n, _INT64)
        surface = (np.empty(n, dtype), np.empty(n, dtype), np.empty(n, _INT64)) \
            if barycentrics else None
    else:
        t, obj, prim, *surface = out
        surface = tuple(surface) if barycentrics else None
    if n < SERIAL_BELOW and not barycentrics:
        first_bad = _compiled(_hits_here, scene)(scene, CLOSEST, test, sphere_method, *rays, t,
                                                 obj, prim, _NO_FLAGS)
    else:
        first_bad = trace(scene, CLOSEST, rays, test, sphere_method, out_t=t, out_obj=obj,
                          out_prim=prim, barycentrics=surface)
    return first_bad, t, obj, prim, surface


def any_hits(scene, rays, test, sphere_method):
    """First refused ray (or N), and (N,) bool: whether each ray hits anything in [tmin, tmax],
    stopping at the first hit."""
    n = len(rays[0])
    hit = np.empty(n, _BOOL)
    if n < SERIAL_BELOW:
        first_bad = _compiled(_any_here, scene)(scene, test, sphere_method, *rays, hit)
    else:
        first_bad = trace(scene, ANY, rays, test, sphere_method, out_hit=hit)
    return first_bad, hit


def crossing_counts(scene, rays, test, sphere_method, mode=COUNT, out_hit=None, group=True,
                    listing=None):
    """First refused ray (or N), the (N,) int64 crossings of each ray (a shared edge or vertex
    crossed once counts once), and the hit-list capacity that held every ray's crossings.

    With ``mode`` PARITY, ``out_hit`` ((N,) bool) also receives whether each ray crosses some
    closed object an odd number of times.  With ``listing``, ``(offsets, hits)`` as
    :func:`all_hits` makes them, the pass lists the crossings that fit there (mode LIST of
    :func:`raycore.bvh.traverse.trace_range`), in the order the rays are given: such a pass is
    never grouped.  ``group`` as :func:`trace`'s."""
    counts = np.empty(len(rays[0]), _INT64)
    offsets, hits = _NO_OFFSETS, None
    if listing is not None:
        # LIST writes offsets[i] for every ray: never with the shared one-element default
        mode, (offsets, hits), group = LIST, listing, False
    capacity = HIT_CAPACITY
    serial = listing is None and len(counts) < SERIAL_BELOW
    while True:
        if serial and capacity == HIT_CAPACITY:
            first_bad = _compiled(_hits_here, scene)(
                scene, mode, test, sphere_method, *rays, _EMPTY[rays[0].dtype], counts, _NO_INTS,
                _NO_FLAGS if out_hit is None else out_hit)
        else:
            first_bad = trace(scene, mode, rays, test, sphere_method, out_obj=counts,
                              out_hit=out_hit, offsets=offsets, hits=hits, capacity=capacity,
                              group=group)
        most = -int(counts.min()) if len(counts) else 0
        if first_bad < len(counts) or most <= capacity:
            return first_bad, counts, capacity
        # a ray crossed more surfaces than the list holds: again, with room for all of them
        capacity = most


def odd_crossings(scene, rays, test, sphere_method):
    """First refused ray (or N), and (N,) bool: whether each ray crosses some closed object an
    odd number of times (it starts inside that object)."""
    odd = np.empty(len(rays[0]), _BOOL)
    first_bad, _, _ = crossing_counts(scene, rays, test, sphere_method, PARITY, odd)
    return first_bad, odd


def all_hits(scene, rays, test, sphere_method, max_hits=None):
    """Every crossing of each ray, sorted by t, one per surface crossing; ``TooManyHits``
    when there are more than ``max_hits`` (None: no limit), before their arrays are made.

    Returns
    -------
    first_bad : int
    counts : ndarray of int64, shape (N,)
    t : ndarray, shape (H,)
    obj, prim : ndarray of int64, shape (H,)
        Crossings of ray i are at ``[offsets[i], offsets[i + 1])`` with offsets the cumulative
        counts; ``prim`` as in :func:`closest_hits`.
    """
    # One pass counts the crossings and lists them in LIST_ROOM places a ray; they are then
    # moved to exactly-sized arrays, and only rays that found no room are traced again (a
    # count pass and a fill pass traced every ray twice).  A batch is grouped once.
    n = len(rays[0])
    grouped = grouping(scene, rays, get_num_threads(), LIST) if n >= SERIAL_BELOW else None
    order, traced = (np.arange(0), rays) if grouped is None else grouped
    listed_at = np.empty(n, np.int64)
    listed = (np.empty(LIST_ROOM * n, rays[0].dtype), np.empty(LIST_ROOM * n, np.int64),
              np.empty(LIST_ROOM * n, np.int64))
    first_bad, traced_counts, capacity = crossing_counts(
        scene, traced, test, sphere_method, listing=(listed_at, listed))
    counts = traced_counts
    if len(order):
        first_bad = order[first_bad] if first_bad < n else n
        counts = np.empty_like(traced_counts)
        ungroup(order, traced_counts, counts)
    if first_bad < n:
        return first_bad, counts, None, None, None
    offsets = np.zeros(n + 1, np.int64)
    counts.cumsum(out=offsets[1:])
    # where each traced ray's crossings go in the batch's order
    places = offsets[order] if len(order) else offsets[:-1]
    total = int(offsets[-1])
    if max_hits is not None and total > max_hits:
        raise TooManyHits(total, max_hits)
    hits = (np.empty(total, rays[0].dtype), np.empty(total, np.int64), np.empty(total, np.int64))
    if _compiled(_move_lists, scene)(listed_at, traced_counts, places, *listed, *hits):
        again = np.flatnonzero(listed_at < 0)
        trace(scene, ALL, _gathered(traced, again), test, sphere_method,
              out_obj=np.empty(len(again), np.int64), offsets=places[again], hits=hits,
              capacity=capacity, group=False)
    return first_bad, counts, *hits


@njit(cache=True)
def _move_lists(listed_at, counts, places, listed_t, listed_obj, listed_prim, hits_t, hits_obj,
                hits_prim):
    """Copy each ray's crossings from where :func:`all_hits`'s pass listed them
    (``listed_at``; -1 where they did not fit) to their places in the answer, and count the
    rays whose crossings did not fit."""
    unlisted = 0
    for i in range(len(counts)):
        at = listed_at[i]
        if at < 0:
            unlisted += 1
            continue
        to = places[i]
        for j in range(counts[i]):
            hits_t[to + j] = listed_t[at + j]
            hits_obj[to + j] = listed_obj[at + j]
            hits_prim[to + j] = listed_prim[at + j]
    return unlisted


def surface_fields(record, origins, directions, t, obj, slot, u, v, want_uv, want_normal,
                   want_point, miss=np.nan):
    """Surface data of closest hits, computed after traversal and only for the asked fields.

    Parameters
    ----------
    record : SceneRecord
    origins, directions : ndarray, shape (N, 3)
    t : ndarray, shape (N,)
    obj, slot : ndarray of int64, shape (N,)
        Object hit (-1 on a miss), and the slot of a mesh hit or the surface part of an
        analytic one.
    u, v : ndarray, shape (N,)
        Barycentrics of mesh hits.
    miss : float
        The misses' rows: NaN, or what a caller's format asks (Open3D's zeros, written here
        rather than by a pass over the fields after: that pass took a seventh of a
        ``cast_rays``).

    Returns
    -------
    uv : ndarray, shape (N, 2) or (0, 2)
    normal, point : ndarray, shape (N, 3) or (0, 3)
        ``miss`` rows for misses; empty when not asked for.
    """
    n = len(t)
    # NumPy's arrays on a huge page boundary (raycore._memory), filled without reference
    # counts: a view per ray (a parameter row, a leaf block) made the pass 10x slower with them
    uv = empty_aligned((n if want_uv else 0, 2), t.dtype)
    normal = empty_aligned((n if want_normal else 0, 3), t.dtype)
    point = empty_aligned((n if want_point else 0, 3), t.dtype)
    _fill_surface_fields(record, origins, directions, t, obj, slot, u, v, uv, normal, point,
                         float(miss))
    return uv, normal, point


#: :func:`raycore.primitives.analytic.analytic_surface` inlined into :func:`hit_surface`: a
#: call per analytic hit, its parameter row passed as an array, made the demo render's fields
#: (836K plane hits of 1M rays) 7.6 ms, inlined 4.3 ms.  Not cached on its own: it is compiled
#: into the passes that call hit_surface, which are.
_analytic_surface_inline = njit(error_model="numpy", forceinline=True)(analytic_surface.py_func)


@njit(error_model="numpy", forceinline=True)
def _table_surface(params, row, kind, ox, oy, oz, dx, dy, dz, t, part, want_uv):
    """:func:`_analytic_surface_inline` of the shape in row ``row`` of a scene's parameter table
    ``params``; NaN where the scene holds no shapes (``params`` None), which compiles the shapes'
    code away, as :func:`raycore.primitives.analytic.table_hit` does."""
    if params is None:
        nan = like(ox, np.nan)
        return nan, nan, nan, nan, nan
    return _analytic_surface_inline(kind, params[row], ox, oy, oz, dx, dy, dz, t, part, want_uv)


@njit(cache=True)
def _fill_surface_fields(record, origins, directions, t, obj, slot, u, v, uv, normal, point,
                         miss):
    _surface_fields(tabled_arrays_of(record), origins, directions, t, obj, slot, u, v, uv, normal,
                    point, miss)


@njit(cache=True, parallel=True, error_model="numpy", _nrt=False)
def _surface_fields(scene, origins, directions, t, obj, slot, u, v, uv, normal, point, miss):
    """Fill the rows of ``uv``, ``normal`` and ``point`` (each N rows, or none) for each ray;
    ``miss`` in every value of a miss's rows."""
    n = len(t)
    want_uv, want_normal, want_point = len(uv) == n, len(normal) == n, len(point) == n
    for i in prange(n):
        if obj[i] < 0:
            for a in range(3):
                if want_uv and a < 2:
                    uv[i, a] = miss
                if want_normal:
                    normal[i, a] = miss
                if want_point:
                    point[i, a] = miss
            continue
        # before any store: the compiler cannot tell that the outputs do not overlap the rays
        nx, ny, nz, su, sv = hit_surface(scene, origins, directions, t, obj, slot, u, v, i,
                                         want_normal, want_uv)
        if want_point:
            ox, oy, oz = origins[i, 0], origins[i, 1], origins[i, 2]
            dx, dy, dz = directions[i, 0], directions[i, 1], directions[i, 2]
            point[i, 0] = ox + t[i] * dx
            point[i, 1] = oy + t[i] * dy
            point[i, 2] = oz + t[i] * dz
        if want_uv:
            uv[i, 0] = su
            uv[i, 1] = sv
        if want_normal:
            normal[i, 0] = nx
            normal[i, 1] = ny
            normal[i, 2] = nz


@njit(inline="always")
def hit_surface(scene, origins, directions, t, obj, slot, u, v, i, want_normal, want_uv):
    """Unit geometric normal and surface parameters ``(u, v)`` of hit ``i`` (not a miss), in
    the rays' precision, as :func:`surface_fields` gives them; for the passes over closest hits
    (``scene``: :data:`raycore.bvh.record.SceneArrays`).  A mesh hit's normal is only computed
    when ``want_normal``, an analytic hit's ``(u, v)`` when ``want_uv`` (else NaN)."""
    real = t[i]  # of the rays' precision
    k = scene.kind[obj[i]]
    if k != MESH:
        nx, ny, nz, su, sv = _table_surface(
            scene.params, scene.param_row[obj[i]], k, origins[i, 0], origins[i, 1],
            origins[i, 2], directions[i, 0], directions[i, 1], directions[i, 2], t[i], slot[i],
            want_uv)
        return like(real, nx), like(real, ny), like(real, nz), like(real, su), like(real, sv)
    nan = like(real, np.nan)
    if not want_normal:
        return nan, nan, nan, u[i], v[i]
    blocks = scene.blocks
    s = slot[i]
    nx, ny, nz = triangle_normal(
        slot_value(blocks, s, 0), slot_value(blocks, s, 1), slot_value(blocks, s, 2),
        slot_value(blocks, s, 3), slot_value(blocks, s, 4), slot_value(blocks, s, 5),
        slot_value(blocks, s, 6), slot_value(blocks, s, 7), slot_value(blocks, s, 8))
    r = scene.xform_row[obj[i]]
    if r >= 0:
        # normals transform by the inverse transpose; xforms hold the inverse
        m = scene.xforms
        nx, ny, nz = (m[r, 0] * nx + m[r, 4] * ny + m[r, 8] * nz,
                      m[r, 1] * nx + m[r, 5] * ny + m[r, 9] * nz,
                      m[r, 2] * nx + m[r, 6] * ny + m[r, 10] * nz)
        length = np.sqrt(nx * nx + ny * ny + nz * nz)
        nx, ny, nz = nx / length, ny / length, nz / length
    return like(real, nx), like(real, ny), like(real, nz), u[i], v[i]
