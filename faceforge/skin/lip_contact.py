"""The lips' contact at the commissure: the skin quads across the lip line at the inner lip
corners may bend, not turn over (``skin.commissure_fold_deg``).

At the inner lip corners (FDPs 2.4 / 2.5) the upper and the lower lip meet in sub-millimetre
triangles spanning the lip line. Both lips ride the orbicularis oris, each anchor on its own
lip's point of the ring, and in a smile or a sideways mouth the lower lip's corner vertex ends a
fraction of a mm forward of the upper lip's ones: the triangle joining them turns over (a fold
of 92-114 deg on the MakeHuman sample, docs/notes/mouthfold10.md). Real lips are in contact
there and cannot pass through each other. :func:`commissure_quads` picks the quads that hold a
vertex of each lip with one within ``radius`` x MW0 of a lip corner (inner or outer); the skin layer keeps
their dihedral within ``skin.commissure_fold_deg`` after every step
(:func:`faceforge.pbd.dihedral_limit.limit_dihedrals`).
"""

from __future__ import annotations

import numpy as np

from faceforge.skin.rules import COMMISSURE_RADIUS, _near_fdps

__all__ = ["commissure_quads", "LIP_CORNER_FDPS"]

#: the corners where the lips meet: inner (2.4 / 2.5) and outer (8.3 / 8.4). On the MakeHuman
#: sample they are 0.08 MW0 apart and the lip line between them folded too
LIP_CORNER_FDPS = ("2.4", "2.5", "8.3", "8.4")


def commissure_quads(vertices, faces, lip_sides, landmarks: dict,
                     radius: float = COMMISSURE_RADIUS) -> np.ndarray:
    """(m, 4) int64 bending quads of the skin (:func:`faceforge.skin.layer.skin_topology`) that
    span the lip line at an inner lip corner: a vertex of the upper lip (``lip_sides`` +1) and one
    of the lower (-1) among its four, one of them within ``radius`` x MW0 of a lip corner
    (:data:`LIP_CORNER_FDPS`, those given). vertices (n, 3), faces (f, 3), lip_sides (n,)
    int (None: no lips, no quads)."""
    from faceforge.skin.layer import skin_topology

    if lip_sides is None:
        return np.zeros((0, 4), np.int64)
    sides = np.asarray(lip_sides).reshape(-1)
    near = _near_fdps(vertices, landmarks, radius, LIP_CORNER_FDPS)
    quads = np.asarray(skin_topology(faces).bending_quads, np.int64).reshape(-1, 4)
    s = sides[quads]
    keep = (s > 0).any(axis=1) & (s < 0).any(axis=1) & near[quads].any(axis=1)
    return quads[keep]
