"""The ala's insertion (``bind.ala_mm``, ``bind.ala_muscles``, beyond §8): the skin of the nose's
wing binds to the levator labii superioris alaeque nasi, not to the lips' sphincter.

The levator labii superioris alaeque nasi (``levator_labii_inner`` of the muscle map) runs from
the frontal process of the maxilla down the side of the nose; its medial slip inserts into the
ala's skin and cartilage, its lateral slip into the upper lip. By its ray (§8) the ala's skin
looks inward across the nasal cavity and, on the MakeHuman sample, 50 of the 94 vertices that
MakeHuman's nose-left-elevation unit moves most (> 0.3 of its peak) bound to the orbicularis
oris, 19 to the bone and 10 to the muscle: the muscle lifted the upper lip's middle and the
nostril sill, the unit lifts the ala and the skin beside it (cosine 0.46).

:func:`ala_mask` is the skin within ``bind.ala_mm`` of the alae's FDPs (9.1, 9.2), outside the
eyes' skin; :func:`faceforge.skin.cheek.cheek_binding` (``also_from``: the sphincters) rebinds
those of its vertices whose only anchor is on the bone or on the sphincter to the closest point
of the ala muscles.
"""

from __future__ import annotations

import numpy as np

from faceforge.constants import FLOAT

#: ``bind.ala_mm`` when not given: 0, the paper's rays
ALA_MM = 0.0

#: the alae's FDPs (left nostril border, right)
ALA_FDPS = ("9.1", "9.2")


def ala_mask(vertices, landmarks: dict, reach_mm: float = ALA_MM, up=(0.0, 1.0, 0.0)) -> np.ndarray:
    """(n,) bool: skin vertices (n, 3) within ``reach_mm`` (scaled by ES0,
    :func:`faceforge.anatomy.tissue.units_per_mm`) of FDP 9.1 or 9.2, outside the eyes' skin
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
    for k in ALA_FDPS:
        if k in landmarks:
            mask |= np.linalg.norm(v - np.asarray(landmarks[k], FLOAT), axis=1) <= r
    return mask & ~eye_mask(v, landmarks, up=up)
