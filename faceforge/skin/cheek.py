"""The cheek's insertion (``bind.cheek_mm``, beyond §8): the skin over the cheek bone binds to
the cheek raiser, not to the bone.

The lower orbital orbicularis oculi (the cheek raiser, FACS AU6: ``orbicularis_oculi_lower``
of the muscle map) inserts into the dermis of the cheek below the eye. By its ray (§8) the
cheek skin between the lower lid and the cheek bone's FDP (5.3 / 5.4) looks past the thin
sheet, across the orbit's rim, and binds to the cranium: on the MakeHuman sample 117 of the 167
vertices within 0.3 ES0 of FDP 5.3 were tied to the bone, and the cheek raiser at c = 1 lifted
FDP 5.3 86 ENS while its own surface under it moved about twice that. The skin within
:data:`CHEEK_MM` of FDP 5.3 / 5.4 that its rays bound to the bone binds instead to the closest
point of the cheek muscles (``bind.cheek_muscles``) within the longest ray. The eyes' skin
(:func:`faceforge.skin.brow.eye_mask`: lids and margins) stays where its rays bound it: the lid
field moves it (:mod:`faceforge.animation.eyelids`).
"""

from __future__ import annotations

import numpy as np

from faceforge.constants import FLOAT, INT

#: ``bind.cheek_mm``: the skin within this many mm (an average adult's, scaled by ES0) of the
#: cheek bone's FDP is the cheek's (0: none, the paper's rays)
CHEEK_MM = 15.0

#: the cheek bone FDPs (subject's left, right)
CHEEK_FDPS = ("5.3", "5.4")


def cheek_mask(vertices, landmarks: dict, reach_mm: float = CHEEK_MM, up=(0.0, 1.0, 0.0)) -> np.ndarray:
    """(n,) bool: skin vertices within ``reach_mm`` (scaled by ES0,
    :func:`faceforge.anatomy.tissue.units_per_mm`) of FDP 5.3 or 5.4, outside the eyes' skin
    (:func:`faceforge.skin.brow.eye_mask`). No vertex without the FDPs or for ``reach_mm <= 0``."""
    from faceforge.anatomy.tissue import units_per_mm
    from faceforge.skin.brow import eye_mask

    v = np.asarray(vertices, FLOAT)
    mask = np.zeros(len(v), bool)
    if reach_mm <= 0:
        return mask
    try:
        r = float(reach_mm) * units_per_mm(landmarks)
    except KeyError:
        return mask
    for k in CHEEK_FDPS:
        if k in landmarks:
            mask |= np.linalg.norm(v - np.asarray(landmarks[k], FLOAT), axis=1) <= r
    return mask & ~eye_mask(v, landmarks, up=up)


def cheek_binding(binding, vertices, bodies, muscles, mask, max_distance: float):
    """``binding`` (:class:`faceforge.skin.binding.Binding`) with the vertices of ``mask``
    (n,) bool whose only anchor is on the bone rebound to the closest point of the bodies
    ``muscles`` (indices into ``bodies``) within ``max_distance`` (skin units); a vertex with
    none in reach keeps its anchor. Returns ``(binding, count rebound)``."""
    from dataclasses import replace

    from faceforge.geometry.triangles import barycentric
    from faceforge.skin.brow import _rebind
    from faceforge.skin.casting import MUSCLE

    todo, row = binding.sole_bone_anchors(mask)
    n = len(binding.status)
    if not len(todo) or not len(muscles):
        return binding, 0
    body = np.full(n, -1, INT)
    face = np.full(n, -1, INT)
    pts = np.zeros((n, 3), FLOAT)
    dist = np.full(n, np.inf, FLOAT)
    done = _rebind(np.asarray(vertices, FLOAT), bodies, todo, list(muscles), max_distance, body, face, pts,
                   dist, None)
    moved = np.flatnonzero(done)
    if not len(moved):
        return binding, 0
    r = row[moved]
    a_body, a_face = binding.body.copy(), binding.face_ids.copy()
    a_pts, a_dist, a_bary = binding.points.copy(), binding.distance.copy(), binding.bary.copy()
    a_out, a_closest, status = binding.outward.copy(), binding.closest.copy(), binding.status.copy()
    a_body[r], a_face[r], a_pts[r], a_dist[r] = body[moved], face[moved], pts[moved], dist[moved]
    a_out[r] = a_closest[r] = False
    status[moved] = MUSCLE
    for b in np.unique(body[moved]):
        sel = body[moved] == b
        a_bary[r[sel]] = barycentric(pts[moved][sel], bodies[b].vertices, bodies[b].faces, face[moved][sel])
    return replace(binding, body=a_body, face_ids=a_face, points=a_pts, distance=a_dist, bary=a_bary,
                   outward=a_out, closest=a_closest, status=status), len(moved)


def cheek_tether(binding, muscles, stiffness: float):
    """(k,) float per anchor of ``binding``: ``stiffness`` on the anchors on the cheek
    muscles ``muscles`` (``bind.cheek_muscles``: names, or left/right pairs' names without
    ``_L`` / ``_R``), 0 elsewhere; None when ``stiffness`` is 0 or no anchor is on them
    (``skin.cheek_tether``, :func:`faceforge.skin.layer.add_skin`).

    The cheek raiser's fibres end in the dermis of the cheek. Tied like any anchor, by a §8
    stretch of ``skin.stiffness.anchor`` (0.2) that the skin vertex shares with its anchor
    particle, the cheek skin, squeezed between the rising muscle and the lower lid, followed its
    muscle a third of the way or less: at c = 1 the raiser's surface under FDP 5.3 rose 322 ENS
    on the MakeHuman sample, the skin 94; 290 and 46 on MediaPipe's mask; the Xface files ask 150.
    """
    from faceforge.skin.rules import match_insertions

    if not stiffness or float(stiffness) <= 0:
        return None
    ids, _ = match_insertions(tuple(muscles or ()), [str(n) for n in binding.body_names])
    on = np.isin(np.asarray(binding.body), ids)
    return np.where(on, float(stiffness), 0.0) if on.any() else None

