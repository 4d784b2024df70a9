"""The error hierarchy. Every user-facing failure is a :class:`FaceforgeError`.

The CLI prints ``str(error)`` as one line and exits with status 2; a traceback
is shown only with ``-v``. Messages name the file (and line, where known) and
the cause, e.g. ``my.yaml:12: skin.stiffness.bending: expected a number in
[0, 1], got 'high'``.
"""

from __future__ import annotations

from pathlib import Path


class FaceforgeError(Exception):
    """Base class of every error a user can cause. Exit status 2."""

    exit_code = 2

    def __init__(self, message: str, path: str | Path | None = None, line: int | None = None):
        self.message = message
        self.path = None if path is None else str(path)
        self.line = line
        super().__init__(self.__str__())

    def __str__(self) -> str:
        if self.path is None:
            return self.message
        where = self.path if self.line is None else f"{self.path}:{self.line}"
        return f"{where}: {self.message}"


class ConfigError(FaceforgeError):
    """A configuration file or ``--set`` override is invalid."""


class MeshError(FaceforgeError):
    """A mesh file is missing, unreadable, empty or has invalid geometry."""


class LandmarkError(FaceforgeError):
    """A landmark file is missing, malformed or inconsistent with its mesh."""


class FapError(FaceforgeError):
    """An MPEG-4 FAP file is malformed."""


class StageError(FaceforgeError):
    """A pipeline stage cannot run (missing upstream stage, locked workdir, ...)."""


class TemplateError(FaceforgeError):
    """The skull / muscle-map template is inconsistent."""


class ChecksFailed(FaceforgeError):
    """A stage ran (or was up to date) but its result failed its own checks: exit status 3, so
    scripts tell a broken result from bad input (2). The stage's files stay in the workdir;
    ``--keep-going`` accepts them (:mod:`faceforge.pipeline.result_checks`)."""

    exit_code = 3
    #: the stage's folder was committed (its result is in the workdir); False when the stage
    #: itself refused to commit (a failed fit)
    kept = False
