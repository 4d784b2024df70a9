"""One-sided point-vs-triangle contact: points that may touch a sheet of triangles, not cross it.

Each contact point ``x`` has a list of candidate triangles ``(a, b, c)`` (vertex order gives the
normal ``n = (b - a) x (c - a) / |...|``, its *front*). Every call, among the candidates whose
plane holds ``x``'s projection inside the triangle (barycentric coordinates all >= ``-margin``),
the one nearest along its normal is the point's *sheet*; when ``x`` is behind it,
``d = n . (x - a) < floor`` (``floor <= 0`` per point: 0, or the depth the point already had at
rest), and not deeper than ``reach`` (a point far behind is on another fold of the sheet, not
through it), the constraint ``C = d - floor >= 0`` is projected at stiffness 1 as a PBD contact:
with the projection's barycentric coordinates ``(u, v, t)`` and inverse masses ``w``,
``s = -C / (w_x + u^2 w_a + v^2 w_b + t^2 w_c)``; ``x`` moves by ``w_x s n``, each triangle
vertex by ``-u w_a s n`` (and so on): the point and the sheet meet half way (equal masses), the
momentum is kept.

It is applied after a solver step (as :mod:`faceforge.pbd.dihedral_limit`), Gauss-Seidel over
the points, ``sweeps`` times (a sweep that moves nothing ends them). No velocities are touched.

*With the step's history* (the positions ``prev`` at the step's start given): a point that was
already behind its sheet (in ``prev``) by more than ``lost`` past its floor did not cross in this
step (it jumped further than a step's contact can sort out, or something after the contact put it
there) and is left where it is until it comes back out; and when the sheet jumped onto the point
(``a_s = max(0, n . (s - s_prev)) > lost``, ``s`` the projection, the barycentric mean of the
sheet's vertices, ``n`` its normal) the point is pushed out only by its share of the approach,
``a_x / (a_x + a_s)`` of the crossing with ``a_x = max(0, -n . (x - x_prev))`` (a press, the sheet
coming on less than ``lost`` in a step, is pushed out whole). Two sheets whose vertices are each
other's points (the two lips) then stop the one that jumped through the other instead of dragging
the one that stood still. Each sweep applies the rule anew (the test's twin uses one sweep).
The numba kernel has a plain-numpy twin in ``tests/pbd/test_triangle_contact.py``. Knows nothing
of faces: the caller chooses the points and their candidates
(:func:`faceforge.skin.lip_contact.lip_contacts`).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from faceforge.constants import NUMBA_OPTIONS
from faceforge.pbd.model import checked_positions, inverse_masses

__all__ = ["TriangleContact", "signed_depths"]


@numba.njit(**NUMBA_OPTIONS)
def _sheet(p, x, cand, tris, margin):  # pragma: no cover - numba
    """(row of ``tris`` or -1, d, u, v, t): the candidate triangle whose projection of ``p[x]``
    is inside (barycentrics >= -margin) and nearest along its normal; d the signed distance."""
    best, bd, bu, bv, bt = -1, 0.0, 0.0, 0.0, 0.0
    for k in range(cand.shape[0]):
        j = cand[k]
        a, b, c = tris[j, 0], tris[j, 1], tris[j, 2]
        e1x, e1y, e1z = p[b, 0] - p[a, 0], p[b, 1] - p[a, 1], p[b, 2] - p[a, 2]
        e2x, e2y, e2z = p[c, 0] - p[a, 0], p[c, 1] - p[a, 1], p[c, 2] - p[a, 2]
        nx, ny, nz = e1y * e2z - e1z * e2y, e1z * e2x - e1x * e2z, e1x * e2y - e1y * e2x
        nn = nx * nx + ny * ny + nz * nz
        if nn <= 0.0:
            continue
        rx, ry, rz = p[x, 0] - p[a, 0], p[x, 1] - p[a, 1], p[x, 2] - p[a, 2]
        # barycentrics of the projection: v = ((e1 x r) . n) ... via cross products with n
        qx, qy, qz = ry * e2z - rz * e2y, rz * e2x - rx * e2z, rx * e2y - ry * e2x
        v = (qx * nx + qy * ny + qz * nz) / nn
        qx, qy, qz = e1y * rz - e1z * ry, e1z * rx - e1x * rz, e1x * ry - e1y * rx
        t = (qx * nx + qy * ny + qz * nz) / nn
        u = 1.0 - v - t
        if u < -margin or v < -margin or t < -margin:
            continue
        d = (rx * nx + ry * ny + rz * nz) / math.sqrt(nn)
        if best < 0 or abs(d) < abs(bd):
            best, bd, bu, bv, bt = j, d, u, v, t
    return best, bd, bu, bv, bt


@numba.njit(**NUMBA_OPTIONS)
def _contact(p, points, start, cand, tris, floor, reach, margin, w, sweeps, touched, sheet,
             prev, lost):  # pragma: no cover - numba
    """In place on ``p (n, 3)``: ``points (m,)`` particle ids, their candidates
    ``cand[start[i]:start[i + 1]]`` (rows of ``tris (f, 3)``), ``floor (m,)`` <= 0, ``reach`` > 0,
    ``margin`` >= 0, ``w (n,)`` inverse masses, ``touched (n,)`` bool or ``(0,)``, ``sheet`` in [0, 1]
    (the triangles' inverse masses are scaled by it: 0 pins the sheet); ``prev (n, 3)`` the positions
    at the step's start or ``(0, 3)`` (no history), ``lost`` >= 0 (module docstring). Returns the
    projections made."""
    mark = touched.shape[0] > 0
    history = prev.shape[0] > 0
    moved = 0
    for _ in range(sweeps):
        before = moved
        for i in range(points.shape[0]):
            x = points[i]
            j, d, u, v, t = _sheet(p, x, cand[start[i]:start[i + 1]], tris, margin)
            if j < 0 or d >= floor[i] or d < floor[i] - reach:
                continue
            if history:
                # behind its sheet already at the step's start: it did not cross in this step (a jump,
                # or a guard put it there); pushed now it would be torn from its neighbours
                jp, dp, _u, _v, _t = _sheet(prev, x, cand[start[i]:start[i + 1]], tris, margin)
                if jp >= 0 and dp < floor[i] - lost:
                    continue
            # clamp the barycentrics into the triangle for the weights (the margin lets them stray)
            u, v, t = max(u, 0.0), max(v, 0.0), max(t, 0.0)
            s = u + v + t
            u, v, t = u / s, v / s, t / s
            a, b, c = tris[j, 0], tris[j, 1], tris[j, 2]
            wa, wb, wc = sheet * w[a], sheet * w[b], sheet * w[c]
            den = w[x] + u * u * wa + v * v * wb + t * t * wc
            if den <= 0.0:
                continue
            e1x, e1y, e1z = p[b, 0] - p[a, 0], p[b, 1] - p[a, 1], p[b, 2] - p[a, 2]
            e2x, e2y, e2z = p[c, 0] - p[a, 0], p[c, 1] - p[a, 1], p[c, 2] - p[a, 2]
            nx, ny, nz = e1y * e2z - e1z * e2y, e1z * e2x - e1x * e2z, e1x * e2y - e1y * e2x
            nl = math.sqrt(nx * nx + ny * ny + nz * nz)
            nx, ny, nz = nx / nl, ny / nl, nz / nl
            share = 1.0
            if history:
                # the crossing is the point's in proportion to how far it moved onto the sheet, against
                # how far the sheet moved onto it (a lip springing back through the other one is
                # stopped by the other lip's points against its faces, not the other lip dragged)
                ap = -((p[x, 0] - prev[x, 0]) * nx + (p[x, 1] - prev[x, 1]) * ny + (p[x, 2] - prev[x, 2]) * nz)
                sm = 0.0
                for k, f in ((a, u), (b, v), (c, t)):
                    sm += f * ((p[k, 0] - prev[k, 0]) * nx + (p[k, 1] - prev[k, 1]) * ny + (p[k, 2] - prev[k, 2]) * nz)
                ap, sm = max(ap, 0.0), max(sm, 0.0)
                if sm > lost:   # a press (the sheet coming on a little a step) is pushed out whole
                    share = ap / (ap + sm)
                if share <= 0.0:
                    continue
            lam = share * (floor[i] - d) / den
            for k, f in ((x, w[x]), (a, -u * wa), (b, -v * wb), (c, -t * wc)):
                if f != 0.0:
                    p[k, 0] += f * lam * nx
                    p[k, 1] += f * lam * ny
                    p[k, 2] += f * lam * nz
                    if mark:
                        touched[k] = True
            moved += 1
        if moved == before:
            break
    return moved


class TriangleContact:
    """The contact of fixed points against their candidate triangles (module docstring), checked
    once and applied as often as needed.

    points : (m,) int particle ids; candidates : list of m int arrays (rows of ``tris``), or a CSR
    pair ``(start (m + 1,), cand (k,))``; tris : (f, 3) int particle ids (their order gives the
    front); n : the number of particles; floor : (m,) <= 0 or a scalar (0: the point may touch,
    not cross); reach : how deep behind its sheet a point is still pushed out (> 0, positions'
    units); margin : barycentric slack of "inside" (>= 0); inv_mass : (n,) >= 0 or None (all 1).
    """

    def __init__(self, points, candidates, tris, n: int, floor=0.0, reach: float = 1.0,
                 margin: float = 0.0, inv_mass=None, sheet: float = 1.0):
        self.points = np.ascontiguousarray(points, dtype=np.int64).reshape(-1)
        if isinstance(candidates, tuple):
            start, cand = candidates
        else:
            lens = [len(c) for c in candidates]
            start = np.r_[0, np.cumsum(lens)]
            cand = np.concatenate([np.asarray(c, np.int64) for c in candidates]) if candidates else np.zeros(0)
        self.start = np.ascontiguousarray(start, dtype=np.int64)
        self.cand = np.ascontiguousarray(cand, dtype=np.int64)
        self.tris = np.ascontiguousarray(tris, dtype=np.int64).reshape(-1, 3)
        m = len(self.points)
        if self.start.shape != (m + 1,) or self.start[0] != 0 or self.start[-1] != len(self.cand):
            raise ValueError("candidates must give one list per point")
        if len(self.cand) and (self.cand.min() < 0 or self.cand.max() >= len(self.tris)):
            raise ValueError("candidates index triangles outside tris")
        for ids in (self.points, self.tris):
            if ids.size and (ids.min() < 0 or ids.max() >= n):
                raise ValueError(f"points and tris must index particles in [0, {n})")
        self.floor = np.ascontiguousarray(np.broadcast_to(np.asarray(floor, np.float64), (m,)))
        if np.any(self.floor > 0):
            raise ValueError("floor must be <= 0")
        if not (reach > 0 and margin >= 0):
            raise ValueError(f"reach must be > 0 and margin >= 0, got {reach}, {margin}")
        if not 0.0 <= sheet <= 1.0:
            raise ValueError(f"sheet must be in [0, 1], got {sheet}")
        self.n, self.reach, self.margin, self.sheet = int(n), float(reach), float(margin), float(sheet)
        self.inv_mass = inverse_masses(inv_mass, self.n)

    def __call__(self, positions: np.ndarray, sweeps: int = 2, touched: np.ndarray | None = None,
                 previous: np.ndarray | None = None, lost: float = 0.0) -> int:
        """Push every point that is behind its sheet back to its floor, in place on ``positions``
        ((n, 3) float64, C-contiguous), in at most ``sweeps`` Gauss-Seidel passes; ``touched`` (n,)
        bool, optional, set True where a particle moved. ``previous`` ((n, 3) float64, optional):
        the positions at the step's start; then a point already more than ``lost`` (>= 0, positions'
        units) behind its floor there is left, and a crossing is pushed out in proportion to the
        point's share of the approach (module docstring). Returns the projections made."""
        touched = checked_positions(positions, touched, self.n)
        if not len(self.points):
            return 0
        if previous is None:
            previous = np.zeros((0, 3))
        elif previous.dtype != np.float64 or previous.shape != (self.n, 3) or not previous.flags.c_contiguous:
            raise ValueError(f"previous must be a C-contiguous ({self.n}, 3) float64 array")
        if not lost >= 0:
            raise ValueError(f"lost must be >= 0, got {lost}")
        return int(_contact(positions, self.points, self.start, self.cand, self.tris, self.floor,
                            self.reach, self.margin, self.inv_mass, int(sweeps), touched, self.sheet,
                            previous, float(lost)))

    def depths(self, positions: np.ndarray) -> np.ndarray:
        """(m,) each point's signed distance to its sheet in ``positions`` (nan: no sheet)."""
        return signed_depths(positions, self.points, self.start, self.cand, self.tris, self.margin)


def signed_depths(positions, points, start, cand, tris, margin: float = 0.0) -> np.ndarray:
    """(m,) signed distance of each point to its sheet (module docstring) in ``positions (n, 3)``,
    nan where no candidate holds its projection."""
    p = np.ascontiguousarray(positions, dtype=np.float64)
    out = np.full(len(points), np.nan)
    for i, x in enumerate(np.asarray(points, np.int64)):
        j, d, _, _, _ = _sheet(p, x, np.ascontiguousarray(cand[start[i]:start[i + 1]], np.int64),
                               np.ascontiguousarray(tris, np.int64), float(margin))
        if j >= 0:
            out[i] = d
    return out
