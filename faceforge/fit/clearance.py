"""Clear skin that the fitted bone swallowed: the last step of the fit (§7).

The RBF fit (:mod:`faceforge.fit.head`) is smooth and global, so a skin that is
modelled deep into the head (a closed eye socket folding behind the lids, a nostril
reaching into the nasal aperture) can end up inside the fitted bone, and enhancement
landmarks cannot always push the bone out of it without ringing elsewhere. The skin
is the user's and never moves; the bone there is only a rough template. So the bone
gives way locally: for every skin vertex inside a bone, the closest bone point ``b``
(outward normal ``n``) is to move inward by ``delta = min(0, (s - b) . n - clearance)
n``. The bone is a mesh and moves by its vertices, so the push is put on the three corners
of the closest face (whose edges can be longer than the later rounds' radius), and the
displacement is spread over the neighbourhood with a compactly supported Wendland C2 bump
of radius ``R`` around each corner ``c_i``:

    u(x) = sum_i phi(|x - c_i| / R) delta_i / max(1, sum_i phi(|x - c_i| / R))
    phi(r) = (1 - r)^4 (4 r + 1) for r < 1, else 0

The normalisation keeps overlapping bumps from adding up beyond the largest push.
Only faces on the bones' common outer surface count as the closest face: where two bones
meet face to face (the molars of both jaws in occlusion) one field moves both alike, and a
skin vertex on that seam pushed out of one bone would end inside the other (MakeHuman's
cheek lining, alternating between cranium and mandible every round).
Rounds repeat until no skin vertex is inside (or ``rounds`` is reached), each with a
radius ``shrink`` times the last: the later rounds fix what is left (a vertex on a thin
nasal fin) locally, without moving the bone that the earlier rounds cleared (with a fixed
radius the pushes on the two fins of a MakeHuman nostril alternated for 5 rounds; with
0.7 it takes 3). Each round is
a :class:`BumpField`, a callable on points that is appended to the fit's map, so the
skull, the muscles lying on it, the landmarks and the jaw axes all move together and
stay in contact.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def wendland_c2(r: np.ndarray) -> np.ndarray:
    """phi(r) = (1 - r)^4 (4 r + 1) on [0, 1), 0 beyond; ``r`` (k,) float, radius-relative."""
    r = np.asarray(r, dtype=np.float64)
    out = np.zeros_like(r)
    m = r < 1.0
    out[m] = (1.0 - r[m]) ** 4 * (4.0 * r[m] + 1.0)
    return out


@dataclass(frozen=True)
class BumpField:
    """A displacement field: bumps of radius ``radius`` at ``centres (k, 3)`` carrying
    ``deltas (k, 3)`` (length units). Calling it on ``points (n, 3)`` returns the moved
    points; points farther than ``radius`` from every centre are returned unchanged."""

    centres: np.ndarray
    deltas: np.ndarray
    radius: float

    def __call__(self, points) -> np.ndarray:
        from scipy.spatial import cKDTree

        p = np.asarray(points, dtype=np.float64)
        flat = p.reshape(-1, 3)
        out = flat.copy()
        if len(self.centres) == 0 or len(flat) == 0:
            return out.reshape(p.shape)
        pairs = cKDTree(flat).sparse_distance_matrix(cKDTree(self.centres), self.radius,
                                                     output_type="coo_matrix")
        w = wendland_c2(pairs.data / self.radius)
        total = np.bincount(pairs.row, weights=w, minlength=len(flat))
        disp = np.zeros_like(flat)
        for axis in range(3):
            disp[:, axis] = np.bincount(pairs.row, weights=w * self.deltas[pairs.col, axis],
                                        minlength=len(flat))
        out += disp / np.maximum(total, 1.0)[:, None]
        return out.reshape(p.shape)


def swallowed(bones, points: np.ndarray) -> np.ndarray:
    """Bool (n,): ``points (n, 3)`` inside any closed bone of ``bones`` [(vertices, faces)]."""
    from faceforge.fit.surface import inside_closed

    inside = np.zeros(len(points), bool)
    for v, f in bones:
        inside |= inside_closed(v, f, points)
    return inside


def covered_faces(vertices: np.ndarray, faces: np.ndarray, others) -> np.ndarray:
    """Bool (m,): faces of the closed bone ``(vertices (n, 3), faces (m, 3))`` whose outer side
    lies inside one of the ``others`` [(vertices, faces)] (where two bones touch or overlap):
    the centroid, moved out along the face normal by 1e-4 of the bone's diagonal, is inside."""
    v, f = np.asarray(vertices, dtype=np.float64), np.asarray(faces)
    tri = v[f]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    probe = tri.mean(axis=1) + 1e-4 * float(np.linalg.norm(np.ptp(v, axis=0))) * n
    return swallowed(others, probe) if len(others) else np.zeros(len(f), bool)


