"""Skin that got inside a bone is put back out (beyond the paper; after the skin's constraints).

:class:`faceforge.anatomy.animate.SkullGuard` holds each skin vertex above the plane of the
bone triangle under it at rest. A vertex that slides over the bone (the lips onto the other
jaw's teeth, the cheek over the cheekbone) meets bone that triangle does not describe and can
end inside it. :class:`BoneCollision` finds such vertices with the same test the animation
check uses (ray parity, :class:`faceforge.geometry.parity.ParityGrid`) and moves each out
along the shortest way to ``keep`` times its rest distance above the bone.

Local signs (the closest face's normal, angle-weighted pseudonormals) were tried first and
misjudge the fitted bone where the fit folds it (MakeHuman's orbits and jaw angles): they
pushed skin in. Parity counts crossings of the whole surface and is not misled by a fold.

The bones are rigid: each is tested in its rest pose, the skin brought into the bone's rest
frame, so each bone's parity grid is built once. Only vertices that may be inside are
cast: the distance to a rigid bone is 1-Lipschitz, so a vertex nearer than ``d0`` to where
its rest position went with the bone (``d0`` its rest distance) is still outside.
"""

from __future__ import annotations

import numba
import numpy as np

from faceforge.constants import NUMBA_OPTIONS

__all__ = ["BoneCollision"]

_EYE4 = np.eye(4)


class BoneCollision:
    """Puts skin vertices found inside a rigid bone back out (see the module docstring).

    Parameters
    ----------
    rest : (n, 3) float, skin at rest (skin units)
    bodies : dict name -> (vertices (v, 3), faces (f, 3)), the bones at rest, closed
    reach : float, skin units: vertices outside a bone and within this of it at rest are guarded
    keep : float in [0, 1): a vertex put back out sits at ``keep * d0`` from the bone

    Attributes
    ----------
    guarded : dict name -> (vertex ids (k,) int, rest positions (k, 3) in the bone's rest frame,
        floor (k,), rest distance (k,))
    """

    def __init__(self, rest: np.ndarray, bodies: dict, reach: float, keep: float = 0.5):
        import trimesh

        from faceforge.geometry.parity import ParityGrid

        rest = np.asarray(rest, dtype=np.float64).reshape(-1, 3)
        self.names, self.guarded, self._grids, self._trees = [], {}, {}, {}
        for name, (v, f) in bodies.items():
            mesh = trimesh.Trimesh(np.asarray(v, np.float64), np.asarray(f, np.int64), process=False)
            if not len(rest) or not len(mesh.faces):
                continue
            _, dist, _ = trimesh.proximity.closest_point(mesh, rest)
            grid = ParityGrid(mesh.vertices, mesh.faces)
            ids = np.flatnonzero((dist < reach) & (dist > 0.0) & ~grid.contains(rest))
            self.names.append(name)
            self.guarded[name] = (ids, rest[ids], keep * dist[ids], dist[ids])
            self._grids[name] = grid
            self._trees[name] = _TriangleTree(mesh.triangles)
        self._all = {name: np.arange(len(self.guarded[name][0])) for name in self.names}

    def apply(self, positions: np.ndarray, transforms: dict, only=None) -> int:
        """Move the guarded vertices of ``positions`` ((n, 3) float, in place) that are inside a
        bone out of it. ``transforms``: name -> (4, 4) rigid transform of that bone from its rest
        pose (missing: identity). ``only`` (optional, (p,) int): test just these vertices (the
        others were found outside with the bones where they are now and have not moved since).
        Returns how many moved; :attr:`moved` holds their ids ((k,) int, repeats allowed)."""
        # every bone sees the positions as they came in (a vertex pushed out of one bone is not
        # re-tested against the other in the same pass)
        passes = []
        if only is not None:
            listed = np.zeros(len(positions), dtype=bool)
            listed[np.asarray(only, dtype=np.int64)] = True
        for name in self.names:
            t = np.asarray(transforms.get(name, _EYE4), dtype=np.float64)
            ids, rest, _, slack = self.guarded[name]
            rows = self._all[name] if only is None else np.flatnonzero(listed[ids])
            p, kept = np.empty((len(rows), 3)), np.empty_like(rows)
            maybe = kept[:_maybe_inside(positions, ids, rows, rest, slack, t, p, kept)]
            passes.append((name, t, p[:len(maybe)], maybe))
        moved = []
        for name, t, p, maybe in passes:
            hit = self._grids[name].contains(p)
            if not hit.any():
                continue
            ids, _, floor, _ = self.guarded[name]
            k = maybe[hit]
            q, face = self._trees[name].closest(p[hit])
            out = q + floor[k, None] * _outward(q - p[hit], self._trees[name].normals[face])
            positions[ids[k]] = out @ t[:3, :3].T + t[:3, 3]
            moved.append(ids[k])
        self.moved = np.concatenate(moved) if moved else np.zeros(0, dtype=np.int64)
        return len(self.moved)



