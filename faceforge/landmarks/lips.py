"""The inner-lip FDPs 2.2, 2.3, 2.6-2.9 of a closed mouth on their own lip's rolled-in edge, and
the inner corners 2.4/2.5 on the slit's end wall (:func:`inner_corners`).

Why a rule. Where the lips meet, the detector's inner-lip points lie a pixel off the seam
and lift onto the lips' front (MakeHuman 2.2 0.75 %, 2.6/2.7 0.78 % of the diagonal in front
of the hand points). Worse, a point lifted near the seam may snap to the *other* lip's
surface: ``bind`` then draws the inner-lip contours through both lips and deletes the
triangles "bridging" them (22 on MakeHuman), and the lip rows of the calibration fail.
A rule that snaps to the seam in the picture (its deepest pixel) was tried: it put 2.2 and
2.3 on one vertex of the upper lip (the calibration went 20 -> 38 %).

The rule walks the mesh, so each lip keeps its own surface. In each column of the mouth
(:data:`COLUMNS`: the inner points' side-to-side position, :data:`BAND` of the mouth's width
either way) it takes the vertices that face forward (normal . forward > 0) between the outer
upper and outer lower lip points, and spreads over the mesh's edges from the vertex nearest
the outer upper point (8.1, 8.5, 8.6: on the upper lip, far from the seam) and from the one
nearest the outer lower point (8.2, 8.7, 8.8), no further than :data:`DEPTH` behind them. Closed lips that are separate surfaces (a slit
into a mouth cavity, MakeHuman; lips touching in front of a mouth hole, ICT) give two parts:
the upper inner point is the vertex of the upper part whose normal turns most downward,
where the lip rolls under into the mouth (MakeHuman's hand points are those vertices), the
lower one the lower part's vertex turned most upward. If the two parts meet (lips joined by
a forward-facing sheet, the MediaPipe mask's bridged mouth), the lips are told apart by height
instead: the upper inner point is the column's lowest vertex above the middle of the detector's
two inner points, the lower one its highest vertex below it (the sheet bridging parted lips has no
vertex of its own, so those are the two lips' inner edges; a detector's point lifted onto the sheet
snapped to the *other* lip's edge, and ``bind`` then cut the mask's upper lip off its lower as a
shared ring: the mask's lower lip did not move in the user's file). A separate lip with no vertex
turned at least :data:`ROLL` gives its edge nearest the other lip (its lowest vertex in the column
for the upper lip, the highest for the lower).
"""

from __future__ import annotations

import numpy as np

#: the mouth's columns: (upper inner FDP, its outer partner, lower inner FDP, its outer partner)
COLUMNS = (("2.2", "8.1", "2.3", "8.2"), ("2.6", "8.5", "2.8", "8.7"), ("2.7", "8.6", "2.9", "8.8"))
#: half-width of the point's column, fraction of the mouth's width (outer corners 8.3-8.4)
BAND = 0.06
#: the chosen vertex's normal must point at least this far down (upper lip) or up (lower lip)
ROLL = 0.5
#: the walk stays within this fraction of the mouth's width behind the column's outer lip points
#: (the hand files' inner points lie 0.02-0.08 behind them; a 2,000-vertex MakeHuman's walk went
#: on into the mouth cavity and put 2.9 10 cm behind the lips, docs/notes/robust19.md)
DEPTH = 0.2


def _neighbours(faces: np.ndarray, n: int):
    """CSR vertex adjacency of the triangle mesh: ``(start (n + 1,), nbr (k,))``."""
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    e = np.concatenate([e, e[:, ::-1]])
    order = np.argsort(e[:, 0], kind="stable")
    e = e[order]
    start = np.searchsorted(e[:, 0], np.arange(n + 1))
    return start, e[:, 1]


