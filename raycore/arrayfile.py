"""A file of named NumPy arrays behind a JSON header: checked on reading, memory-mappable.

Layout (little-endian)::

    [0:8]    magic b"\\x89RAYCORE"
    [8:12]   uint32 format version
    [12:16]  uint32 header length H
    [16:20]  uint32 CRC-32 of the header
    [20:20+H] UTF-8 JSON: {"meta": {...}, "arrays": [[name, dtype, shape, offset], ...],
             "data_bytes": D, "crc32": [CRC-32 of each CHUNK bytes of the data]}
    then, from the first multiple of ALIGN past the header (the data's start S), each array's
    raw C-order bytes at S + its offset (a multiple of ALIGN), zeros between them; the file ends
    at S + D

Nothing is pickled: the header is JSON and the arrays are plain numbers of the dtypes it names,
so a file cannot run code when read.  The data carries CRC-32s, and the header its own, so that
a flipped bit or a truncated copy is refused rather than answered from.  Arrays start on 64-byte
boundaries, so that a memory map gives aligned views that compiled kernels take as they are
(Numba types a misaligned array differently, and would compile its kernels again).

Format version 1 gave each array its own CRC-32s, in an entry of named fields; it is still read.
Version 2 checks the data as one piece, and its entries are lists: a small scene's load spent
more time on a header entry and a checksum call per array than on its arrays (20 arrays:
66 -> 47 us to parse the file of a 968-triangle scene, suzanne).  Version 3 is version 2's
layout with fewer arrays in a scene file (:mod:`raycore.scene_file`: one object table, no empty
tables), which a reader of version 2 would take for a corrupt one.
"""

import json
import mmap as memory_map
import os
import struct
import tempfile
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from numba import get_num_threads
from zlib_ng import zlib_ng

from raycore._memory import empty_on_line
from raycore.rays import flag

MAGIC = b"\x89RAYCORE"
#: Version of this layout and of what :mod:`raycore.scene_file` puts in it; a reader refuses a
#: newer one.
VERSION = 3
ALIGN = 64
#: Arrays are checksummed in pieces of this many bytes (the file records a CRC-32 for each).
#: zlib-ng computes the standard CRC-32 that zlib does, with carry-less multiplication: 32 GB/s
#: on 150 MB here, against zlib's 4.2, so a file is checked on one thread in a fraction of the
#: time it takes to read.
CHUNK = 1 << 21
_PREFIX = struct.Struct("<8sIII")
#: A file of this many bytes or more is read, and its CRC-32s are computed, on as many threads
#: as raycore's kernels run on (Numba's): reading one is the kernel zeroing pages and copying
#: into them, the most of a large scene's load.  The 148 MB of nefertiti-1.6M: 52.6 -> 29.6 ms
#: read and checked on two threads (the other core idle), 58-62 -> 44-55 ms to load (the other
#: core busy); below some 40 MB, a second thread cost more than it saved.
THREADED_BYTES = 64 << 20
#: The dtypes a file may hold, by the names the header gives them: numbers only (an object dtype
#: would need pickle).
DTYPES = {name: np.dtype(name) for name in ("<f4", "<f8", "<i4", "<i8", "|u1", "|b1")}


