"""Triangle area preservation.

``C(p0, p1, p2) = |(p1 - p0) x (p2 - p0)| / 2 - A0`` (paper §8). With the unit normal
``n``: ``grad_p0 = n x (p2 - p1) / 2``, ``grad_p1 = n x (p0 - p2) / 2``,
``grad_p2 = n x (p1 - p0) / 2`` (they sum to zero: momentum is conserved). A
zero-area triangle has no normal and is skipped.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from faceforge.constants import NUMBA_OPTIONS
from faceforge.pbd.constraints._common import DEGENERATE, _multiplier


def init_area(positions: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Rest areas ``(m,) float64`` (squared length units) of ``triangles (m, 3) int``."""
    p = np.asarray(positions, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    n = np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]])
    return 0.5 * np.linalg.norm(n, axis=1)


def residual_area(positions, triangles, rest_area) -> np.ndarray:
    """``C`` per constraint, ``(m,) float64`` in squared length units."""
    return init_area(positions, triangles) - np.asarray(rest_area, dtype=np.float64)


@numba.njit(inline="always", **NUMBA_OPTIONS)
def _solve_area(x, w, i0, i1, i2, rest, k, c, lam, xpbd):
    """Project one area constraint in place on ``x (n, 3)``; return the multiplier increment."""
    w0 = w[i0]
    w1 = w[i1]
    w2 = w[i2]
    if w0 + w1 + w2 == 0.0:
        return 0.0
    ux = x[i1, 0] - x[i0, 0]
    uy = x[i1, 1] - x[i0, 1]
    uz = x[i1, 2] - x[i0, 2]
    vx = x[i2, 0] - x[i0, 0]
    vy = x[i2, 1] - x[i0, 1]
    vz = x[i2, 2] - x[i0, 2]
    nx = uy * vz - uz * vy
    ny = uz * vx - ux * vz
    nz = ux * vy - uy * vx
    n2 = nx * nx + ny * ny + nz * nz
    scale = ux * ux + uy * uy + uz * uz + vx * vx + vy * vy + vz * vz
    if n2 <= DEGENERATE * scale * scale or n2 == 0.0:
        return 0.0
    nlen = math.sqrt(n2)
    h = 0.5 / nlen  # gradients are (n / |n|) x edge / 2
    # edges opposite each vertex: p2 - p1 = v - u, p0 - p2 = -v, p1 - p0 = u
    ox = vx - ux
    oy = vy - uy
    oz = vz - uz
    g0x = h * (ny * oz - nz * oy)
    g0y = h * (nz * ox - nx * oz)
    g0z = h * (nx * oy - ny * ox)
    g1x = -h * (ny * vz - nz * vy)
    g1y = -h * (nz * vx - nx * vz)
    g1z = -h * (nx * vy - ny * vx)
    g2x = h * (ny * uz - nz * uy)
    g2y = h * (nz * ux - nx * uz)
    g2z = h * (nx * uy - ny * ux)
    denom = (w0 * (g0x * g0x + g0y * g0y + g0z * g0z)
             + w1 * (g1x * g1x + g1y * g1y + g1z * g1z)
             + w2 * (g2x * g2x + g2y * g2y + g2z * g2z))
    if denom <= 0.0:
        return 0.0
    s = _multiplier(0.5 * nlen - rest, denom, k, c, lam, xpbd)
    f = s * w0
    x[i0, 0] += f * g0x
    x[i0, 1] += f * g0y
    x[i0, 2] += f * g0z
    f = s * w1
    x[i1, 0] += f * g1x
    x[i1, 1] += f * g1y
    x[i1, 2] += f * g1z
    f = s * w2
    x[i2, 0] += f * g2x
    x[i2, 1] += f * g2y
    x[i2, 2] += f * g2z
    return s


@numba.njit(**NUMBA_OPTIONS)
def _project_area(x, w, idx, rest, k, c, lam, xpbd, start, stop):
    """Gauss-Seidel sweep over constraints ``start:stop`` in order (``xpbd``: accumulate ``lam``)."""
    if xpbd:
        for j in range(start, stop):
            lam[j] += _solve_area(x, w, idx[j, 0], idx[j, 1], idx[j, 2], rest[j], k[j], c[j],
                                  lam[j], True)
    else:
        for j in range(start, stop):
            _solve_area(x, w, idx[j, 0], idx[j, 1], idx[j, 2], rest[j], k[j], 0.0, 0.0, False)


def solve_area(positions, inv_mass, triangles, rest_area, stiffness) -> np.ndarray:
    """One PBD Gauss-Seidel sweep over all area constraints; returns new ``(n, 3)`` positions."""
    x = np.array(positions, dtype=np.float64, order="C")
    idx = np.ascontiguousarray(triangles, dtype=np.int64).reshape(-1, 3)
    m = len(idx)
    k = np.broadcast_to(np.asarray(stiffness, dtype=np.float64), (m,)).copy()
    _project_area(x, np.ascontiguousarray(inv_mass, dtype=np.float64), idx,
                  np.ascontiguousarray(rest_area, dtype=np.float64), k,
                  np.zeros(m), np.zeros(m), False, 0, m)
    return x
