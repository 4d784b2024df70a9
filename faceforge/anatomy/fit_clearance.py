"""Clear skin that the fitted bone swallowed: the last step of the fit (§7).

The RBF fit (:mod:`faceforge.anatomy.fit`) is smooth and global, so a skin that is
modelled deep into the head (a closed eye socket folding behind the lids, a nostril
reaching into the nasal aperture) can end up inside the fitted bone, and enhancement
landmarks cannot always push the bone out of it without ringing elsewhere. The skin
is the user's and never moves; the bone there is only a rough template. So the bone
gives way locally: for every skin vertex inside a bone, the closest bone point ``b``
(outward normal ``n``) is to move inward by ``delta = min(0, (s - b) . n - clearance)
n``, and the displacement is spread over the neighbourhood with a compactly supported
Wendland C2 bump of radius ``R``:

    u(x) = sum_i phi(|x - b_i| / R) delta_i / max(1, sum_i phi(|x - b_i| / R))
    phi(r) = (1 - r)^4 (4 r + 1) for r < 1, else 0

The normalisation keeps overlapping bumps from adding up beyond the largest push.
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
    from faceforge.anatomy.fit import inside_closed

    inside = np.zeros(len(points), bool)
    for v, f in bones:
        inside |= inside_closed(v, f, points)
    return inside


def clearance_fields(bones, skin_points: np.ndarray, clearance: float, radius: float,
                     rounds: int = 4, shrink: float = 0.7) -> list[BumpField]:
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

    Returns
    -------
    [BumpField], to be applied in order to every bone (and muscle, landmark) point.
    """
    import trimesh

    fields: list[BumpField] = []
    bones = [(np.asarray(v, dtype=np.float64), np.asarray(f)) for v, f in bones if len(f)]
    for _ in range(rounds):
        centres, deltas = [], []
        for v, f in bones:
            inside = swallowed([(v, f)], skin_points)
            if not inside.any():
                continue
            s = skin_points[inside]
            mesh = trimesh.Trimesh(v, f, process=False, validate=False)
            b, _, tri = trimesh.proximity.closest_point(mesh, s)
            n = mesh.face_normals[tri]
            below = np.einsum("ij,ij->i", s - b, n)
            # only skin that lies beneath its closest bone face is pushed out; a point the
            # parity test calls inside but that lies above its closest face sits where the
            # fitted bone folds over itself, and pushing there only deepens the fold
            keep = below < 0.0
            if not keep.any():
                continue
            centres.append(b[keep])
            deltas.append((below[keep] - clearance)[:, None] * n[keep])
        if not centres:
            break
        field = BumpField(np.vstack(centres), np.vstack(deltas), float(radius) * shrink ** len(fields))
        bones = [(field(v), f) for v, f in bones]
        fields.append(field)
    return fields
