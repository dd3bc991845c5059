"""Content-addressed store of meshes and built scenes, in memory, under a byte budget.

Entries are keyed by ``(kind, id)``; the least recently used go first when a new one does not
fit.  Pinned entries (the demo scene) are never evicted.  Request threads share one store, so
every operation holds a lock; building what goes in happens outside it.
"""

import hashlib
import threading
import time
from collections import OrderedDict

from service.errors import LimitExceeded

#: Bytes charged to every entry on top of its arrays: the Python objects around them (the
#: Scene, its geometry records, the info models) take 5 to 20 kB even for a single sphere, so
#: that without this charge a budget of arrays would let millions of tiny scenes in.
ENTRY_OVERHEAD = 32 * 1024


def content_id(*parts):
    """128-bit hex digest of byte strings (length-prefixed, so that parts cannot run together)."""
    digest = hashlib.sha256()
    for part in parts:
        digest.update(len(part).to_bytes(8, "little"))
        digest.update(part)
    return digest.hexdigest()[:32]


class Store:
    """Least-recently-used map from ``(kind, id)`` to values of known size.

    Parameters
    ----------
    budget : int
        Bytes the entries may hold in all.
    """

    def __init__(self, budget):
        self.budget = budget
        self._entries = OrderedDict()  # (kind, id) -> (value, nbytes, pinned), oldest first
        self._used = {}  # (kind, id) -> time.time() of the last put or get
        self._aliases = {}  # (kind, name) -> id
        self._bytes = 0
        self._lock = threading.Lock()

    @property
    def nbytes(self):
        """Bytes held now."""
        return self._bytes

    def get(self, kind, key):
        """The value stored under ``key`` (or an alias of it), marked as just used; else None."""
        with self._lock:
            key = self._aliases.get((kind, key), key)
            entry = self._entries.get((kind, key))
            if entry is None:
                return None
            self._entries.move_to_end((kind, key))
            self._used[(kind, key)] = time.time()
            return entry[0]

    def put(self, kind, key, value, nbytes, *, pinned=False):
        """Store ``value`` (keeping an equal one already there); evict to stay within budget.

        Returns
        -------
        value, created : the stored value and whether it is new

        Raises
        ------
        LimitExceeded
            When ``nbytes`` exceeds what the pinned entries leave of the budget.
        """
        with self._lock:
            if (kind, key) in self._entries:
                self._entries.move_to_end((kind, key))
                self._used[(kind, key)] = time.time()
                return self._entries[(kind, key)][0], False
            pinned_bytes = sum(size for _, size, pin in self._entries.values() if pin)
            if nbytes > self.budget - pinned_bytes:
                raise LimitExceeded(f"the {kind} needs {nbytes} bytes; the store keeps at most "
                                f"{self.budget - pinned_bytes} bytes for it")
            for old in list(self._entries):
                if self._bytes + nbytes <= self.budget:
                    break
                if not self._entries[old][2]:
                    self._bytes -= self._entries.pop(old)[1]
                    del self._used[old]
            self._entries[(kind, key)] = (value, nbytes, pinned)
            self._used[(kind, key)] = time.time()
            self._bytes += nbytes
            return value, True

    def alias(self, kind, name, key):
        """Make ``name`` another key for ``key``."""
        with self._lock:
            self._aliases[(kind, name)] = key

    def delete(self, kind, key):
        """Remove an entry (by key or alias); return whether there was one."""
        with self._lock:
            key = self._aliases.get((kind, key), key)
            entry = self._entries.pop((kind, key), None)
            if entry is None:
                return False
            self._bytes -= entry[1]
            del self._used[(kind, key)]
            return True

    def listing(self, kind):
        """``(id, nbytes, last used as seconds since the epoch)`` of every ``kind`` entry, by id.

        Reading the list does not count as using the entries.
        """
        with self._lock:
            return sorted((key, entry[1], self._used[(k, key)])
                          for (k, key), entry in self._entries.items() if k == kind)
