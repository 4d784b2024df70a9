"""Inside a closed triangle mesh, by exact-rule ray parity along +X and -X (compiled).

A point is inside when the ray from it along +X and the ray along -X both cross the surface an
odd number of times. The rays are parallel to X, so a crossing is a triangle whose projection
onto the (y, z) plane covers the point's (y, z); :class:`ParityGrid` bins the triangles' (y, z)
bounding boxes in a uniform grid once, and a query visits only the triangles of its cell.

Where the point's (y, z) falls exactly on a projected edge or vertex, the rasteriser's
top-left rule decides: with every projected triangle taken counter-clockwise, an edge counts
as covered when its direction ``(dy, dz)`` has ``dz < 0``, or ``dz == 0`` and ``dy > 0``. Two
triangles that share an edge and face the same way along X traverse it in opposite directions,
so exactly one of them covers it: a ray through an edge crosses once, never twice or not at all.
At a silhouette edge (the surface turns back along X) the two traverse it the same way: both or
neither count, and the parity is that of a ray grazing the surface, unchanged. The edge
functions are evaluated with the edge's endpoints in vertex-id order, so a shared edge gives
the two triangles exactly opposite values, whatever the rounding. Triangles parallel to X
(zero projected area) are skipped: a ray only grazes them.

This is what :mod:`faceforge.animation.checks` checks and what
:class:`faceforge.animation.guards.bone_collision.BoneCollision` pushes out with: the skin's
vertices against each bone, every frame, with no ray-tracing library and no repeated casts
to collect multiple hits. Points exactly on the surface (crossing at their own x) are outside.
"""

from __future__ import annotations

import numba
import numpy as np

from faceforge.constants import FLOAT, INT, NUMBA_OPTIONS
from faceforge.geometry.triangles import check_mesh

__all__ = ["ParityGrid"]


class ParityGrid:
    """The (y, z) grid of a closed mesh's triangles, for :meth:`contains` queries.

    Parameters
    ----------
    vertices : (n, 3) float
    faces : (m, 3) int, a closed (watertight) surface; orientation does not matter
    per_cell : float, about this many triangles' bounding boxes per grid cell on average
    """

    def __init__(self, vertices, faces, per_cell: float = 0.5):
        v, f = check_mesh(vertices, faces)
        self.vertices = np.ascontiguousarray(v, dtype=FLOAT)
        self.faces = np.ascontiguousarray(f, dtype=INT)
        yz = self.vertices[:, 1:]
        if len(f):
            lo = yz[f].min(axis=1)
            hi = yz[f].max(axis=1)
            self.origin = lo.min(axis=0)
            extent = np.maximum(hi.max(axis=0) - self.origin, 1e-300)
        else:
            lo = hi = np.zeros((0, 2))
            self.origin, extent = np.zeros(2), np.ones(2)
        # square-ish cells, about len(f) / per_cell of them
        cells = max(len(f) / per_cell, 1.0)
        size = float(np.sqrt(extent[0] * extent[1] / cells)) or float(extent.max())
        self.shape = np.maximum(np.ceil(extent / size).astype(INT), 1)
        self.size = extent / self.shape
        first = self._cell(lo)
        last = self._cell(hi)
        counts = (last - first + 1).prod(axis=1)
        tri = np.repeat(np.arange(len(f), dtype=INT), counts)
        # every cell of each triangle's box: offsets within the box, row-major
        within = np.arange(counts.sum(), dtype=INT) - np.repeat(np.cumsum(counts) - counts, counts)
        width = np.repeat(last[:, 1] - first[:, 1] + 1, counts)
        cy = np.repeat(first[:, 0], counts) + within // width
        cz = np.repeat(first[:, 1], counts) + within % width
        key = cy * self.shape[1] + cz
        order = np.argsort(key, kind="stable")
        self.cell_tris = np.ascontiguousarray(tri[order])
        self.cell_start = np.searchsorted(key[order], np.arange(self.shape.prod() + 1)).astype(INT)
        # per triangle: orientation of its (y, z) projection (0 = parallel to X) and which
        # of its edges (0: v0->v1, 1: v1->v2, 2: v2->v0, in the counter-clockwise order) are
        # top-left
        self.sign, self.top_left = _orientations(self.vertices, self.faces)

    def _cell(self, yz: np.ndarray) -> np.ndarray:
        c = np.floor((yz - self.origin) / self.size).astype(INT)
        return np.clip(c, 0, self.shape - 1)

    def contains(self, points) -> np.ndarray:
        """(k,) bool: which ``points (k, 3)`` lie inside the mesh (see the module docstring)."""
        p = np.ascontiguousarray(np.asarray(points, dtype=FLOAT).reshape(-1, 3))
        out = np.zeros(len(p), dtype=np.bool_)
        if len(p) and len(self.faces):
            _contains(p, self.vertices, self.faces, self.sign, self.top_left, self.origin, self.size,
                      self.shape, self.cell_start, self.cell_tris, out)
        return out


