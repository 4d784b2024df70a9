"""Where a template file lives: the one resolver of ``template.skull`` and
``template.muscle_map`` (the fit, the animation rig and ``faceforge template`` use it)."""

from __future__ import annotations

from pathlib import Path


def resolve_template_path(path) -> Path:
    """A template file's or folder's path (``template.skull``, ``template.muscle_map``).

    As given when it exists (relative to the working directory) or is absolute; else under
    the repository root (``templates/...`` of a source checkout), else under the package
    (``faceforge/templates/...`` of an installed copy); else as given, for the loader's error.
    The only template-path resolver: the fit, the animation rig and ``faceforge template``
    all use it.
    """
    p = Path(str(path))
    if p.exists() or p.is_absolute():
        return p
    for root in (Path(__file__).resolve().parents[2], Path(__file__).resolve().parents[1]):
        if (root / p).exists():
            return root / p
    return p
