"""Shared numeric conventions.

All geometric thresholds are relative to the head's bounding-box diagonal
(``Tolerance.scaled``) so that decimetre, centimetre and millimetre heads
behave alike. numba options live here so that every kernel compiles the same
way: on-disk caching, no fastmath (same inputs give the same bytes).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

FLOAT = np.float64
INT = np.int64

#: options for every ``numba.njit`` in the project (deterministic, cached)
NUMBA_OPTIONS = {"cache": True, "nogil": True, "fastmath": False, "error_model": "numpy"}


@dataclass(frozen=True)
class Tolerance:
    """Relative tolerances; multiply by a length scale (the head diagonal)."""

    #: a point closer than this to a surface lies on it
    on_surface: float = 1e-6
    #: lengths, areas and volumes below this are degenerate
    degenerate: float = 1e-12

    def scaled(self, diagonal: float) -> "Tolerance":
        return Tolerance(self.on_surface * diagonal, self.degenerate * diagonal)


TOL = Tolerance()