def _orientations(v: np.ndarray, f: np.ndarray):
    """``sign (m,) int8``: +1 / -1 as the (y, z) projection of each triangle is counter-clockwise
    / clockwise, 0 when it has no area; ``top_left (m, 3) bool`` per edge of the counter-clockwise
    traversal (see the module docstring)."""
    y, z = v[:, 1][f], v[:, 2][f]
    area = (y[:, 1] - y[:, 0]) * (z[:, 2] - z[:, 0]) - (z[:, 1] - z[:, 0]) * (y[:, 2] - y[:, 0])
    sign = np.sign(area).astype(np.int8)
    top_left = np.zeros((len(f), 3), dtype=np.bool_)
    for e in range(3):
        a, b = e, (e + 1) % 3
        s = np.where(sign < 0, -1.0, 1.0)          # a clockwise triangle is walked backwards
        dy = s * (y[:, b] - y[:, a])
        dz = s * (z[:, b] - z[:, a])
        top_left[:, e] = (dz < 0.0) | ((dz == 0.0) & (dy > 0.0))
    return sign, top_left


@numba.njit(inline="always", **NUMBA_OPTIONS)
def _edge(v, a, b, py, pz):  # pragma: no cover - numba
    """Edge function of the directed edge a -> b at (py, pz), evaluated with the endpoints in
    vertex-id order (so b -> a gives exactly the negated value)."""
    lo, hi = (a, b) if a < b else (b, a)
    ya, za = v[lo, 1], v[lo, 2]
    e = (v[hi, 1] - ya) * (pz - za) - (v[hi, 2] - za) * (py - ya)
    return e if a < b else -e


@numba.njit(**NUMBA_OPTIONS)
def _contains(p, v, f, sign, top_left, origin, size, shape, cell_start, cell_tris, out):  # pragma: no cover
    for k in range(p.shape[0]):
        px, py, pz = p[k, 0], p[k, 1], p[k, 2]
        fy = (py - origin[0]) / size[0]
        fz = (pz - origin[1]) / size[1]
        if not (0.0 <= fy <= shape[0]) or not (0.0 <= fz <= shape[1]):
            continue                                       # outside the projection: no crossing
        cy = min(int(fy), shape[0] - 1)
        cz = min(int(fz), shape[1] - 1)
        cell = cy * shape[1] + cz
        ahead = 0
        behind = 0
        for j in range(cell_start[cell], cell_start[cell + 1]):
            t = cell_tris[j]
            s = sign[t]
            if s == 0:
                continue
            i0, i1, i2 = f[t, 0], f[t, 1], f[t, 2]
            # oriented edge functions: e0 on v0->v1 (opposite v2), e1 on v1->v2, e2 on v2->v0
            e0 = s * _edge(v, i0, i1, py, pz)
            if e0 < 0.0 or (e0 == 0.0 and not top_left[t, 0]):
                continue
            e1 = s * _edge(v, i1, i2, py, pz)
            if e1 < 0.0 or (e1 == 0.0 and not top_left[t, 1]):
                continue
            e2 = s * _edge(v, i2, i0, py, pz)
            if e2 < 0.0 or (e2 == 0.0 and not top_left[t, 2]):
                continue
            total = e0 + e1 + e2
            if total <= 0.0:
                continue
            x = (e1 * v[i0, 0] + e2 * v[i1, 0] + e0 * v[i2, 0]) / total
            if x > px:
                ahead += 1
            elif x < px:
                behind += 1
        out[k] = (ahead % 2 == 1) and (behind % 2 == 1)
