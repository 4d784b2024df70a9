"""Fail before the work on an output path that cannot be written.

A simulation of minutes that ends in ``FileNotFoundError`` because ``--preview`` named a
missing folder wastes the minutes and prints a traceback (issue 28); commands check their
output paths first with :func:`check_writable`.
"""

from __future__ import annotations

import os
from pathlib import Path

from faceforge.exceptions import StageError


def check_writable(path: str | Path, what: str = "output") -> None:
    """Raise :class:`StageError` naming ``path`` unless a file could be written there: its
    folder exists and is writable, and ``path`` is not an existing folder (for a file
    output) -- ``what`` names the option in the message (e.g. ``"--preview"``)."""
    p = Path(path)
    if p.is_dir():
        raise StageError(f"{what}: is a folder, expected a file path", p)
    check_folder(p, what)
    if p.exists() and not os.access(p, os.W_OK):
        raise StageError(f"{what}: file is not writable", p)


def check_folder(path: str | Path, what: str = "output", error: type[Exception] = StageError) -> None:
    """Raise ``error`` naming ``path`` unless the folder ``path`` goes into exists and is
    writable (``path`` itself may be a file or a folder to create, e.g. an OBJ sequence's)."""
    p = Path(path)
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.is_dir():
        raise error(f"{what}: folder {parent} does not exist", p)
    if not os.access(parent, os.W_OK | os.X_OK):
        raise error(f"{what}: folder {parent} is not writable", p)
