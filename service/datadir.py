"""The durable store: uploaded meshes and built scenes as files in ``RAYCORE_DATA_DIR``.

Each entry is one file named by its content id (``meshes/<id>.rcf``, ``scenes/<id>.rcf``), in
raycore's scene file format (:mod:`raycore.arrayfile`; a scene's through
:mod:`raycore.scene_file`, so that reading it skips the build).  A file is written to a
temporary name, flushed to disk and renamed, before the request that made it is answered: after
a crash (``kill -9`` included) a file is there whole or not at all, and every worker and replica
that shares the directory finds it.  A file's modification time is its last use; when the files
pass the byte budget, the least recently used go.  A file that cannot be read back (truncated,
corrupt, from a newer raycore) is logged, removed and treated as absent: its client is answered
404 and sends it again, as after an eviction.
"""

import logging
import os
import re
import threading
import time
from pathlib import Path

import numpy as np

from raycore import arrayfile, scene_file
from service.builder import MeshEntry, SceneEntry
from service.errors import LimitExceeded
from service.schemas import MeshInfo, SceneInfo

logger = logging.getLogger("raycore.service")

#: Content ids (:func:`service.store.content_id`); any other key is never a file name.
_ID = re.compile(r"[0-9a-f]{32}")
_SUFFIX = ".rcf"
_FOLDERS = {"mesh": "meshes", "scene": "scenes"}
#: A temporary file older than this is left over from a writer that died (kill -9).
_STALE_SECONDS = 3600


class DataDir:
    """Meshes and scenes as files under ``root``, at most ``budget`` bytes of them.

    Several processes may share one directory: every change is a rename or an unlink, which
    the file system makes atomic, and a reader that loses a race sees a file as absent.
    """

    def __init__(self, root, budget):
        self.root = Path(root)
        self.budget = budget
        self._lock = threading.Lock()  # one eviction at a time in this process
        for folder in _FOLDERS.values():
            (self.root / folder).mkdir(parents=True, exist_ok=True)
        self._sweep_temporaries()

    def _path(self, kind, key):
        """The file of ``key``, or None when ``key`` is not a content id (e.g. ``demo``, or
        something a client made up: never a path outside the directory)."""
        if not isinstance(key, str) or not _ID.fullmatch(key):
            return None
        return self.root / _FOLDERS[kind] / f"{key}{_SUFFIX}"

    def save(self, kind, key, entry):
        """Write ``entry`` under ``key`` unless a file is there; return whether it was written.

        Raises
        ------
        LimitExceeded
            When the file alone is larger than the budget (it is not kept).
        """
        path = self._path(kind, key)
        if _touch(path):
            return False
        path.parent.mkdir(parents=True, exist_ok=True)  # the directory may have been emptied
        if kind == "mesh":
            arrayfile.write(path, {"info": entry.info.model_dump(mode="json")},
                            {"vertices": entry.vertices, "faces": entry.faces})
        else:
            scene_file.save(entry.scene, path, ({"info": entry.info.model_dump(mode="json")},
                                                {"colors": entry.colors}))
        size = path.stat().st_size
        if size > self.budget:
            path.unlink(missing_ok=True)
            raise LimitExceeded(f"the {kind} takes {size} bytes on disk; the data directory "
                                f"keeps at most {self.budget} (RAYCORE_DATA_BYTES)")
        self._evict(keep=path)
        return True

    def load(self, kind, key):
        """``(entry, nbytes)`` stored under ``key``, marked as just used; None when there is
        none, or when its file is unreadable (then it is logged and removed)."""
        path = self._path(kind, key)
        if path is None:
            return None
        try:
            if kind == "mesh":
                meta, arrays = arrayfile.read(path)
                entry = MeshEntry(arrayfile.checked(arrays, "vertices", np.float64, (None, 3)),
                                  arrayfile.checked(arrays, "faces", np.int64, (None, 3)),
                                  MeshInfo.model_validate(meta["info"]))
                loaded = entry, entry.nbytes
            else:
                scene, meta, arrays = scene_file.load_with_extra(path)
                info = SceneInfo.model_validate(meta["info"])
                entry = SceneEntry(
                    scene, arrayfile.checked(arrays, "colors", np.float64, (len(scene), 3)), info)
                loaded = entry, info.bytes
        except FileNotFoundError:
            return None
        except (ValueError, KeyError, TypeError) as error:  # pydantic's errors are ValueErrors
            logger.warning("removing unreadable %s file %s: %s", kind, path, error)
            path.unlink(missing_ok=True)
            return None
        except OSError as error:  # the disk, not the file (permissions, I/O): leave it there
            logger.warning("cannot read %s file %s: %s", kind, path, error)
            return None
        _touch(path)
        return loaded

    def touch(self, kind, key):
        """Mark the file of ``key`` as just used (a hit in a worker's memory is a use)."""
        _touch(self._path(kind, key))

    def delete(self, kind, key):
        """Remove the file of ``key``; return whether there was one."""
        path = self._path(kind, key)
        if path is None:
            return False
        try:
            path.unlink()
        except FileNotFoundError:
            return False
        return True

    def listing(self, kind):
        """``{id: (bytes, last used as seconds since the epoch)}`` of the ``kind`` files."""
        return {path.name[:-len(_SUFFIX)]: (size, used)
                for path, size, used in self._files((kind,))}

    def _files(self, kinds=tuple(_FOLDERS)):
        """``(path, bytes, modification time)`` of every stored file of ``kinds`` (not
        temporaries)."""
        found = []
        for folder in (_FOLDERS[kind] for kind in kinds):
            try:
                entries = list(os.scandir(self.root / folder))
            except FileNotFoundError:  # the directory was emptied: nothing stored
                continue
            for entry in entries:
                if entry.name.endswith(_SUFFIX) and _ID.fullmatch(entry.name[:-len(_SUFFIX)]):
                    try:
                        stat = entry.stat()
                    except FileNotFoundError:  # removed by another worker meanwhile
                        continue
                    found.append((Path(entry.path), stat.st_size, stat.st_mtime))
        return found

    def _evict(self, keep):
        """Remove the least recently used files (never ``keep``) until the rest fit."""
        with self._lock:
            files = sorted(self._files(), key=lambda file: file[2])
            total = sum(size for _, size, _ in files)
            for path, size, _ in files:
                if total <= self.budget:
                    break
                if path != keep:
                    path.unlink(missing_ok=True)
                    total -= size

    def _sweep_temporaries(self):
        """Remove temporary files that a writer killed mid-write left behind."""
        now = time.time()
        for folder in _FOLDERS.values():
            for path in (self.root / folder).glob(arrayfile.TEMPORARY_PATTERN):
                try:
                    if now - path.stat().st_mtime > _STALE_SECONDS:
                        path.unlink()
                except FileNotFoundError:
                    continue


def _touch(path):
    """Set ``path``'s modification time to now; return whether it exists."""
    if path is None:
        return False
    try:
        os.utime(path)
    except FileNotFoundError:
        return False
    return True
