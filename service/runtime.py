"""What the routes share: settings, the store (in memory, and on disk when configured), and the
slots for geometry work."""

import asyncio
import threading
from dataclasses import dataclass, field
from functools import partial

import anyio
from fastapi import Request

from service.config import Settings
from service.datadir import DataDir
from service.errors import LimitExceeded, NotFound
from service.store import Store


@dataclass
class Runtime:
    """Per-app state, created by :func:`service.app.create_app`.

    ``limiter`` and ``startup`` (the task that loads the demo scene, if any) are made at
    startup, inside the event loop that they belong to.  With a data directory, the memory
    store is a cache of it: what is kept goes to disk first, and a miss in memory looks there.
    """

    settings: Settings
    store: Store
    disk: DataDir | None = None  # the data directory, when RAYCORE_DATA_DIR is set
    ready: threading.Event = field(default_factory=threading.Event)
    limiter: anyio.CapacityLimiter | None = None
    startup: asyncio.Task | None = None

    async def compute(self, function, *args):
        """Run CPU work in a worker thread, off the event loop, ``compute_slots`` at once.

        The kernels' parallel loops release the GIL, so the event loop keeps serving (health
        checks, other uploads) while one runs; their serial parts and NumPy calls hold it for
        tens of milliseconds at most.
        """
        return await anyio.to_thread.run_sync(partial(function, *args), limiter=self.limiter)

    async def get(self, kind, key):
        """A stored mesh or scene; NotFound when there is none under ``key``.

        A miss while startup work runs waits for it: the demo scene exists once it is done.
        With several workers, a client that saw another worker answer /readyz cannot tell that
        this one is still loading.  A miss in memory reads the data directory, off the event
        loop.
        """
        entry = self.store.get(kind, key)
        if entry is None and self.startup is not None and not self.startup.done():
            await asyncio.shield(self.startup)  # a client that leaves must not cancel startup
            entry = self.store.get(kind, key)
        if entry is None and self.disk is not None:
            entry = await anyio.to_thread.run_sync(self.find, kind, key)
        elif entry is not None:
            self._used(kind, key)
        if entry is None:
            raise _not_found(kind, key)
        return entry

    def find(self, kind, key):
        """:meth:`get` for worker threads: the entry from memory or the data directory, or
        None."""
        entry = self.store.get(kind, key)
        if entry is None:
            return None if self.disk is None else self._from_disk(kind, key)
        self._used(kind, key)
        return entry

    def _used(self, kind, key):
        """Mark a memory hit as the entry's last use in the data directory too (its file's
        time orders the eviction of every worker sharing the directory)."""
        if self.disk is not None:
            self.disk.touch(kind, key)

    def _from_disk(self, kind, key):
        loaded = self.disk.load(kind, key)
        if loaded is None:
            return None
        try:
            return self.store.put(kind, key, *loaded)[0]
        except LimitExceeded:  # larger than the memory budget allows: answer from it once
            return loaded[0]

    def keep(self, kind, key, entry, nbytes):
        """Store a new mesh or scene: in the data directory first (flushed, so that it
        survives a crash once this returns), then in memory.  Call it from a worker thread.

        Returns
        -------
        entry, created : the stored entry and whether it is new (in memory and on disk)
        """
        stored_before = self.disk is not None and not self.disk.save(kind, key, entry)
        entry, created = self.store.put(kind, key, entry, nbytes)
        return entry, created and not stored_before

    def delete(self, kind, key):
        """Remove a stored mesh or scene, from memory and the data directory; NotFound when
        there is none under ``key``."""
        found = self.store.delete(kind, key)
        if self.disk is not None:
            found = self.disk.delete(kind, key) or found
        if not found:
            raise _not_found(kind, key)

    def listing(self, kind):
        """``(id, bytes, last used)`` of every ``kind`` entry in memory or on disk, by id (a
        file's bytes and time where only the data directory holds it)."""
        entries = {key: (nbytes, used) for key, nbytes, used in self.store.listing(kind)}
        if self.disk is not None:
            entries = {**self.disk.listing(kind), **entries}
        return sorted((key, nbytes, used) for key, (nbytes, used) in entries.items())


def _not_found(kind, key):
    return NotFound(f"no {kind} {key!r} (it may have been evicted: send it again)")


def runtime(request: Request) -> Runtime:
    """FastAPI dependency: the app's Runtime."""
    return request.app.state.runtime
