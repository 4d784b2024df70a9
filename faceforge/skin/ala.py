"""The ala's insertion (``bind.ala_mm``, beyond §8): the skin of the alae binds to the levator
labii superioris alaeque nasi, not to the bone.

The levator labii superioris alaeque nasi (``levator_labii_inner`` of the muscle map) runs from
the maxilla's frontal process down beside the nose; its medial slip inserts into the alar
cartilage and the skin over it, its lateral slip into the upper lip. Contracted, it lifts and
flares the ala (FACS AU9, the sneer; MakeHuman's nose-*-elevation units). By its rays (§8) the
ala's skin looks past the thin muscle onto the maxilla, and ``bind.nose_on_bone`` ties the rest
of the nose to the cranium: on the MakeHuman sample 64 of the 86 vertices of one ala and its
nostril rim sat on the bone, and the unit's ala moved 0.35 of its field (docs/notes/nose21.md).

The ala's skin that lies on the bone binds instead to the muscle, at the muscle's point nearest
in a metric that counts the distance along ``up`` :data:`ALA_STRETCH` times (the point at the
ala's own height), among the muscle's faces beside the ala (:data:`ALA_LATERAL`). The plain
closest point was the muscle's lowest, most medial corner under the columella (for 17 of 23
vertices of an ala), which the contracting muscle draws up and 12 mm back into the nasal
aperture: the ala went into the face (nose-left-elevation 0.394); at the ala's height but on
the muscle's medial edge it still went 3-9 mm back (0.645); beside the ala, 1.4-3.8 (0.778).
"""

from __future__ import annotations

import numpy as np

from faceforge.constants import FLOAT, INT

#: ``bind.ala_mm`` (its default when on): the ala's skin reaches this many mm (an average adult's,
#: scaled by ES0) from the line of the alar base to the alar crease
ALA_MM = 5.0

#: the nearest muscle point counts distance along ``up`` this many times (1: the closest point)
ALA_STRETCH = 10.0

#: the ala binds to the muscle's faces at least this fraction of the alar base's distance from the
#: midline away from it (:func:`beside_ala`): the part beside the ala, not the slip under the
#: nostril's floor, which the contracting muscle draws back into the nasal aperture
ALA_LATERAL = 0.75

#: the alar creases (the nose's widest points) and the alar bases, subject's left and right
ALA_FDPS = ("9.1", "9.2", "9.4", "9.5")


def ala_mask(vertices, landmarks: dict, reach_mm: float = ALA_MM) -> np.ndarray:
    """(n,) bool: the alae and the alar grooves beside them -- the vertices within ``reach_mm``
    (scaled by ES0, :func:`faceforge.anatomy.tissue.units_per_mm`) of the segment from each alar
    crease (FDP 9.1 / 9.2) to the alar base nearer it (9.4 / 9.5). No vertex without the four
    FDPs and ES0's, or for ``reach_mm <= 0``."""
    from faceforge.anatomy.tissue import units_per_mm

    v = np.asarray(vertices, FLOAT)
    out = np.zeros(len(v), bool)
    if reach_mm <= 0 or any(k not in landmarks for k in ALA_FDPS):
        return out
    try:
        r = float(reach_mm) * units_per_mm(landmarks)
    except KeyError:
        return out
    for crease in ("9.1", "9.2"):
        c = np.asarray(landmarks[crease], FLOAT)
        base = min((np.asarray(landmarks[k], FLOAT) for k in ("9.4", "9.5")), key=lambda p: float(np.linalg.norm(p - c)))
        ab = c - base
        t = np.clip(((v - base) @ ab) / max(float(ab @ ab), 1e-300), 0.0, 1.0)
        out |= np.linalg.norm(v - (base + t[:, None] * ab), axis=1) <= r
    return out


