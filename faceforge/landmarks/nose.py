"""The alare 9.1/9.2: the most lateral point of the nose's wing seen from the front.

Why a rule. The hand files define 9.1 as "the most lateral point of the ala that is visible
from the front (its lateral edge, not the bottom of the alar groove)". There the skin faces
sideways: the hand points' vertex normals point 0.97-0.98 along the face's left axis
(MakeHuman, its identity, ICT). The detector's point lies just beside the wing, on the cheek
in the alar-facial groove. Its normal faces mostly forward (0.61-0.88), and it sits 0.6-1.1 %
of the diagonal behind the hand point.

The rule looks at the vertices in a thin horizontal slab through the detected point
(:data:`SLAB`). It keeps those between the midline and the detected point, in front of it, whose
normal faces outwards (toward the point's side) at least :data:`FACING`. The most lateral of
them is the wing's edge. A mesh too coarse to draw the wing is left to the detector: the median
edge near the point must be under :data:`RESOLUTION` of the detected alae's distance. The
478-vertex MediaPipe mask fails this at 0.24; MakeHuman passes at 0.11, ICT at 0.06.

The nose's lower edge points 9.4/9.5 (:func:`nose_base`) keep the detector's point less the
detector's bias there on its own canonical face (:data:`NOSE_BASE_BIAS`).
"""

from __future__ import annotations

import numpy as np

#: half-height of the slab through the detected point, fraction of the diagonal
SLAB = 0.005
#: the wing's edge faces outwards at least this much (normal . left for 9.1, . -left for 9.2)
FACING = 0.85
#: the median edge near the point must be shorter than this fraction of the alae's distance
RESOLUTION = 1.0 / 6.0
#: the detector's bias at the nose's lower edge 9.4/9.5 (MediaPipe 327/98), (outward from the
#: midline, up) in eye spans (|3.7 - 3.12| across): on a grey render of MediaPipe's own canonical
#: face (the MediaPipe sample head) the consensus put them this far from the model's vertices, the
#: mean of the left and right point (outward 0.018 / 0.021, up 0.006 / 0.010; ``tools/detector_bias.py``).
#: The whole heads' detected points sat 0.023-0.033 outward and 0.007-0.022 up of their hand points
#: (MakeHuman, its young female identity, ICT)
NOSE_BASE_BIAS = {"9.4": (0.0195, 0.008), "9.5": (0.0195, 0.008)}


def alae(vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray, pos: dict, frame,
         diagonal: float) -> dict:
    """{"9.1" / "9.2": vertex id}: the alae on the wings' lateral edges (module docstring).

    ``vertices (n, 3)``, ``faces (m, 3)``, ``normals (n, 3)`` unit vertex normals, ``pos`` {fdp: (3,)}
    holding the detected 9.1 and 9.2, ``frame`` (left, up, forward) unit (3,); {} where the mesh is
    too coarse, and a side is left out where no vertex qualifies.
    """
    left, up, fwd = (np.asarray(a, dtype=np.float64) for a in frame)
    if not all(k in pos for k in ("9.1", "9.2")):
        return {}
    v = np.asarray(vertices, dtype=np.float64)
    width = float(np.linalg.norm(pos["9.1"] - pos["9.2"]))
    f = np.asarray(faces, dtype=np.int64)
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    near = np.linalg.norm(v[e[:, 0]] - pos["9.1"], axis=1) < 0.02 * diagonal
    if not near.any() or np.median(np.linalg.norm(v[e[near, 0]] - v[e[near, 1]], axis=1)) >= RESOLUTION * width:
        return {}
    mid = (pos["9.1"] + pos["9.2"]) / 2
    out = {}
    for k, side in (("9.1", 1.0), ("9.2", -1.0)):
        p = pos[k]
        lateral = (v - mid) @ left * side
        sel = ((np.abs((v - p) @ up) < SLAB * diagonal) & (lateral > 0)
               & (lateral <= (p - mid) @ left * side + 0.002 * diagonal)
               & ((v - p) @ fwd > 0) & (normals @ left * side >= FACING))
        if sel.any():
            idx = np.flatnonzero(sel)
            out[k] = int(idx[np.argmax(lateral[idx])])
    return out


def nose_base(caster, pos: dict, frame, diagonal: float) -> dict:
    """{"9.4" / "9.5": (3,)}: the detector's points less :data:`NOSE_BASE_BIAS` (eye spans from the
    outer eye corners 3.7/3.12 in ``pos``), put on the skin from in front by
    :func:`faceforge.landmarks.rules._onto_skin` (``caster``: a RayCaster or the frontal render);
    a point whose ray misses the mesh is left out, and {} without the eye corners."""
    from faceforge.landmarks.rules import _onto_skin

    left, up, fwd = (np.asarray(a, dtype=np.float64) for a in frame)
    if not all(k in pos for k in ("3.7", "3.12")):
        return {}
    span = float(abs((pos["3.7"] - pos["3.12"]) @ left))
    mid = (pos["3.7"] + pos["3.12"]) / 2
    ids = [k for k in NOSE_BASE_BIAS if k in pos]
    if not ids or span <= 0:
        return {}
    targets = np.array([pos[k] - np.sign((pos[k] - mid) @ left) * NOSE_BASE_BIAS[k][0] * span * left
                        - NOSE_BASE_BIAS[k][1] * span * up for k in ids])
    hits = _onto_skin(caster, targets, fwd, diagonal)
    return {k: p for k, p in zip(ids, hits) if np.isfinite(p).all()}
