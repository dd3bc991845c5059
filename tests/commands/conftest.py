"""Shared meshes and helpers of the command line's tests."""

from pathlib import Path

import pytest

from raycore.cli import main

MESH_DIR = Path(__file__).resolve().parents[3] / "shared" / "meshes"


def mesh_file(name):
    """The path of a shared mesh (../shared/meshes beside the repository)."""
    path = MESH_DIR / f"{name}.obj"
    if not path.exists():
        pytest.skip(f"{path} is not there (the shared/ folder beside the repository)")
    return path


def refused(argv, capsys):
    """Run ``raycore argv`` in process, expecting a refusal; return its exit status and stderr."""
    with pytest.raises(SystemExit) as exit_info:
        main([str(arg) for arg in argv])
    code = exit_info.value.code
    # sys.exit(message) prints the message and exits with 1; argparse exits with 2 itself
    err = capsys.readouterr().err + (code if isinstance(code, str) else "")
    return (1 if isinstance(code, str) else code), err