def _aligned(offset):
    return -(-offset // ALIGN) * ALIGN


def _bytes(array):
    """The array's memory as a flat uint8 array (no copy for a C-contiguous one)."""
    return np.ascontiguousarray(array).reshape(-1).view(np.uint8)


def _crcs(array, mapping=map):
    """CRC-32 of each CHUNK bytes of a C-contiguous array's memory (one for an empty array),
    computed in the calls that ``mapping`` makes: ``map``, or a thread pool's (zlib-ng lets go
    of the GIL)."""
    if array.nbytes <= CHUNK:  # most files: their memory as it is, no slices of it
        return [zlib_ng.crc32(array)]
    data = _bytes(array)
    return list(mapping(zlib_ng.crc32, [data[i:i + CHUNK] for i in range(0, len(data), CHUNK)]))


def _streamed_crcs(parts):
    """What :func:`_crcs` gives for the concatenation of ``parts`` (bytes-like), without
    concatenating them: the writer checksums the data as it will lie in the file."""
    crcs, crc, filled = [], 0, 0
    for part in parts:
        view = memoryview(part).cast("B")
        while len(view):
            take = min(CHUNK - filled, len(view))
            crc = zlib_ng.crc32(view[:take], crc)
            filled += take
            view = view[take:]
            if filled == CHUNK:
                crcs.append(crc)
                crc = filled = 0
    if filled or not crcs:
        crcs.append(crc)
    return crcs


def encode(meta, arrays):
    """Yield the file's bytes, in parts, for ``meta`` (a JSON-able dict) and ``arrays``.

    Parameters
    ----------
    meta : dict
    arrays : dict of str to ndarray
        Each of one of :data:`DTYPES` (native little-endian), any shape.

    Yields
    ------
    bytes or memoryview
        The prefix and header, then each array's bytes and the padding around them.
    """
    entries, data, offset = [], [], 0
    for name, array in arrays.items():
        array = np.ascontiguousarray(array)
        if array.dtype.str not in DTYPES:
            raise ValueError(f"array {name!r} has dtype {array.dtype}, not one of "
                             f"{tuple(DTYPES)}")
        entries.append([name, array.dtype.str, list(array.shape), offset])
        data.append(_bytes(array))
        end = offset + array.nbytes
        offset = _aligned(end)
        data.append(bytes(offset - end))
    header = json.dumps({"meta": meta, "arrays": entries, "data_bytes": offset,
                         "crc32": _streamed_crcs(data)}).encode()
    prefix = _PREFIX.pack(MAGIC, VERSION, len(header), zlib_ng.crc32(header)) + header
    yield prefix + bytes(_aligned(len(prefix)) - len(prefix))
    yield from data


#: Glob pattern of the temporary files that :func:`write` makes beside their target (a writer
#: killed mid-write leaves one behind).
TEMPORARY_PATTERN = ".*.tmp"


def checked(arrays, name, dtype, shape, what="the file"):
    """``arrays[name]`` (of a file :func:`read` returned), with ``dtype`` and ``shape`` (ints,
    or None for any length); ``ValueError`` saying that ``what`` is corrupt otherwise."""
    array = arrays.get(name)
    if array is None:
        raise ValueError(f"{what} is corrupt (array {name!r} is missing)")
    # a plain loop: every array of a file is taken so, and any() of a generator, or zip(), took
    # longer than the rest of the call
    if array.dtype == dtype and array.ndim == len(shape):
        got = array.shape
        for axis, want in enumerate(shape):
            if want is not None and got[axis] != want:
                break
        else:
            return array
    raise ValueError(f"{what} is corrupt (array {name!r} is {array.dtype} {array.shape}, "
                     f"not {np.dtype(dtype)} {shape})")


def write(path, meta, arrays):
    """Write the file atomically: a temporary file beside ``path``, flushed to disk (fsync),
    then renamed over it, so that a reader (or a crash) sees no file or the whole new one."""
    path = os.path.abspath(os.fspath(path))
    descriptor, temporary = tempfile.mkstemp(dir=os.path.dirname(path),
                                             prefix=f".{os.path.basename(path)}.", suffix=".tmp")
    try:
        with os.fdopen(descriptor, "wb") as file:
            for part in encode(meta, arrays):
                file.write(part)
            file.flush()
            os.fsync(file.fileno())
        os.replace(temporary, path)
    finally:
        if os.path.exists(temporary):  # not renamed: an error or an interrupt came first
            os.unlink(temporary)
    directory = os.open(os.path.dirname(path), os.O_RDONLY)
    try:
        os.fsync(directory)  # the rename itself survives a power cut
    finally:
        os.close(directory)


def read(source, *, mmap=False):
    """Read a file written by :func:`write` (or the bytes of one).

    Parameters
    ----------
    source : str, path-like, bytes or bytearray
    mmap : bool
        Map the file rather than read it: the arrays are copy-on-write views of its pages
        (shared with other processes that map it, read from disk as they are touched).

    Returns
    -------
    meta : dict
    arrays : dict of str to ndarray
        Writable, aligned, in the dtypes and shapes the header names.

    Raises
    ------
    ValueError
        When the source is not such a file, is truncated, fails a checksum, or has a newer
        format version; the message says which.
    """
    # read into memory that starts on a cache line, as a map's pages do, so that the arrays,
    # on 64-byte boundaries of the file, start on lines too (raycore.bvh.leaves.empty_blocks)
    if not isinstance(source, (str, os.PathLike, bytes, bytearray, memoryview)):
        # open() would take an integer as a file descriptor, and close it
        raise ValueError(f"path must be a file path (str or os.PathLike) or the file's bytes, "
                         f"got {type(source).__name__}")
    mmap = flag(mmap, "mmap")
    if isinstance(source, (bytes, bytearray, memoryview)):
        raw = empty_on_line(len(source), np.uint8)  # aligned and writable
        raw[:] = np.frombuffer(source, np.uint8)
    elif mmap:
        with open(source, "rb", buffering=0) as file:
            size = os.fstat(file.fileno()).st_size
            if size < _PREFIX.size:  # mmap refuses an empty file
                raise ValueError(f"{source} is truncated: {size} bytes")
            # copy-on-write pages (np.memmap took 9 us more to set up, and the arrays, views
            # of a memmap, would have been memmaps: Numba types those apart)
            raw = np.frombuffer(memory_map.mmap(file.fileno(), 0, access=memory_map.ACCESS_COPY),
                                np.uint8)
    else:
        with open(source, "rb", buffering=0) as file:  # unbuffered: reads go straight into raw
            raw = empty_on_line(os.fstat(file.fileno()).st_size, np.uint8)
            threads = get_num_threads() if len(raw) >= THREADED_BYTES else 1
            if threads > 1:
                with ThreadPoolExecutor(threads) as pool:
                    _read_into(raw, file, pool.map)
                    return _parse(raw, pool.map)
            _read_into(raw, file)
    return _parse(raw)


def _read_into(raw, file, mapping=None):
    """Read ``file`` (unbuffered, as long as ``raw``) into ``raw``: in turn, or in pieces that
    the threads of ``mapping`` (a thread pool's map) read at once, where the platform reads at
    an offset (``os.preadv``: not on Windows)."""
    view = memoryview(raw)
    if mapping is not None and hasattr(os, "preadv"):
        # pieces of a few chunks, each taken by whichever thread is free: one that another
        # process holds up takes fewer of them
        piece = 4 * CHUNK
        done = sum(mapping(lambda start: _read_at(file, view[start:start + piece], start),
                           range(0, len(raw), piece)))
    else:
        done = 0
        while done < len(raw) and (count := file.readinto(view[done:])):  # <= 2 GB a call
            done += count
    if done != len(raw):
        raise ValueError(f"{file.name} changed while it was read")


def _read_at(file, view, offset):
    """How many bytes of ``file`` from ``offset`` were read into ``view`` (all, but at the
    file's end): positional reads, which threads sharing the file may make at once."""
    done = 0
    while done < len(view) and (count := os.preadv(file.fileno(), [view[done:]],
                                                   offset + done)):
        done += count
    return done


def _parse(raw, mapping=map):
    """``(meta, arrays)`` of a file's bytes ``raw``, checked; a large file's checksums in the
    calls that ``mapping`` makes (:func:`_crcs`)."""
    if len(raw) < _PREFIX.size:
        raise ValueError(f"the scene file is truncated: {len(raw)} bytes")
    magic, version, header_bytes, header_crc = _PREFIX.unpack(bytes(raw[:_PREFIX.size]))
    if magic != MAGIC:
        raise ValueError("not a raycore scene file (wrong magic number)")
    if version > VERSION:
        raise ValueError(f"the scene file has format version {version}, newer than this "
                         f"raycore reads ({VERSION}): upgrade raycore")
    if version < 1:
        raise ValueError(f"the scene file has an unknown format version {version}")
    end = _PREFIX.size + header_bytes
    if len(raw) < end:
        raise ValueError("the scene file is truncated (in its header)")
    header = bytes(raw[_PREFIX.size:end])
    if zlib_ng.crc32(header) != header_crc:
        raise ValueError("the scene file is corrupt (its header fails its checksum)")
    try:
        header = json.loads(header)
        meta, entries = header["meta"], header["arrays"]
        start = _aligned(end)
        file_bytes = start + int(header["data_bytes"])
    except (ValueError, KeyError, TypeError) as error:
        raise ValueError(f"the scene file is corrupt (unreadable header: {error})") from error
    if not isinstance(meta, dict) or not isinstance(entries, list):
        raise ValueError("the scene file is corrupt (its header lacks meta or arrays)")
    if len(raw) < file_bytes:
        raise ValueError(f"the scene file is truncated: {len(raw)} of {file_bytes} bytes")
    if len(raw) > file_bytes:
        raise ValueError(f"the scene file is corrupt: {len(raw) - file_bytes} bytes past its end")
    if version >= 2:
        sums, expected = _crcs(raw[start:file_bytes], mapping), header.get("crc32")
        if sums != expected:  # a wrong count of checksums does not match either
            where = _failed_chunk(sums, expected, entries, file_bytes - start)
            raise ValueError(f"the scene file is corrupt (its data fails its checksum in {where})")
    arrays = {}
    for entry in entries:
        name, array = _array(raw, entry, start, version, mapping)
        arrays[name] = array
    return meta, arrays


def _array(raw, entry, start, version, mapping):
    """``(name, array)`` of a header ``entry``: a view of ``raw`` (which ends where the file
    does), once the entry is found sound (and, in version 1, the array's bytes pass their
    checksums)."""
    try:
        if version >= 2:
            name, dtype, shape, offset = entry
        else:
            name, dtype, shape, offset = (entry["name"], entry["dtype"], entry["shape"],
                                          entry["offset"])
        dtype = DTYPES[dtype]
        offset += start
    except (KeyError, TypeError, ValueError) as error:
        raise ValueError(f"the scene file is corrupt (bad array entry {entry})") from error
    if not isinstance(name, str) or offset < start or offset % ALIGN:
        raise ValueError(f"the scene file is corrupt (array {name!r}: {entry})")
    try:  # np.ndarray refuses a shape of other than integers, or one past raw's end
        array = np.ndarray(shape, dtype, raw, offset)  # (buffer, offset: by keyword, 50% dearer)
        if array.shape != tuple(shape):  # a length of -1, which np.ndarray takes as "the rest"
            raise ValueError(f"shape {shape}")
    except (ValueError, TypeError, OverflowError) as error:  # OverflowError: past 2^63
        raise ValueError(f"the scene file is corrupt (array {name!r} lies outside it or has a "
                         f"bad shape: {error})") from error
    # the header's list is compared as it is: a wrong count of checksums does not match either
    if version == 1 and _crcs(array, mapping) != entry.get("crc32"):
        raise ValueError(f"the scene file is corrupt (array {name!r} fails its checksum)")
    return name, array


def _failed_chunk(sums, expected, entries, data_bytes):
    """Where ``data_bytes`` of data failed their checksums: the bytes of the first chunk whose
    CRC-32 in ``sums`` differs from the header's (``expected``), and the arrays that lie in
    them."""
    expected = expected if isinstance(expected, list) else []
    both = min(len(sums), len(expected))
    chunk = next((i for i in range(both) if sums[i] != expected[i]), both)
    low, high = chunk * CHUNK, min((chunk + 1) * CHUNK, data_bytes)
    try:
        names = [repr(name) for name, dtype, shape, offset in entries
                 if offset < high and offset + np.prod(shape) * DTYPES[dtype].itemsize > low]
    except (KeyError, TypeError, ValueError):  # a malformed entry: the message names no arrays
        names = []
    return f"bytes {low}-{high}" + (f", which hold arrays {', '.join(names)}" if names else "")
