"""The lids' fold limit (``animate.eyelid_fold_deg``, :class:`faceforge.animation.eyelids.Eyelids`):
which of the skin's quads it holds, and the inverse masses that pin the lid margins while it and the
lids' orientation guard bend the skin around them, so that a blink closes as its FAPs say.
"""

from __future__ import annotations

import numpy as np



def lid_margins(eye, rest: np.ndarray, faces: np.ndarray, depth: float = 0.5) -> np.ndarray:
    """``(p,)`` sorted vertex ids of ``rest (n, 3)`` (triangles ``faces (m, 3)``) that lie on the
    two lid margins of ``eye`` (:class:`faceforge.animation.eyelids.Eye`): for each margin curve
    (heights ``top * s(u)``, ``bottom * s(u)``, module docstring of
    :mod:`faceforge.animation.eyelids`), every mesh edge the curve crosses (its two ends on either
    side of it, in height along v, within the corners) gives its end nearer the curve; only skin in
    front of the depth fade (``depth`` rest openings behind the margins,
    :func:`faceforge.animation.eyelids.lid_field`): the socket's lining behind a closed eye is not a
    margin. These are the vertices whose closing the FAPs set: a full blink brings the two rows
    together, :data:`faceforge.animation.eyelids.MIN_OPENING` apart."""
    rest = np.asarray(rest, dtype=np.float64).reshape(-1, 3)
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    x = (rest - eye.centre) @ eye.axes.T
    s = eye.taper(x[:, 0])
    front = eye.lid_depth * s - x[:, 2] <= depth * eye.gap
    edges = np.unique(np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1), axis=0)
    a, b = edges[:, 0], edges[:, 1]
    ok = front[a] & front[b] & ((s[a] > 0.0) | (s[b] > 0.0))
    out = []
    for height in eye.margins:
        h = x[:, 1] - height * s
        cross = ok & ((h[a] >= 0.0) != (h[b] >= 0.0))
        out.append(np.where(np.abs(h[a]) <= np.abs(h[b]), a, b)[cross])
    return np.unique(np.concatenate(out))


def margin_inv_mass(field, rest: np.ndarray, faces: np.ndarray, depth: float = 0.5) -> np.ndarray:
    """``(n,)`` inverse masses in [0, 1] for :class:`faceforge.animation.eyelids.Eyelids`' fold limit
    and guard: 0 on the lid margins (:func:`lid_margins`, those in ``field``, a
    :class:`faceforge.animation.eyelids.LidField`) where the taper ``s(u)`` is at least
    :data:`MARGIN_FREE_TAPER`, rising linearly to 1 at the corners (``s`` 0); 1 everywhere else.
    Where the lids meet, the margins stay where the FAPs put them and the skin bends around them;
    in the canthi the two margins close onto each other with no opening left to keep, and two
    pinned margin vertices facing each other across a sliver of lining would leave the limit
    nothing to turn (MakeHuman's outer canthus: one folded edge per blink)."""
    w = np.ones(len(rest))
    margin = lid_margins(field.eye, rest, faces, depth)
    margin = margin[np.isin(margin, field.index)]
    s = field.eye.taper((rest[margin] - field.eye.centre) @ field.eye.axes[0])
    w[margin] = np.clip(1.0 - s / MARGIN_FREE_TAPER, 0.0, 1.0)
    return w


#: below this taper ``s(u)`` (near the corners) the lid margins ease out of their pin
#: (:func:`margin_inv_mass`): with TAPER 3, the outer eighth of the way to each corner. Pinned all
#: along, MakeHuman's blinks kept 1 / 1 folded edges and ICT's 4 / 0; eased below 1/3, 0 / 0 and
#: 3 / 0, the margins moving at most 0.014 of the opening, and only there (eased below 1: 0 / 0
#: and 1 / 1, but the margins moved up to 0.06 of the opening where the lids meet)
MARGIN_FREE_TAPER = 1.0 / 3.0


#: rounds of (one sweep of the dihedral limit, orientation guard) over a frame the lids moved
#: (``animate.eyelid_fold_deg``): each undoes a little of the other and the pair does not settle (every
#: round projects something), so the count matters. With the margins pinned, 8 rounds of 4 sweeps left
#: ICT's blinks 3 / 0 folded edges (and 19 of 29 on the raw ICT mesh's two blinks: the limit's whole-excess
#: turns inverted triangles, the guard's repairs folded others); single sweeps, 16 rounds 1 / 2, 24 rounds
#: 0 / 0 (raw mesh 3), 32 0 / 0 (4), 48 0 / 0 (7); MakeHuman and MediaPipe 0 / 0 from 16 on. 5-9 ms per
#: frame on MakeHuman and ICT
FOLD_ROUNDS = 24

#: the lids' fold limit holds the quads bent less than this at rest (deg): taking in the quads
#: bent 60-80 deg at rest (the socket's rim) folded MakeHuman's blink more (4 -> 13 edges), not less
FOLD_FLAT_DEG = 60.0


def fold_quads(rest, faces, moving, fold_deg: float):
    """(quads (q, 4), limits (q,) radians) of :class:`faceforge.animation.eyelids.Eyelids`' fold
    limit: the skin's bending quads whose four vertices the lids move (``moving (n,)`` bool) and
    that are bent less than ``fold_deg`` and :data:`FOLD_FLAT_DEG` at rest; None when ``fold_deg``
    is 0 or there are none."""
    if not fold_deg or float(fold_deg) <= 0:
        return None
    from faceforge.pbd.constraints.bending import dihedral_angle
    from faceforge.skin.layer import skin_topology

    quads = np.asarray(skin_topology(faces).bending_quads, dtype=np.int64).reshape(-1, 4)
    limit = np.radians(float(fold_deg))
    quads = quads[moving[quads].all(axis=1)]
    quads = quads[np.abs(dihedral_angle(rest, quads)) < min(limit, np.radians(FOLD_FLAT_DEG))]
    return (np.ascontiguousarray(quads), np.full(len(quads), limit)) if len(quads) else None


def referred_limits(frame: np.ndarray, quads: np.ndarray, limit: np.ndarray) -> np.ndarray:
    """``(q,)`` radians: each quad's ``limit`` (``(q,)`` radians), or its unsigned dihedral in ``frame (n, 3)``
    where that is larger (below pi) — the lids' fold limit held to the frame the lids were laid over
    (``animate.eyelid_relative``): a quad the simulation left bent past the limit may stay as bent, and
    the lids straighten only what they bend themselves."""
    from faceforge.pbd.constraints.bending import dihedral_angle

    bent = np.abs(dihedral_angle(np.asarray(frame, dtype=np.float64), np.asarray(quads, dtype=np.int64)))
    return np.minimum(np.maximum(np.asarray(limit, dtype=np.float64), bent), np.pi - 1e-9)


def referred_floors(frame: np.ndarray, faces: np.ndarray, normal0: np.ndarray, floor: np.ndarray) -> np.ndarray:
    """``(m,)``: each triangle's ``floor`` (least signed area along its unit rest normal ``normal0 (m, 3)``,
    skin units squared), or its signed area in ``frame (n, 3)`` where that is lower but positive, or -inf
    (left alone) where the triangle is turned over in ``frame`` — the lids' guard held to the frame the lids
    were laid over (``animate.eyelid_relative``), as :func:`referred_limits`."""
    p = np.asarray(frame, dtype=np.float64)[np.asarray(faces, dtype=np.int64)]
    area = 0.5 * np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), normal0)
    floor = np.asarray(floor, dtype=np.float64)
    return np.where(area >= floor, floor, np.where(area > 0.0, area, -np.inf))
