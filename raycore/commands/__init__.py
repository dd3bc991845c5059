"""The subcommands of ``raycore`` that work on files: ``render``, ``cast`` and ``bench``.

Each module adds its parser (``add_parser``) and runs it; :mod:`raycore.cli` gathers them and
turns :class:`CommandError` (and the library's and the service's refusals) into one line on
stderr.  They sit on the library and on the service's scene parsing, queries and encoders
(``service.builder``, ``service.answers``, ``service.codecs``), which they share with the
HTTP API rather than repeat, so they need the ``service`` extra.
"""


class CommandError(Exception):
    """Input that a command refuses; its message is the whole of what the user sees."""


def user_error(error):
    """The message of an error that the user's input caused, or None for a bug.

    Those are :class:`CommandError`, the library's ``ValueError`` (it names the argument), the
    service's ``ClientError`` and the system's ``OSError`` (a file that cannot be read, a full
    disk).
    """
    if isinstance(error, CommandError | ValueError):
        return str(error)
    if isinstance(error, OSError):
        where = f"{error.filename}: " if error.filename else ""
        return f"{where}{error.strerror or error}"
    if isinstance(error, MemoryError):
        return "not enough memory for this input"
    if type(error).__module__ == "service.errors":
        return str(error)
    return None


def needs_service_extra(command):
    """Import what ``command`` needs from the ``service`` extra, or raise CommandError."""
    try:
        import pydantic  # noqa: F401
        import trimesh  # noqa: F401
    except ImportError as error:
        raise CommandError(f"raycore {command} needs the service extra ({error.name} is "
                           "missing): pip install 'raycore[service]'") from error


def positive_int(text):
    """argparse type: an integer of at least 1."""
    import argparse

    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {text!r}")
    return value


def write_file(path, data):
    """Write bytes to ``path``; CommandError, naming it, when that fails."""
    try:
        path.write_bytes(data)
    except OSError as error:
        raise CommandError(f"{path}: cannot write it: {error.strerror or error}") from error