def _component(seed: int, ok: np.ndarray, start: np.ndarray, nbr: np.ndarray) -> np.ndarray:
    """Vertex ids reached from ``seed`` over mesh edges through vertices where ``ok``."""
    seen, stack = {seed}, [seed]
    while stack:
        a = stack.pop()
        for b in nbr[start[a]:start[a + 1]].tolist():
            if ok[b] and b not in seen:
                seen.add(b)
                stack.append(b)
    return np.fromiter(seen, dtype=np.int64)


def inner_lips(vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray, pos: dict, frame) -> dict:
    """{inner-lip fdp: vertex id} for the points of :data:`COLUMNS` the rule places (module
    docstring); ``pos`` {fdp: (3,)} the detected points (needs 8.3, 8.4 and the column's four
    points), ``frame`` (left, up, forward) unit (3,), ``normals`` (n, 3) unit vertex normals."""
    left, up, fwd = (np.asarray(a, dtype=np.float64) for a in frame)
    if not all(k in pos for k in ("8.3", "8.4")):
        return {}
    v = np.asarray(vertices, dtype=np.float64)
    width = abs((pos["8.3"] - pos["8.4"]) @ left)
    start, nbr = _neighbours(np.asarray(faces, dtype=np.int64), len(v))
    side, height, depth, rolled = v @ left, v @ up, v @ fwd, normals @ up
    facing = normals @ fwd > 0.0
    out = {}
    for column in COLUMNS:
        if not all(k in pos for k in column):
            continue
        up_in, up_out, lo_in, lo_out = column
        col = 0.5 * (pos[up_in] + pos[lo_in]) @ left
        top, bottom = pos[up_out] @ up, pos[lo_out] @ up
        front = min(pos[up_out] @ fwd, pos[lo_out] @ fwd) - DEPTH * width
        ok = facing & (np.abs(side - col) <= BAND * width) & (height >= bottom) & (height <= top) & (depth >= front)
        cand = np.flatnonzero(ok)
        if len(cand) == 0:
            continue
        # each lip's surface from the vertex nearest its outer point; lips joined in front (a
        # bridged or flat mouth) are one surface: no rolled-in edges to find, the detector's kept
        parts = [_component(int(cand[np.argmin(np.linalg.norm(v[cand] - pos[k], axis=1))]), ok, start, nbr)
                 for k in (up_out, lo_out)]
        if np.intersect1d(parts[0], parts[1]).size:
            out.update(_split_by_height(cand, height, 0.5 * (pos[up_in] + pos[lo_in]) @ up, up_in, lo_in))
            continue
        for inner, ids, sign in ((up_in, parts[0], 1.0), (lo_in, parts[1], -1.0)):
            best = ids[np.argmin(sign * rolled[ids])]
            if sign * rolled[best] <= -ROLL:
                out[inner] = int(best)
            else:                       # a lip that does not roll in: its edge nearest the other
                out[inner] = int(ids[np.argmin(sign * height[ids])])
    return out


def _split_by_height(cand: np.ndarray, height: np.ndarray, middle: float, up_in: str, lo_in: str) -> dict:
    """{upper inner fdp: the lowest of ``cand`` (vertex ids) above ``middle``, lower inner fdp: the
    highest below it} by ``height`` (n,); {} when either side is empty."""
    above, below = cand[height[cand] > middle], cand[height[cand] <= middle]
    if len(above) == 0 or len(below) == 0:
        return {}
    return {up_in: int(above[np.argmin(height[above])]), lo_in: int(below[np.argmax(height[below])])}


#: the inner-lip corners: FDP -> +1 on the face's left side, -1 on its right
CORNERS = {"2.4": 1.0, "2.5": -1.0}
#: corner search radius, fraction of the mouth's width
CORNER_REACH = 0.15


