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

Along the rest of the lip line the red faces of the two lips press on each other in anger and the
closed visemes, and without contact the upper lip's skin went 2-3 mm through the lower one's (a
sawtooth line; docs/notes/lipcontact16.md). :func:`lip_contacts` pairs each lip's vertices near the
other lip with the other lip's faces that face them, for a one-sided contact
(:class:`faceforge.pbd.triangle_contact.TriangleContact`, ``skin.lip_contact_mm``, off by default).
"""

from __future__ import annotations

import numpy as np

from faceforge.skin.rules import COMMISSURE_RADIUS, _near_fdps

__all__ = ["commissure_quads", "lip_contacts", "LIP_CORNER_FDPS"]

#: the corners where the lips meet: inner (2.4 / 2.5) and outer (8.3 / 8.4). On the MakeHuman
#: sample they are 0.08 MW0 apart and the lip line between them folded too
LIP_CORNER_FDPS = ("2.4", "2.5", "8.3", "8.4")

#: a lip vertex behind the other lip's sheet at rest by more than this fraction of the contact's
#: radius is on its far side (inside the mouth), not in contact with it (:func:`lip_contacts`)
BEHIND = 0.1

#: a lip vertex meets a face of the other lip only where they face each other: the cosine between
#: the vertex's normal and the face's is below -FACING (at the lip corners both face forward)
FACING = 0.0

#: a lip vertex is checked against at most this many of the other lip's faces, the nearest at rest
#: (by their centroids): ICT's dense lips have 46 within 3 mm a vertex and the contact's pass cost
#: 6 ms a step; the lips slide along each other a few mm at most
NEAREST = 12

#: barycentric slack of a lip vertex's "over the other lip's face": the lips meet at a rim (MakeHuman's
#: cut lip ring sits exactly on the other lip's border edge), and a vertex that slid a hair past the
#: rim must still be held (:class:`faceforge.pbd.triangle_contact.TriangleContact`'s ``margin``)
MARGIN = 0.25


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


def lip_contacts(vertices, faces, lip_sides, radius: float):
    """The lips' one-sided contact (``skin.lip_contact_mm``): the upper and the lower lip may
    touch, not pass through each other. Returns ``(points (m,) int64, (start (m + 1,), cand (k,))
    int64, tris (t, 3) int64, floor (m,) float, reach = radius, margin =`` :data:`MARGIN` ``)`` for :class:`faceforge.pbd.triangle_contact.TriangleContact`
    (skin vertex ids; None when there are no lips or no pair within ``radius``).

    Each lip's *sheet* is its faces whose three vertices are of that lip (``lip_sides`` +1 upper,
    -1 lower; a face bridging the two lips, as MediaPipe's, belongs to neither), oriented as the
    skin's faces (their front is the skin's outside). The points are every vertex of one lip
    within ``radius`` (skin units) at rest of a vertex of the other; each is checked against the
    other lip's sheet triangles with a vertex within ``radius`` of it at rest that face it (the
    cosine of its vertex normal and the face's normal below -:data:`FACING`; at the lip corners the
    two lips face forward side by side and are left to the commissure's quads), the :data:`NEAREST`
    of them nearest. ``floor`` is 0, or
    the depth a point is already behind the other lip's sheet at rest (rest stays a fixed point).
    vertices (n, 3) rest skin, faces (f, 3), lip_sides (n,) int.
    """
    from scipy.spatial import cKDTree

    from faceforge.geometry.triangles import vertex_normals
    from faceforge.pbd.triangle_contact import signed_depths

    if lip_sides is None or not radius > 0:
        return None
    v = np.asarray(vertices, np.float64)
    f = np.asarray(faces, np.int64).reshape(-1, 3)
    sides = np.asarray(lip_sides).reshape(-1)
    fs = sides[f]
    sheet = {s: np.flatnonzero((fs == s).all(axis=1)) for s in (1, -1)}
    points, cands = [], []
    tris = f[np.r_[sheet[1], sheet[-1]]]
    offset = {1: 0, -1: len(sheet[1])}
    vn = vertex_normals(v, f)
    fn = np.cross(v[tris[:, 1]] - v[tris[:, 0]], v[tris[:, 2]] - v[tris[:, 0]])
    fn /= np.maximum(np.linalg.norm(fn, axis=1), 1e-300)[:, None]
    centre = v[tris].mean(axis=1)
    for s in (1, -1):
        mine, theirs = np.flatnonzero(sides == s), np.flatnonzero(sides == -s)
        if not len(mine) or not len(sheet[-s]):
            continue
        near = cKDTree(v[theirs]).query_ball_point(v[mine], radius)
        tree = cKDTree(v[f[sheet[-s]]].reshape(-1, 3))   # three rows per triangle
        for x, hits in zip(mine, near):
            if not hits:
                continue
            rows = offset[-s] + np.unique(np.asarray(tree.query_ball_point(v[x], radius), np.int64) // 3)
            # the lips touch where their surfaces face each other (the red faces across the lip
            # line); at the corners both face forward, side by side: no contact there
            rows = rows[fn[rows] @ vn[x] < -FACING]
            if len(rows) > NEAREST:   # the nearest by their centroids (each call tests every candidate)
                rows = rows[np.argsort(np.linalg.norm(centre[rows] - v[x], axis=1), kind="stable")[:NEAREST]]
            if len(rows):
                points.append(x)
                cands.append(rows)
    if not points:
        return None
    start = np.r_[0, np.cumsum([len(c) for c in cands])].astype(np.int64)
    cand = np.concatenate(cands).astype(np.int64)
    pts = np.asarray(points, np.int64)
    depth = np.nan_to_num(signed_depths(v, pts, start, cand, tris, MARGIN), nan=0.0)
    # a point well behind the other lip at rest is on its far side (the mouth's inside), not in contact
    keep = depth >= -BEHIND * radius
    if not keep.any():
        return None
    lens = np.diff(start)[keep]
    cand = np.concatenate([c for c, k in zip(cands, keep) if k]).astype(np.int64)
    return pts[keep], (np.r_[0, np.cumsum(lens)].astype(np.int64), cand), np.ascontiguousarray(tris), \
        np.minimum(depth[keep], 0.0), float(radius), MARGIN
