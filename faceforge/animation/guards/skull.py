"""Skin against the skull (beyond the paper): :class:`SkullGuard` keeps skin that lies close
to the bone at rest from being pulled through it, one compiled pass per skin step."""

from __future__ import annotations

import math

import numba
import numpy as np

from faceforge.constants import NUMBA_OPTIONS


class SkullGuard:
    """Keeps skin that lies close to the bone from being pulled through it.

    Where the soft tissue is thin (nose bridge, upper lip over the maxilla, chin), a muscle
    pull or the jaw can drag a skin vertex through the skull. At rest each skin vertex
    within ``reach`` of a bone gets its nearest bone point (triangle + barycentric
    coordinates) and its rest depth ``d0`` along that triangle's normal; every frame the
    vertex is pushed back along the current normal so that its depth stays at least
    ``keep * d0`` (the tissue may thin, not vanish). Vertices inside the bone at rest (mouth
    folds around the teeth) are left alone.

    Parameters
    ----------
    rest : (n, 3) float, skin at rest
    bodies : dict name -> (vertices (v, 3), faces (f, 3)), the bones at rest
    reach : float, skin units
    keep : float in [0, 1)
    """

    def __init__(self, rest: np.ndarray, bodies: dict, reach: float, keep: float = 0.5):
        import trimesh

        from faceforge.geometry.surface_points import closest_points

        self.names = list(bodies)
        verts = [np.asarray(bodies[n][0], dtype=float) for n in self.names]
        faces = [np.asarray(bodies[n][1], dtype=np.int64) for n in self.names]
        offs = np.cumsum([0] + [len(v) for v in verts])
        foffs = np.cumsum([0] + [len(f) for f in faces])
        mesh = trimesh.Trimesh(np.vstack(verts), np.vstack([f + o for f, o in zip(faces, offs)]), process=False)
        points, dist, tri = closest_points(np.asarray(rest, dtype=float), mesh.vertices, mesh.faces)
        body = np.searchsorted(foffs, tri, side="right") - 1
        local = tri - foffs[body]
        t = mesh.triangles[tri]
        n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
        depth = np.einsum("ij,ij->i", np.asarray(rest, dtype=float) - points, n)
        inside = np.zeros(len(rest), dtype=bool)
        if len(rest):
            inside = mesh.contains(np.asarray(rest, dtype=float)) if mesh.is_watertight else depth < 0
        sel = (dist < reach) & (depth > 0.0) & ~inside
        self.vertex = np.flatnonzero(sel)
        self.body = body[sel]
        self.face = local[sel]
        self.bary = trimesh.triangles.points_to_barycentric(t[sel], points[sel])
        self.floor = keep * depth[sel]
        self.faces = faces
        # each guarded vertex's bone triangle as ids into the bodies stacked in ``names`` order
        self._ids = np.ascontiguousarray(np.asarray(mesh.faces)[tri[sel]], dtype=np.int64)
        self._slot = np.full(len(rest), -1, dtype=np.int64)   # skin vertex -> its row here, or -1
        self._slot[self.vertex] = self._all = np.arange(len(self.vertex), dtype=np.int64)
        self._mark = np.zeros(len(self.vertex), dtype=np.uint8)

    def apply(self, positions: np.ndarray, bodies_now: dict) -> int:
        """Push guarded vertices of ``positions`` (n, 3, modified in place) out to their floor.

        bodies_now : dict name -> (v, 3) current bone vertices. Returns how many moved.
        One compiled pass (:func:`_skull_guard`; its plain twin is in the tests).
        """
        if not len(self.vertex):
            return 0
        bones = np.ascontiguousarray(np.vstack([np.asarray(bodies_now[n], dtype=float) for n in self.names]))
        return self.apply_stacked(positions, bones)

    def apply_stacked(self, positions: np.ndarray, bones: np.ndarray, moved=None, only=None) -> int:
        """:meth:`apply` with the current bone vertices already stacked in :attr:`names` order,
        ``bones (sum v, 3)`` float64 C-contiguous (e.g. rows of a world mesh that starts with
        the same bodies in the same order): no per-frame copy. ``moved`` (optional, int64,
        at least ``len(vertex)`` long) receives the moved vertices in its first rows.

        ``only`` (optional, (p,) int skin vertices, repeats allowed): test just these (the
        guarded ones among them, in the guard's order); for a caller that knows every other
        guarded vertex is where a pass with the same bones left it without pushing it (a
        pushed vertex may be nudged again by round-off, so it belongs in ``only``): then the
        result is that of a full pass."""
        if not len(self.vertex):
            return 0
        if moved is None:
            moved = np.empty(len(self.vertex), dtype=np.int64)
        slots = self._all if only is None else _guarded_rows(np.asarray(only, dtype=np.int64), self._slot, self._mark)
        return int(_skull_guard(positions, self.vertex, self._ids, self.bary, self.floor, bones, moved, slots))


@numba.njit(**NUMBA_OPTIONS)
def _guarded_rows(vertices, slot, mark):
    """Ascending unique rows ``slot[v] >= 0`` of the skin vertices ``vertices (p,)`` (repeats
    allowed); ``mark`` uint8 scratch, one per row, all 0 (left so)."""
    count = 0
    for v in vertices:
        k = slot[v]
        if k >= 0 and mark[k] == 0:
            mark[k] = 1
            count += 1
    out = np.empty(count, np.int64)
    i = 0
    for k in range(mark.shape[0]):
        if mark[k]:
            out[i] = k
            i += 1
            mark[k] = 0
    return out


@numba.njit(**NUMBA_OPTIONS)
def _skull_guard(x, vertex, ids, bary, floor, bones, out, slots):
    """For each guarded vertex ``vertex[k]``, ``k`` in ``slots`` (ascending), of ``x (n, 3)``:
    its bone point ``s`` (``bary[k]`` on triangle ``ids[k]`` of ``bones``) and unit normal
    ``nrm``; where the depth ``(x - s) . nrm`` is below ``floor[k]``, move it out along ``nrm``
    to the floor. In place; returns how many moved, whose vertex ids go to the first rows of
    ``out``."""
    moved = 0
    for k in slots:
        a, b, c = ids[k, 0], ids[k, 1], ids[k, 2]
        e1x, e1y, e1z = bones[b, 0] - bones[a, 0], bones[b, 1] - bones[a, 1], bones[b, 2] - bones[a, 2]
        e2x, e2y, e2z = bones[c, 0] - bones[a, 0], bones[c, 1] - bones[a, 1], bones[c, 2] - bones[a, 2]
        nx, ny, nz = e1y * e2z - e1z * e2y, e1z * e2x - e1x * e2z, e1x * e2y - e1y * e2x
        length = max(math.sqrt(nx * nx + ny * ny + nz * nz), 1e-300)
        nx, ny, nz = nx / length, ny / length, nz / length
        v = vertex[k]
        sx = bary[k, 0] * bones[a, 0] + bary[k, 1] * bones[b, 0] + bary[k, 2] * bones[c, 0]
        sy = bary[k, 0] * bones[a, 1] + bary[k, 1] * bones[b, 1] + bary[k, 2] * bones[c, 1]
        sz = bary[k, 0] * bones[a, 2] + bary[k, 1] * bones[b, 2] + bary[k, 2] * bones[c, 2]
        depth = (x[v, 0] - sx) * nx + (x[v, 1] - sy) * ny + (x[v, 2] - sz) * nz
        if depth < floor[k]:
            push = floor[k] - depth
            x[v, 0] += push * nx
            x[v, 1] += push * ny
            x[v, 2] += push * nz
            out[moved] = v
            moved += 1
    return moved