def inner_corners(vertices: np.ndarray, normals: np.ndarray, pos: dict, frame) -> dict:
    """{2.4 / 2.5: vertex id}: the inner-lip corners on the lips' slit's end wall.

    The detector's corner sits on the lips' front where they meet (MakeHuman 0.84 %, ICT 0.40 %
    of the diagonal off); the lips' inner contours end deeper, where the slit's lateral wall
    faces the midline. Among the vertices within :data:`CORNER_REACH` of the mouth's width
    (8.3-8.4) of the detected corner, the one whose normal points most toward the midline
    (``-left`` for 2.4), if it points there at least :data:`ROLL`; else the detector's is kept.
    """
    left = np.asarray(frame[0], dtype=np.float64)
    if not all(k in pos for k in ("8.3", "8.4")):
        return {}
    v = np.asarray(vertices, dtype=np.float64)
    width = abs((pos["8.3"] - pos["8.4"]) @ left)
    out = {}
    for k, sign in CORNERS.items():
        if k not in pos:
            continue
        near = np.flatnonzero(np.linalg.norm(v - pos[k], axis=1) <= CORNER_REACH * width)
        if len(near) == 0:
            continue
        inward = normals[near] @ (-sign * left)
        if inward.max() >= ROLL:
            out[k] = int(near[np.argmax(inward)])
    return out


#: outer lip corner FDP -> (its inner corner FDP, MediaPipe canonical-face points of the pair)
OUTER_CORNERS = {"8.3": ("2.4", 291, 308), "8.4": ("2.5", 61, 78)}


def outer_corners(caster, pos: dict, frame, diagonal: float) -> dict:
    """{8.3 / 8.4: (3,)}: the outer lip corners from the inner ones (2.4/2.5, the slit's end wall
    of :func:`inner_corners`) and MediaPipe's canonical face.

    Why. The detector puts the outer corner at the end of the lips' slit, on the upper lip's
    underside (MakeHuman and its identity 0.51 % of the diagonal off, 0.3 % towards the midline
    and 0.3 % up; the calibration's MW 5.5 % small); the mesh shows no feature where the hand
    points lie (the crease fades gradually). But in the eye frame of :mod:`brows` (scale: the
    outer eye corners' span ``s``) the hand files put 8.3 at the same offset from 2.4 on every
    head: (0.035, -0.011) MakeHuman, (0.036, -0.004) ICT, (0.031, -0.009) the identity,
    (0.033, -0.009) the mask; MediaPipe's canonical face (0.034, -0.008). So: the inner corner
    plus the canonical offset (side-to-side and height, times ``s``), put on the skin from in
    front by :func:`faceforge.landmarks.rules._onto_skin` (``caster``: a RayCaster or the
    frontal render). Needs 2.4/2.5 and the four eye corners in ``pos`` {fdp: (3,)}.
    """
    from faceforge.landmarks.brows import EYE_CORNERS, eye_frame
    from faceforge.landmarks.rules import _onto_skin

    left, up, fwd = (np.asarray(a, dtype=np.float64) for a in frame)
    ids = [k for k, (inner, _, _) in OUTER_CORNERS.items() if inner in pos]
    if not ids or not all(k in pos for k in EYE_CORNERS):
        return {}
    _, s = eye_frame(pos, left)
    model = _canonical()
    _, cs = eye_frame({k: model[i] for k, i in EYE_CORNERS.items()}, np.array([1.0, 0.0, 0.0]))
    targets = []
    for k in ids:
        inner, outer_i, inner_i = OUTER_CORNERS[k]
        off = (model[outer_i] - model[inner_i]) / cs          # +X the subject's left, +Y up
        targets.append(pos[inner] + (left * off[0] + up * off[1]) * s)
    hits = _onto_skin(caster, np.array(targets), fwd, diagonal)
    return {k: p for k, p in zip(ids, hits) if np.isfinite(p).all()}


def _canonical() -> np.ndarray:
    """MediaPipe's canonical face, (478, 3) cm (``data/mediapipe_canonical_478.txt``)."""
    from faceforge.landmarks.brows import canonical_model

    return canonical_model()
