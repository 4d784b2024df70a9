"""Dihedral bending constraint between two triangles sharing an edge.

A quad ``(p0, p1, p2, p3)``: ``(p0, p1)`` is the shared edge, ``p2`` the opposite vertex
of triangle A = ``(p0, p1, p2)`` and ``p3`` that of triangle B = ``(p1, p0, p3)`` (so
A and B are consistently oriented when the surface is). With the area-weighted
normals ``nA = (p1 - p0) x (p2 - p0)``, ``nB = (p0 - p1) x (p3 - p1)`` and
``e = p1 - p0`` the signed dihedral angle is

    theta = atan2((nA x nB) . e / |e|, nA . nB)            (0 when flat, in (-pi, pi])

and ``C = wrap(theta - theta0)`` (Müller et al. 2007, appendix A, here with a signed
angle so that flat and folded configurations stay well defined). With
``a = nA / |nA|^2`` and ``b = nB / |nB|^2`` (Bridson et al. 2003):

    grad_p2 = -|e| a                  grad_p3 = -|e| b
    grad_p0 = -(p2 - p1).e/|e| a - (p3 - p1).e/|e| b
    grad_p1 =  (p2 - p0).e/|e| a + (p3 - p0).e/|e| b

which sum to zero (momentum is conserved). Degenerate triangles or a zero-length edge
skip the projection.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from faceforge.constants import NUMBA_OPTIONS
from faceforge.pbd.constraints._common import DEGENERATE, _multiplier


def dihedral_angle(positions: np.ndarray, quads: np.ndarray) -> np.ndarray:
    """Signed dihedral angles ``(m,) float64`` in radians of ``quads (m, 4)`` (0 = flat)."""
    p = np.asarray(positions, dtype=np.float64)
    q = np.asarray(quads, dtype=np.int64).reshape(-1, 4)
    p0, p1, p2, p3 = (p[q[:, i]] for i in range(4))
    e = p1 - p0
    na = np.cross(e, p2 - p0)
    nb = np.cross(p0 - p1, p3 - p1)
    elen = np.linalg.norm(e, axis=1)
    sin = np.einsum("ij,ij->i", np.cross(na, nb), e) / np.where(elen > 0, elen, 1.0)
    return np.arctan2(sin, np.einsum("ij,ij->i", na, nb))


def init_bending(positions: np.ndarray, quads: np.ndarray) -> np.ndarray:
    """Rest dihedral angles ``(m,) float64`` (radians) of ``quads (m, 4) int``."""
    return dihedral_angle(positions, quads)


def _wrap(a):
    return (a + np.pi) % (2.0 * np.pi) - np.pi


def residual_bending(positions, quads, rest_angle) -> np.ndarray:
    """``C`` per constraint, ``(m,) float64`` in radians, wrapped to [-pi, pi)."""
    return _wrap(dihedral_angle(positions, quads) - np.asarray(rest_angle, dtype=np.float64))


@numba.njit(inline="always", **NUMBA_OPTIONS)
def _solve_bending(x, w, i0, i1, i2, i3, rest, k, c, lam, xpbd):
    """Project one dihedral constraint in place on ``x (n, 3)``; return the multiplier increment."""
    w0 = w[i0]
    w1 = w[i1]
    w2 = w[i2]
    w3 = w[i3]
    if w0 + w1 + w2 + w3 == 0.0:
        return 0.0
    ex = x[i1, 0] - x[i0, 0]
    ey = x[i1, 1] - x[i0, 1]
    ez = x[i1, 2] - x[i0, 2]
    e2 = ex * ex + ey * ey + ez * ez
    if e2 == 0.0:
        return 0.0
    # triangle A (p0, p1, p2): nA = e x (p2 - p0)
    ux = x[i2, 0] - x[i0, 0]
    uy = x[i2, 1] - x[i0, 1]
    uz = x[i2, 2] - x[i0, 2]
    ax = ey * uz - ez * uy
    ay = ez * ux - ex * uz
    az = ex * uy - ey * ux
    # triangle B (p1, p0, p3): nB = (p0 - p1) x (p3 - p1) = (p3 - p1) x e
    vx = x[i3, 0] - x[i1, 0]
    vy = x[i3, 1] - x[i1, 1]
    vz = x[i3, 2] - x[i1, 2]
    bx = vy * ez - vz * ey
    by = vz * ex - vx * ez
    bz = vx * ey - vy * ex
    na2 = ax * ax + ay * ay + az * az
    nb2 = bx * bx + by * by + bz * bz
    tiny = DEGENERATE * e2 * e2
    if na2 <= tiny or nb2 <= tiny:
        return 0.0  # a zero-area triangle has no normal
    elen = math.sqrt(e2)
    # signed angle
    cx = ay * bz - az * by
    cy = az * bx - ax * bz
    cz = ax * by - ay * bx
    sin = (cx * ex + cy * ey + cz * ez) / elen
    cos = ax * bx + ay * by + az * bz
    value = math.atan2(sin, cos) - rest
    if value > math.pi:
        value -= 2.0 * math.pi
    elif value < -math.pi:
        value += 2.0 * math.pi
    # gradient coefficients along a = nA/|nA|^2 and b = nB/|nB|^2
    ia = 1.0 / na2
    ib = 1.0 / nb2
    ie = 1.0 / elen
    # (p2 - p1).e = (p2 - p0).e - e.e ; (p3 - p0).e = (p3 - p1).e + e.e
    ue = (ux * ex + uy * ey + uz * ez) * ie
    ve = (vx * ex + vy * ey + vz * ez) * ie
    a2 = -elen * ia
    b3 = -elen * ib
    a0 = -(ue - elen) * ia
    b0 = -ve * ib
    a1 = ue * ia
    b1 = (ve + elen) * ib
    na_ = ax * ax + ay * ay + az * az
    nb_ = bx * bx + by * by + bz * bz
    ab = ax * bx + ay * by + az * bz
    # |a0 nA + b0 nB|^2 = a0^2 |nA|^2 + 2 a0 b0 nA.nB + b0^2 |nB|^2
    denom = (w0 * (a0 * a0 * na_ + 2.0 * a0 * b0 * ab + b0 * b0 * nb_)
             + w1 * (a1 * a1 * na_ + 2.0 * a1 * b1 * ab + b1 * b1 * nb_)
             + w2 * a2 * a2 * na_ + w3 * b3 * b3 * nb_)
    if denom <= 0.0:
        return 0.0
    s = _multiplier(value, denom, k, c, lam, xpbd)
    f = s * w0
    x[i0, 0] += f * (a0 * ax + b0 * bx)
    x[i0, 1] += f * (a0 * ay + b0 * by)
    x[i0, 2] += f * (a0 * az + b0 * bz)
    f = s * w1
    x[i1, 0] += f * (a1 * ax + b1 * bx)
    x[i1, 1] += f * (a1 * ay + b1 * by)
    x[i1, 2] += f * (a1 * az + b1 * bz)
    f = s * w2 * a2
    x[i2, 0] += f * ax
    x[i2, 1] += f * ay
    x[i2, 2] += f * az
    f = s * w3 * b3
    x[i3, 0] += f * bx
    x[i3, 1] += f * by
    x[i3, 2] += f * bz
    return s


@numba.njit(**NUMBA_OPTIONS)
def _project_bending(x, w, idx, rest, k, c, lam, xpbd, start, stop):
    """Gauss-Seidel sweep over constraints ``start:stop`` in order (``xpbd``: accumulate ``lam``)."""
    if xpbd:
        for j in range(start, stop):
            lam[j] += _solve_bending(x, w, idx[j, 0], idx[j, 1], idx[j, 2], idx[j, 3],
                                     rest[j], k[j], c[j], lam[j], True)
    else:
        for j in range(start, stop):
            _solve_bending(x, w, idx[j, 0], idx[j, 1], idx[j, 2], idx[j, 3],
                           rest[j], k[j], 0.0, 0.0, False)


def solve_bending(positions, inv_mass, quads, rest_angle, stiffness) -> np.ndarray:
    """One PBD Gauss-Seidel sweep over all bending constraints; returns new ``(n, 3)`` positions."""
    x = np.array(positions, dtype=np.float64, order="C")
    idx = np.ascontiguousarray(quads, dtype=np.int64).reshape(-1, 4)
    m = len(idx)
    k = np.broadcast_to(np.asarray(stiffness, dtype=np.float64), (m,)).copy()
    _project_bending(x, np.ascontiguousarray(inv_mass, dtype=np.float64), idx,
                     np.ascontiguousarray(rest_angle, dtype=np.float64), k,
                     np.zeros(m), np.zeros(m), False, 0, m)
    return x
