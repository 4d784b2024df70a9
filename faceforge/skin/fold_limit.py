"""Skin that creases but does not fold over (``skin.fold_deg``, beyond §8).

Skin is a sheet a few mm thick: it wrinkles and creases, but it does not fold flat onto itself.
The §8 layer's bending constraint only pulls each edge back toward its rest dihedral, with the
rest of the solver (the anchors, the stretch) and the guards after it (the skull guard pushing
vertices out along the bone's normals, the bone collision) free to bend an edge past 90 deg: the
jaw's opening folded the upper lids of the ICT sample, the pucker its upper lip, each guard's
push a quad or two where it moved one vertex (docs/notes/foldlimit13.md). The influence map's
blend of rest and simulation (the weighted frame) is not limited: turned there, with no bone to
push it back, skin ended inside the skull.

:func:`fold_limits` picks the skin's bending quads that are flat at rest (bent less than
:data:`FLAT_DEG`) and gives each the limit ``skin.fold_deg``, and the quads across the lip line
at the lip corners (:func:`faceforge.skin.lip_contact.commissure_quads`) the tighter
``skin.commissure_fold_deg``. The skin layer keeps them within it after each solver step and
the guards' alternation after each of its passes (:class:`faceforge.skin.layer.SkinSimulation`,
:mod:`faceforge.animation.guards.alternate`;
the projection itself is :func:`faceforge.pbd.dihedral_limit.limit_dihedrals`, which turns the
two wings about their shared edge and keeps every edge length). Quads already bent at rest
(nostril rims, the lid creases, the lip line) are left to the bending constraint: they crease
by nature.
"""

from __future__ import annotations

import numpy as np

__all__ = ["FLAT_DEG", "fold_limits"]

#: quads bent less than this at rest (degrees) are the skin's flat sheet, the ones the fold limit
#: holds (the lids' limit uses the same, :data:`faceforge.animation.eyelids.FOLD_FLAT_DEG`)
FLAT_DEG = 60.0


def fold_limits(rest, faces, fold_deg: float, commissure=None, commissure_deg: float = 0.0,
                flat_deg: float = FLAT_DEG):
    """``(quads (m, 4) int64, limits (m,) radians)`` the skin may not bend past, or None when
    there are none.

    rest (n, 3) skin positions; faces (f, 3); fold_deg: the limit (degrees, 0: off) of every
    bending quad (:func:`faceforge.skin.layer.skin_topology`) bent less than ``flat_deg`` at rest;
    commissure (c, 4) int quads (optional) held within ``commissure_deg`` (degrees, 0: off), or
    the smaller of the two where both apply. Each quad appears once. A quad's limit is never
    below its rest dihedral (:func:`faceforge.pbd.dihedral_limit.rest_limits`, applied by the
    skin layer).
    """
    from faceforge.pbd.constraints.bending import dihedral_angle
    from faceforge.skin.layer import skin_topology

    quads = np.asarray(skin_topology(faces).bending_quads, np.int64).reshape(-1, 4)
    limits = np.full(len(quads), np.inf)
    if fold_deg and float(fold_deg) > 0:
        flat = np.abs(dihedral_angle(np.asarray(rest, float), quads)) < np.radians(flat_deg)
        limits[flat] = np.radians(float(fold_deg))
    c = np.zeros((0, 4), np.int64) if commissure is None else np.asarray(commissure, np.int64).reshape(-1, 4)
    if len(c) and commissure_deg and float(commissure_deg) > 0:
        row = {tuple(q): i for i, q in enumerate(quads.tolist())}
        at = np.array([row[tuple(q)] for q in c.tolist()], dtype=np.int64)
        limits[at] = np.minimum(limits[at], np.radians(float(commissure_deg)))
    keep = np.isfinite(limits)
    return (np.ascontiguousarray(quads[keep]), limits[keep]) if keep.any() else None
