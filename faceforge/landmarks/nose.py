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
"""

from __future__ import annotations

import numpy as np

#: half-height of the slab through the detected point, fraction of the diagonal
SLAB = 0.005
#: the wing's edge faces outwards at least this much (normal . left for 9.1, . -left for 9.2)
FACING = 0.85
#: the median edge near the point must be shorter than this fraction of the alae's distance
RESOLUTION = 1.0 / 6.0


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
