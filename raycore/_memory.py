"""Arrays that start on a boundary: a huge page for large ones, a cache line for tables.

NumPy asks the kernel for huge (2 MiB) pages on arrays of 4 MiB and more (``madvise``), but only
whole, aligned 2 MiB ranges can be huge pages: the rest of an array that starts anywhere else is
faulted in by 4 KiB pages, up to 2 MiB of them (512 faults of ~1 us).  Seven arrays of one
million rays (4 to 12 MB each), written in turn with one thread: 3,581 faults and 11.1 ms as
``np.empty`` gives them, 43 faults and 6.8 ms from :func:`empty_aligned`.  A 512x512, 4-sample
demo render between tracing calls (as benchmarks/render_cost.py times it): 7,686 -> 2,618 faults
a render, 81-82 -> 75-76 ms; renders one after another, whose memory the allocator reuses, gain
nothing measurable.
"""

import numpy as np

HUGE_PAGE = 2 << 20
#: Bytes of a cache line.
LINE = 64


def empty_aligned(shape, dtype):
    """``np.empty(shape, dtype)`` on a 2 MiB boundary, C-contiguous and writable.

    Parameters
    ----------
    shape : tuple of int
    dtype : numpy dtype

    Returns
    -------
    ndarray, shape ``shape``
        A view of a buffer up to two huge pages longer, whose untouched ends take no memory.
    """
    dtype = np.dtype(dtype)
    nbytes = int(np.prod(shape)) * dtype.itemsize
    if nbytes < 2 * HUGE_PAGE:  # NumPy gives no huge pages below 4 MiB
        return np.empty(shape, dtype)
    # whole huge pages from the boundary on, so that the last one is a huge page too
    buffer = np.empty(-(-nbytes // HUGE_PAGE) * HUGE_PAGE + HUGE_PAGE, np.uint8)
    start = -buffer.ctypes.data % HUGE_PAGE
    return buffer[start:start + nbytes].view(dtype).reshape(shape)


def empty_on_line(count, dtype):
    """``np.empty(count, dtype)`` starting on a cache line (NumPy aligns to 16 bytes): rows of
    a multiple of LINE bytes carved from it each take whole lines, none shared.

    One large enough for huge pages starts on one (:func:`empty_aligned`): reading a 148 MB
    scene file into it took 72 page faults rather than 518, and 1.5 ms less of 55.
    """
    dtype = np.dtype(dtype)
    if count * dtype.itemsize >= 2 * HUGE_PAGE:
        return empty_aligned((count,), dtype)
    memory = np.empty(count + LINE // dtype.itemsize, dtype)
    start = -memory.ctypes.data % LINE // dtype.itemsize
    return memory[start:start + count]
