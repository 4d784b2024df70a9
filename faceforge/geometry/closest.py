"""Closest points on a triangle mesh: a uniform grid of the triangles and a compiled search.

``trimesh.proximity.closest_point`` builds an r-tree of the triangles' boxes for every new
mesh and gathers each point's candidates in Python. Here every triangle is listed in the
cells of a uniform grid that its bounding box overlaps, and one numba loop searches, per
point, the shells of cells around it outward until no unvisited cell can hold anything
nearer than the best triangle found (the tests compare the points with trimesh's). A call
costs ~2 us plus the search, which is what the per-frame bone collision needs (it asks for
a handful of points a frame: a k-d tree of centroids answering through Python lists took
~40-150 us a call).
"""

from __future__ import annotations

import numba
import numpy as np

from faceforge.constants import NUMBA_OPTIONS

__all__ = ["TriangleGrid"]

#: triangles whose distances to a point differ by less than TIE x the grid's cell are equally
#: near (the lowest index wins): rounding must not choose between mirror-image triangles
TIE = 1e-10

#: grid cells per axis at most (a skull: ~40 at two triangle diameters a cell)
MAX_CELLS = 96


class TriangleGrid:
    """Closest points on a static triangle soup ``triangles (m, 3, 3)``, ``m >= 1``, finite.

    The grid's cells are cubes of about two triangle diameters (the median triangle's;
    at most :data:`MAX_CELLS` a side); a triangle is listed in every cell its bounding box
    overlaps."""

    def __init__(self, triangles: np.ndarray):
        self.triangles = np.ascontiguousarray(triangles, dtype=np.float64).reshape(-1, 3, 3)
        t = self.triangles
        if not len(t) or not np.isfinite(t).all():
            raise ValueError(f"TriangleGrid needs at least one triangle, all finite "
                             f"(got {len(t)})")
        n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        length = np.linalg.norm(n, axis=1)
        #: (m, 3) unit normals of the triangles (0 where degenerate)
        self.normals = np.divide(n, length[:, None], out=np.zeros_like(n),
                                 where=length[:, None] > 0.0)
        lo, hi = t.min(axis=1), t.max(axis=1)
        self.origin = lo.min(axis=0)
        extent = float((hi.max(axis=0) - self.origin).max())
        size = float(np.median((hi - lo).max(axis=1))) * 2.0
        self.cell = max(size, extent / MAX_CELLS, 1e-300 if extent == 0.0 else extent * 1e-9)
        self.dims = np.minimum(((hi.max(axis=0) - self.origin) / self.cell).astype(np.int64) + 1,
                               MAX_CELLS)
        first = self._cells(lo)
        last = self._cells(hi)
        self.start, self.items = _fill_cells(first, last, self.dims)

    def _cells(self, p: np.ndarray) -> np.ndarray:
        """Cell coordinates ``(k, 3) int64`` of points ``p (k, 3)``, clamped to the grid."""
        c = np.floor((p - self.origin) / self.cell)
        return np.clip(c, 0, self.dims - 1).astype(np.int64)

    def closest(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(q (k, 3), face (k,) int)``: the closest points of the soup to ``points (k, 3)``
        (finite) and the triangles holding them (of equally near triangles, within
        ``TIE`` x cell, the lowest index). Compiled: :func:`_closest_in`; the tests compare q with trimesh's."""
        points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        if not np.isfinite(points).all():
            raise ValueError("TriangleGrid.closest: points must be finite")
        face = np.zeros(len(points), dtype=np.int64)
        q = _closest_in(points, self.triangles, self.origin, self.cell, self.dims,
                        self.start, self.items, face)
        return q, face


@numba.njit(**NUMBA_OPTIONS)
def _fill_cells(first, last, dims):  # pragma: no cover - numba
    """CSR lists of the triangles in each cell ``(start (cells + 1,), items)``; triangle t
    covers the cells ``first[t] ..= last[t]`` (coordinates, per axis)."""
    cells = dims[0] * dims[1] * dims[2]
    count = np.zeros(cells + 1, dtype=np.int64)
    for t in range(first.shape[0]):
        for i in range(first[t, 0], last[t, 0] + 1):
            for j in range(first[t, 1], last[t, 1] + 1):
                for k in range(first[t, 2], last[t, 2] + 1):
                    count[(i * dims[1] + j) * dims[2] + k + 1] += 1
    start = np.cumsum(count)
    fill = start[:-1].copy()
    items = np.empty(start[-1], dtype=np.int64)
    for t in range(first.shape[0]):
        for i in range(first[t, 0], last[t, 0] + 1):
            for j in range(first[t, 1], last[t, 1] + 1):
                for k in range(first[t, 2], last[t, 2] + 1):
                    c = (i * dims[1] + j) * dims[2] + k
                    items[fill[c]] = t
                    fill[c] += 1
    return start, items


@numba.njit(**NUMBA_OPTIONS)
def _closest_in(points, tri, origin, cell, dims, start, items, face):  # pragma: no cover
    """For each point k the closest point of the triangles ``tri``, searching the grid
    ``(origin (3,), cell, dims (3,), start, items)`` of :class:`TriangleGrid` shell by shell
    around the point's (clamped) cell; ``face[k]`` is set to the triangle holding it (the
    lowest index of equally near ones)."""
    out = np.empty_like(points)
    tie = TIE * cell
    seen = np.full(tri.shape[0], -1, dtype=np.int64)  # the last point that measured each
    c = np.empty(3, dtype=np.int64)
    gap2 = np.empty(3)
    for k in range(points.shape[0]):
        p0, p1, p2 = points[k, 0], points[k, 1], points[k, 2]
        for a in range(3):
            v = np.floor((points[k, a] - origin[a]) / cell)
            c[a] = min(max(v, 0.0), dims[a] - 1.0)
            # how far the point lies outside the grid's box along this axis: every cell is at
            # least that far along it (a far point's search then stops after a few shells)
            g = max(origin[a] - points[k, a], points[k, a] - (origin[a] + dims[a] * cell), 0.0)
            gap2[a] = g * g
        best = np.inf     # the best triangle's distance (not squared)
        r = 0
        while True:
            for i in range(max(c[0] - r, 0), min(c[0] + r, dims[0] - 1) + 1):
                for j in range(max(c[1] - r, 0), min(c[1] + r, dims[1] - 1) + 1):
                    rim = abs(i - c[0]) == r or abs(j - c[1]) == r
                    for kk in range(max(c[2] - r, 0), min(c[2] + r, dims[2] - 1) + 1):
                        if not rim and abs(kk - c[2]) != r:
                            continue   # inside the shell: visited at a smaller r
                        cid = (i * dims[1] + j) * dims[2] + kk
                        for s in range(start[cid], start[cid + 1]):
                            t = items[s]
                            if seen[t] == k:
                                continue
                            seen[t] = k
                            qx, qy, qz = _closest_on(
                                p0, p1, p2, tri[t, 0, 0], tri[t, 0, 1], tri[t, 0, 2],
                                tri[t, 1, 0], tri[t, 1, 1], tri[t, 1, 2],
                                tri[t, 2, 0], tri[t, 2, 1], tri[t, 2, 2])
                            d = np.sqrt((p0 - qx) ** 2 + (p1 - qy) ** 2 + (p2 - qz) ** 2)
                            # within tie of the best: equally near, the lower index wins (a
                            # point on a symmetric mesh's mirror plane must not pick its side
                            # by the last bits of its coordinates)
                            if d < best - tie or (d <= best + tie and t < face[k]):
                                best = d
                                out[k, 0], out[k, 1], out[k, 2] = qx, qy, qz
                                face[k] = t
            # the nearest (squared) an unvisited cell can be: beyond one of the visited cube's
            # faces that are not the grid's own, and outside the box along the other axes
            bound = np.inf
            for a in range(3):
                rest = gap2[0] + gap2[1] + gap2[2] - gap2[a]
                if c[a] - r > 0:
                    d = max(points[k, a] - (origin[a] + (c[a] - r) * cell), 0.0)
                    bound = min(bound, d * d + rest)
                if c[a] + r < dims[a] - 1:
                    d = max(origin[a] + (c[a] + r + 1) * cell - points[k, a], 0.0)
                    bound = min(bound, d * d + rest)
            # strictly nearer: an equally near triangle beyond may have a lower index
            if bound == np.inf or (best + tie) * (best + tie) < bound:
                break
            r += 1
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