def stretched_closest(points, vertices, faces, up=(0.0, 1.0, 0.0), stretch: float = ALA_STRETCH):
    """The nearest point of the mesh ``vertices (m, 3)``, ``faces (l, 3)`` to each of ``points
    (k, 3)`` with distances along ``up`` counted ``stretch`` times (the space scaled by ``stretch``
    along ``up``, where barycentric coordinates are unchanged). Returns ``(face_ids (k,) int,
    bary (k, 3), points (k, 3) on the unscaled mesh, distance (k,) in the stretched metric)``."""
    from faceforge.geometry.surface_points import closest_points
    from faceforge.geometry.triangles import barycentric

    u = np.asarray(up, FLOAT) / np.linalg.norm(up)
    s = np.eye(3) + (float(stretch) - 1.0) * np.outer(u, u)
    mv = np.asarray(vertices, FLOAT) @ s
    p, d, tri = closest_points(np.asarray(points, FLOAT).reshape(-1, 3) @ s, mv, faces)
    tri = np.asarray(tri, INT)
    bary = barycentric(p, mv, faces, tri)
    f = np.asarray(faces, INT)[tri]
    on = np.einsum("kj,kjd->kd", bary, np.asarray(vertices, FLOAT)[f])
    return tri, bary, on, d


def beside_ala(vertices, faces, landmarks: dict, lateral: float = ALA_LATERAL) -> np.ndarray:
    """(l,) bool: the triangles ``faces`` of ``vertices (m, 3)`` whose centroid lies at least
    ``lateral`` times the alar bases' half distance (FDPs 9.4, 9.5) from the midline (the plane
    through their middle across them); all of them without the two FDPs or for ``lateral <= 0``."""
    f = np.asarray(faces, INT)
    if lateral <= 0 or "9.4" not in landmarks or "9.5" not in landmarks:
        return np.ones(len(f), bool)
    a, b = np.asarray(landmarks["9.4"], FLOAT), np.asarray(landmarks["9.5"], FLOAT)
    half = 0.5 * float(np.linalg.norm(b - a))
    if half <= 0.0:
        return np.ones(len(f), bool)
    c = np.asarray(vertices, FLOAT)[f].mean(axis=1)
    return np.abs((c - 0.5 * (a + b)) @ ((b - a) / (2.0 * half))) >= lateral * half


def ala_binding(binding, vertices, bodies, muscles, mask, max_distance: float, up=(0.0, 1.0, 0.0),
                stretch: float = ALA_STRETCH, landmarks=None, lateral: float = ALA_LATERAL):
    """``binding`` (:class:`faceforge.skin.binding.Binding`) with the vertices of ``mask`` (n,)
    bool whose only anchor is on the bone rebound to the point of the bodies ``muscles`` (indices
    into ``bodies``) nearest in the stretched metric of :func:`stretched_closest`, within
    ``max_distance`` (skin units, stretched), on the muscles' faces beside the ala
    (:func:`beside_ala` with ``landmarks``; None: all faces); a vertex with none in reach keeps
    its anchor. Returns ``(binding, count rebound)``."""
    from dataclasses import replace

    from faceforge.skin.casting import MUSCLE

    v = np.asarray(vertices, FLOAT)
    todo, row = binding.sole_bone_anchors(mask)
    if not len(todo) or not len(muscles):
        return binding, 0
    best = np.full(len(todo), np.inf)
    body = np.full(len(todo), -1, INT)
    face = np.full(len(todo), -1, INT)
    bary = np.zeros((len(todo), 3))
    pts = np.zeros((len(todo), 3))
    for i in muscles:
        keep = np.flatnonzero(beside_ala(bodies[i].vertices, bodies[i].faces, landmarks or {}, lateral))
        if not len(keep):
            continue
        tri, b, on, d = stretched_closest(v[todo], bodies[i].vertices, np.asarray(bodies[i].faces, INT)[keep], up,
                                          stretch)
        tri = keep[tri]
        take = (d < best) & (d <= max_distance)
        best[take], body[take], face[take], bary[take], pts[take] = d[take], i, tri[take], b[take], on[take]
    ok = np.isfinite(best)
    if not ok.any():
        return binding, 0
    moved, r = todo[ok], row[todo[ok]]
    out = {k: np.asarray(getattr(binding, k)).copy() for k in
           ("body", "face_ids", "bary", "points", "distance", "outward", "closest", "status")}
    out["body"][r], out["face_ids"][r], out["bary"][r], out["points"][r] = body[ok], face[ok], bary[ok], pts[ok]
    out["distance"][r] = np.linalg.norm(v[moved] - pts[ok], axis=1)
    out["outward"][r] = out["closest"][r] = False
    out["status"][moved] = MUSCLE
    return replace(binding, **out), len(moved)