def _outward(v: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Unit directions ``(k, 3)`` out of the bone at closest points: the closest triangle's
    normal ``normal (k, 3)`` (unit, or 0 when degenerate), turned to the side of ``v = q - p``
    (p inside, q its closest point). Not ``v / |v|``: for skin just inside (|v| << the floor)
    that direction is ill-conditioned (a vertex 1e-6 inside, moved by 1e-12, lands
    1e-12 x floor / 1e-6 further off); the normal does not move with p. A degenerate triangle
    falls back to ``v / |v|``. (Calibrated MakeHuman joy still grows 1e-13 of round-off to
    ~1e-2 within 20 frames with either direction: the collision and orientation passes
    together do that; with either of them off it stays below 1e-6.)"""
    side = np.einsum("ij,ij->i", normal, v)
    out = np.where(side[:, None] < 0.0, -normal, normal)
    flat = ~np.any(normal != 0.0, axis=1)
    if flat.any():
        d = np.linalg.norm(v[flat], axis=1)
        out[flat] = v[flat] / np.maximum(d, 1e-300)[:, None]
    return out


@numba.njit(**NUMBA_OPTIONS)
def _maybe_inside(x, ids, rows, rest, slack, t, p, kept):  # pragma: no cover - numba
    """The guarded ``rows`` whose vertex ``x[ids[row]]``, brought into the bone's rest frame
    (``R^T (x - t)`` with ``t (4, 4)``), is at least ``slack[row]`` from where its rest position
    went: writes them in order into ``kept[:k]`` and their rest-frame positions into ``p[:k]``
    (``kept``, ``p``: as long as ``rows``); returns k."""
    k = 0
    for j in range(rows.shape[0]):
        r = rows[j]
        i = ids[r]
        dx = x[i, 0] - t[0, 3]
        dy = x[i, 1] - t[1, 3]
        dz = x[i, 2] - t[2, 3]
        px = dx * t[0, 0] + dy * t[1, 0] + dz * t[2, 0]
        py = dx * t[0, 1] + dy * t[1, 1] + dz * t[2, 1]
        pz = dx * t[0, 2] + dy * t[1, 2] + dz * t[2, 2]
        ex = px - rest[r, 0]
        ey = py - rest[r, 1]
        ez = pz - rest[r, 2]
        if ex * ex + ey * ey + ez * ez >= slack[r] * slack[r]:
            p[k, 0] = px
            p[k, 1] = py
            p[k, 2] = pz
            kept[k] = r
            k += 1
    return k


class _TriangleTree:
    """Closest points on a static triangle soup ``triangles (m, 3, 3)``: a k-d tree of the
    centroids; the triangles that can hold a point's closest point are those whose centroid
    lies within (distance to the nearest centroid + the largest triangle radius)."""

    def __init__(self, triangles: np.ndarray):
        from scipy.spatial import cKDTree

        self.triangles = np.asarray(triangles, dtype=np.float64)
        centre = self.triangles.mean(axis=1)
        self.reach = float(np.linalg.norm(self.triangles - centre[:, None], axis=2).max())
        self.tree = cKDTree(centre)
        n = np.cross(self.triangles[:, 1] - self.triangles[:, 0],
                     self.triangles[:, 2] - self.triangles[:, 0])
        length = np.linalg.norm(n, axis=1)
        #: (m, 3) unit normals of the triangles (0 where degenerate)
        self.normals = np.divide(n, length[:, None], out=np.zeros_like(n),
                                 where=length[:, None] > 0.0)

    def closest(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(q (k, 3), face (k,) int)``: the closest points of the soup to ``points (k, 3)`` and
        the triangles holding them (compiled, :func:`_closest_in`; the tests compare q with
        trimesh's). (Trying each point's 16 nearest centroids first, complete when the 16th is
        ``reach`` beyond the best, was dropped: on the MakeHuman skull ``reach`` is 0.1 of a
        2.7-unit head and 1,121 of 1,128 points of a joy playback needed the full search.)"""
        points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        near, _ = self.tree.query(points)
        lists = self.tree.query_ball_point(points, near + self.reach)
        start = np.concatenate([[0], np.cumsum([len(c) for c in lists])]).astype(np.int64)
        cand = np.concatenate([np.asarray(c, dtype=np.int64) for c in lists]) if len(lists) else np.zeros(0, np.int64)
        face = np.zeros(len(points), dtype=np.int64)
        return _closest_in(points, self.triangles, start, cand, face), face


@numba.njit(**NUMBA_OPTIONS)
def _closest_in(points, tri, start, cand, face):  # pragma: no cover - numba
    """For each point k the closest point of the triangles ``tri[cand[start[k]:start[k + 1]]]``;
    ``face[k]`` is set to the triangle holding it (the first of equals)."""
    out = np.empty_like(points)
    for k in range(points.shape[0]):
        px, py, pz = points[k, 0], points[k, 1], points[k, 2]
        best = np.inf
        for j in range(start[k], start[k + 1]):
            t = tri[cand[j]]
            qx, qy, qz = _closest_on(px, py, pz, t[0, 0], t[0, 1], t[0, 2], t[1, 0], t[1, 1], t[1, 2],
                                     t[2, 0], t[2, 1], t[2, 2])
            d = (px - qx) ** 2 + (py - qy) ** 2 + (pz - qz) ** 2
            if d < best:
                best = d
                out[k, 0], out[k, 1], out[k, 2] = qx, qy, qz
                face[k] = cand[j]
    return out


@numba.njit(inline="always", **NUMBA_OPTIONS)
def _closest_on(px, py, pz, ax, ay, az, bx, by, bz, cx, cy, cz):  # pragma: no cover - numba
    """Closest point of triangle abc to p, by the Voronoi regions of its corners, edges, face."""
    abx, aby, abz = bx - ax, by - ay, bz - az
    acx, acy, acz = cx - ax, cy - ay, cz - az
    apx, apy, apz = px - ax, py - ay, pz - az
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    if d1 <= 0.0 and d2 <= 0.0:
        return ax, ay, az
    bpx, bpy, bpz = px - bx, py - by, pz - bz
    d3 = abx * bpx + aby * bpy + abz * bpz
    d4 = acx * bpx + acy * bpy + acz * bpz
    if d3 >= 0.0 and d4 <= d3:
        return bx, by, bz
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        s = d1 / (d1 - d3)
        return ax + s * abx, ay + s * aby, az + s * abz
    cpx, cpy, cpz = px - cx, py - cy, pz - cz
    d5 = abx * cpx + aby * cpy + abz * cpz
    d6 = acx * cpx + acy * cpy + acz * cpz
    if d6 >= 0.0 and d5 <= d6:
        return cx, cy, cz
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        s = d2 / (d2 - d6)
        return ax + s * acx, ay + s * acy, az + s * acz
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        s = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return bx + s * (cx - bx), by + s * (cy - by), bz + s * (cz - bz)
    den = va + vb + vc
    if den == 0.0:   # degenerate triangle
        return ax, ay, az
    return ax + abx * (vb / den) + acx * (vc / den), ay + aby * (vb / den) + acy * (vc / den), \
        az + abz * (vb / den) + acz * (vc / den)