def clearance_fields(bones, skin_points: np.ndarray, clearance: float, radius: float,
                     rounds: int = 4, shrink: float = 0.7, mirror=None) -> list[BumpField]:
    """The bump fields that move the bones off the skin they swallowed.

    Parameters
    ----------
    bones : [(vertices (n_b, 3), faces (m_b, 3))]
        Closed, outward-oriented bone meshes (fitted cranium, mandible), head space.
    skin_points : (s, 3) float
        The skin vertices that must stay outside every bone.
    clearance : float
        How far outside the bone a cleared skin vertex ends up (length units).
    radius : float
        Bump radius (length units): how far around a swallowed point the bone bends.
    rounds : int
        At most this many fields (each round re-tests the moved bones).
    shrink : float
        Round ``k`` (from 0) uses the radius ``radius * shrink ** k``.
    mirror : :class:`faceforge.geometry.mirror.Mirror`, optional
        A symmetric head's plane (``skin_points`` then hold both sides' skin): each field also
        carries its bumps' mirror images, so it commutes with the reflection and a symmetric
        bone stays symmetric. Without them a midline skin point pushed whichever of two
        mirror-twin bone faces came first: MakeHuman's nose base and front teeth ended up to
        6 mm off their twins, the muscles lying there 3 mm.

    Returns
    -------
    [BumpField], to be applied in order to every bone (and muscle, landmark) point.
    """
    from faceforge.geometry.surface_points import closest_points
    from faceforge.geometry.triangles import face_normals

    fields: list[BumpField] = []
    bones = [(np.asarray(v, dtype=np.float64), np.asarray(f)) for v, f in bones if len(f)]
    for _ in range(rounds):
        centres, deltas = [], []
        for i, (v, f) in enumerate(bones):
            inside = swallowed([(v, f)], skin_points)
            if not inside.any():
                continue
            s = skin_points[inside]
            # push from the bones' common outer surface: faces of this bone that another
            # bone covers (the molars of the upper and lower jaw in occlusion share faces with
            # opposite normals) are no way out, since the field moves both bones alike and a
            # point on such a seam pushed out of one bone ends inside the other
            open_f = f[~covered_faces(v, f, [b for j, b in enumerate(bones) if j != i])]
            b, _, tri = closest_points(s, v, open_f)
            n = face_normals(v, open_f[tri])
            below = np.einsum("ij,ij->i", s - b, n)
            if mirror is not None:
                n = _midline_pushes(s, n, mirror, radius)
            # only skin that lies beneath its closest bone face is pushed out; a point the
            # parity test calls inside but that lies above its closest face sits where the
            # fitted bone folds over itself, and pushing there only deepens the fold
            keep = below < 0.0
            if not keep.any():
                continue
            # the bumps sit on the corners of the closest face, each with the whole push: the
            # bone is a mesh and moves by its vertices, and a face can be larger than the
            # later rounds' radius (the template's edges reach 26 mm), so a bump centred on the
            # closest point alone moved no corner and left the skin inside (MakeHuman cheek)
            corners = open_f[tri[keep]].reshape(-1)
            centres.append(v[corners])
            deltas.append(np.repeat((below[keep] - clearance)[:, None] * n[keep], 3, axis=0))
        if not centres:
            break
        centres, deltas = np.vstack(centres), np.vstack(deltas)
        if mirror is not None:
            centres = np.vstack([centres, mirror(centres)])
            deltas = np.vstack([deltas, mirror.direction(deltas)])
        field = BumpField(centres, deltas, float(radius) * shrink ** len(fields))
        bones = [(field(v), f) for v, f in bones]
        fields.append(field)
    return fields


def _midline_pushes(points: np.ndarray, normals: np.ndarray, mirror, radius: float) -> np.ndarray:
    """The push directions for skin ``points (k, 3)`` from their closest bone faces' unit
    ``normals (k, 3)``: for a point on the mirror plane, the normal's in-plane part (when at
    least a fifth of it) divided by its squared length, so that the push along the face normal
    stays whole: the point's bump and its mirror image then push the same way, and their
    average (:class:`BumpField`) is that push. With the faces' own normals the
    sideways parts cancelled and MakeHuman's midline nose stayed 0.3 mm inside the bone."""
    on = np.abs(mirror.side(points)) <= 1e-9 * radius
    if not on.any():
        return normals
    n = np.array(normals, dtype=np.float64)
    flat = n[on] - np.outer(n[on] @ mirror.normal, mirror.normal)
    length = np.linalg.norm(flat, axis=1)
    ok = length > 0.2
    rows = np.flatnonzero(on)[ok]
    n[rows] = flat[ok] / length[ok, None] ** 2   # its part along the face normal is the whole push
    return n
