"""Outputs may not land inside the workdir's own files.

A ``--preview`` or ``-o`` path inside a stage folder (``<workdir>/fit/fit.png``) overwrote a
stage's file, which the cache then took for the stage's own output; a file added there is
deleted when the stage reruns (its folder is replaced whole). The remembered inputs, the lock
and the temp folders of running stages are the workdir's too. Such a path is bad input (exit 2),
refused before any work.
"""

from __future__ import annotations

from pathlib import Path

from faceforge.exceptions import StageError


def _resolved(path: str | Path) -> Path:
    """``path`` made absolute with its existing folders' links resolved (the file need not exist)."""
    p = Path(path).absolute()
    return p.parent.resolve() / p.name


def check_outside_workdir(workspace, path: str | Path | None, option: str) -> None:
    """Raise :class:`StageError` (exit 2) when ``path`` (given to ``option``) is or lies inside a
    stage folder of ``workspace`` (any registered stage's name), a running stage's temp folder,
    or is one of its remembered files or its lock. ``None`` passes."""
    from faceforge.pipeline.runner import CONFIG_FILE, PARAMS_FILE
    from faceforge.pipeline.stage import STAGES, discover

    if not path:
        return
    root = workspace.root.resolve()
    out = _resolved(path)
    try:
        rel = out.relative_to(root)
    except ValueError:
        return
    if not rel.parts:
        raise StageError(f"{option}: is the workdir itself; choose a path outside {root}", path)
    top = rel.parts[0]
    discover()
    if top in STAGES or (root / top / "stage.json").exists() or top.startswith((".tmp-", ".trash-")):
        raise StageError(f"{option}: is inside the workdir's stage folder {top}/, which faceforge replaces "
                         f"when the stage reruns; choose a path outside {root / top}", path)
    if len(rel.parts) == 1 and top in (PARAMS_FILE, CONFIG_FILE, ".faceforge.lock"):
        raise StageError(f"{option}: is the workdir's own {top}; choose another output path", path)
