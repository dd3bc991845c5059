"""Service settings: request limits and the scene store's budget.

Read from the environment once, by :func:`load_settings`, when the app is created; tests build
:class:`Settings` directly.
"""

import dataclasses
import os
from dataclasses import dataclass, fields

MIB = 2**20


@dataclass(frozen=True)
class Settings:
    """Limits of what one request may ask for, and of the memory the service keeps.

    Attributes
    ----------
    max_rays : int
        Rays per intersect request.
    max_body_bytes : int
        Bytes of a request body (the default fits 2M rays as float64 (N, 8) .npy).
    max_triangles : int
        Triangles stored per scene and per uploaded mesh (instances share their mesh's).
    max_planes : int
        Planes per scene.  A plane is unbounded, outside every tree, so every ray tests every
        plane: a scene of 100,000 planes took 27 s to render at 256x256, holding the compute
        slot.
    max_render_pixels : int
        width * height of a render.
    max_hits : int
        Crossings that one ``query=all`` answer may list (413 beyond, refused once they are
        counted, before they are listed).
    store_bytes : int
        Memory budget of the scene and mesh store; least recently used entries go first.
    compute_slots : int
        Requests that run geometry work at once, each on all of Numba's threads.  Safe on every
        threading layer raycore runs on (tbb; or workqueue, where raycore lets one parallel
        loop run at a time).
    body_seconds : int
        Seconds a client has, from its request's arrival, to send the whole body (408 after):
        a slow or stalled upload must not hold a connection and its buffers for ever.
    demo : bool
        Build the demo scene (id ``demo``) at startup.
    api_key : str or None
        When set, uploads, scene builds and deletions need it (``X-API-Key`` or
        ``Authorization: Bearer``) and are answered 401 without it.  Not shown by ``repr``.
    data_dir : str or None
        When set, a directory where every uploaded mesh and built scene is written before it is
        acknowledged, and where a worker looks before answering 404 (:mod:`service.datadir`):
        restarts, workers and replicas that share it lose nothing.
    data_bytes : int
        Disk budget of ``data_dir``; least recently used files go first.
    """

    max_rays: int = 2**21
    max_body_bytes: int = 136 * MIB
    max_triangles: int = 4_000_000
    max_planes: int = 256
    max_render_pixels: int = 4096 * 4096
    max_hits: int = 2**22
    store_bytes: int = 2048 * MIB
    compute_slots: int = 1
    body_seconds: int = 60
    demo: bool = True
    api_key: str | None = dataclasses.field(default=None, repr=False)
    data_dir: str | None = None
    data_bytes: int = 16 * 1024 * MIB


def load_settings(environ=None):
    """Settings from ``RAYCORE_<NAME>`` environment variables (e.g. ``RAYCORE_MAX_RAYS``).

    Parameters
    ----------
    environ : mapping, optional
        Defaults to ``os.environ``.

    Raises
    ------
    ValueError
        Naming the variable whose value is not a positive integer (or a boolean for ``DEMO``,
        or a non-empty string for ``API_KEY`` and ``DATA_DIR``).
    """
    environ = os.environ if environ is None else environ
    values = {}
    for field in fields(Settings):
        name = f"RAYCORE_{field.name.upper()}"
        if name not in environ:
            continue
        if field.name == "api_key":
            if not environ[name].strip():
                # refused rather than read as "no key": a blank secret would open the service
                raise ValueError(f"{name} must not be empty (unset it to need no key)")
            values[field.name] = environ[name].strip()
            continue
        if field.name == "data_dir":
            if not environ[name].strip():
                raise ValueError(f"{name} must name a directory (unset it to keep no files)")
            values[field.name] = environ[name]
            continue
        raw = environ[name].strip().lower()
        if field.type is bool:
            if raw not in ("0", "1", "true", "false"):
                raise ValueError(f"{name} must be true or false, got {environ[name]!r}")
            values[field.name] = raw in ("1", "true")
            continue
        if not raw.isdigit() or int(raw) < 1:
            raise ValueError(f"{name} must be a positive integer, got {environ[name]!r}")
        values[field.name] = int(raw)
    return Settings(**values)
