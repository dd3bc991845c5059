"""What the routes share: settings, the store, and the slots for geometry work."""

import asyncio
import threading
from dataclasses import dataclass, field
from functools import partial

import anyio
from fastapi import Request

from service.config import Settings
from service.errors import NotFound
from service.store import Store


@dataclass
class Runtime:
    """Per-app state, created by :func:`service.app.create_app`.

    ``limiter`` and ``startup`` (the task that loads the demo scene, if any) are made at
    startup, inside the event loop that they belong to.
    """

    settings: Settings
    store: Store
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
        this one is still loading.
        """
        entry = self.store.get(kind, key)
        if entry is None and self.startup is not None and not self.startup.done():
            await asyncio.shield(self.startup)  # a client that leaves must not cancel startup
            entry = self.store.get(kind, key)
        if entry is None:
            raise _not_found(kind, key)
        return entry

    def delete(self, kind, key):
        """Remove a stored mesh or scene; NotFound when there is none under ``key``."""
        if not self.store.delete(kind, key):
            raise _not_found(kind, key)


def _not_found(kind, key):
    return NotFound(f"no {kind} {key!r} (it may have been evicted: send it again)")


def runtime(request: Request) -> Runtime:
    """FastAPI dependency: the app's Runtime."""
    return request.app.state.runtime
