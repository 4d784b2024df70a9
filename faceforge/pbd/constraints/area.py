"""Triangle area preservation.

``C(p0, p1, p2) = |(p1 - p0) x (p2 - p0)| / 2 - A0`` (paper §8). With the unit normal
``n``: ``grad_p0 = n x (p2 - p1) / 2``, ``grad_p1 = n x (p0 - p2) / 2``,
``grad_p2 = n x (p1 - p0) / 2`` (they sum to zero: momentum is conserved). The edges lie
in the triangle's plane, normal to ``n``, so ``|grad_i|^2 = |edge opposite i|^2 / 4``: the
kernels compute the denominator ``sum_i w_i |grad_i|^2`` from the edge lengths. A
zero-area triangle has no normal and is skipped.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from faceforge.pbd.constraints._common import BATCH, DEGENERATE, _multiplier, PBD_NUMBA


def init_area(positions: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Rest areas ``(m,) float64`` (squared length units) of ``triangles (m, 3) int``."""
    p = np.asarray(positions, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    n = np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]])
    return 0.5 * np.linalg.norm(n, axis=1)


def residual_area(positions, triangles, rest_area) -> np.ndarray:
    """``C`` per constraint, ``(m,) float64`` in squared length units."""
    return init_area(positions, triangles) - np.asarray(rest_area, dtype=np.float64)


@numba.njit(inline="always", **PBD_NUMBA)
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
    denom = 0.25 * (w0 * (ox * ox + oy * oy + oz * oz) + w1 * (vx * vx + vy * vy + vz * vz)
                    + w2 * (ux * ux + uy * uy + uz * uz))
    if denom <= 0.0:
        return 0.0
    g0x = h * (ny * oz - nz * oy)
    g0y = h * (nz * ox - nx * oz)
    g0z = h * (nx * oy - ny * ox)
    g1x = -h * (ny * vz - nz * vy)
    g1y = -h * (nz * vx - nx * vz)
    g1z = -h * (nx * vy - ny * vx)
    g2x = h * (ny * uz - nz * uy)
    g2y = h * (nz * ux - nx * uz)
    g2z = h * (nx * uy - ny * ux)
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


@numba.njit(**PBD_NUMBA)
def _project_area(x, w, idx, rest, k, c, lam, xpbd, start, stop):
    """Gauss-Seidel sweep over constraints ``start:stop`` in order (``xpbd``: accumulate ``lam``)."""
    if xpbd:
        for j in range(start, stop):
            lam[j] += _solve_area(x, w, idx[j, 0], idx[j, 1], idx[j, 2], rest[j], k[j], c[j],
                                  lam[j], True)
    else:
        for j in range(start, stop):
            _solve_area(x, w, idx[j, 0], idx[j, 1], idx[j, 2], rest[j], k[j], 0.0, 0.0, False)


@numba.njit(inline="always", **PBD_NUMBA)
def _area_increments(p0x, p0y, p0z, p1x, p1y, p1z, p2x, p2y, p2z, w0, w1, w2, rest, k):
    """Branch-free PBD projection of one triangle: the nine position increments
    ``(dp0, dp1, dp2)`` (length units), all 0 when degenerate or immovable.

    The math of :func:`_solve_area` with one division: ``dp_i = s w_i (n x e_i) / (2 |n|)``,
    ``s = -k C / D`` (``e_i`` the edge opposite ``p_i``, ``D`` from the edge lengths).
    Shared by the batched area sweep and the fused quad sweep.
    """
    ux = p1x - p0x
    uy = p1y - p0y
    uz = p1z - p0z
    vx = p2x - p0x
    vy = p2y - p0y
    vz = p2z - p0z
    nx = uy * vz - uz * vy
    ny = uz * vx - ux * vz
    nz = ux * vy - uy * vx
    n2 = nx * nx + ny * ny + nz * nz
    ox = vx - ux
    oy = vy - uy
    oz = vz - uz
    uu = ux * ux + uy * uy + uz * uz
    vv = vx * vx + vy * vy + vz * vz
    scale = uu + vv
    ok = (n2 > DEGENERATE * scale * scale) & (n2 > 0.0)
    nlen = math.sqrt(n2 if ok else 1.0)
    # sum_i w_i |grad_i|^2 from the edge lengths (see the module docstring)
    denom = 0.25 * (w0 * (ox * ox + oy * oy + oz * oz) + w1 * vv + w2 * uu)
    good = ok & (denom > 0.0)
    h = -k * (0.5 * nlen - rest) * 0.5 / (nlen * (denom if good else 1.0))
    h = h if good else 0.0
    f0 = h * w0
    f1 = -h * w1
    f2 = h * w2
    return (f0 * (ny * oz - nz * oy), f0 * (nz * ox - nx * oz), f0 * (nx * oy - ny * ox),
            f1 * (ny * vz - nz * vy), f1 * (nz * vx - nx * vz), f1 * (nx * vy - ny * vx),
            f2 * (ny * uz - nz * uy), f2 * (nz * ux - nx * uz), f2 * (nx * uy - ny * ux))


# offsets of the scratch rows of the batched sweep (see bending._project_bending_batched):
# the gathered positions, then the projected ones
_P0X, _P0Y, _P0Z, _P1X, _P1Y, _P1Z, _P2X, _P2Y, _P2Z = (r * BATCH for r in range(9))
_Q0X, _Q0Y, _Q0Z, _Q1X, _Q1Y, _Q1Z, _Q2X, _Q2Y, _Q2Z = (r * BATCH for r in range(9, 18))


@numba.njit(**PBD_NUMBA)
def _project_area_batched(x, idx, inv_mass, rest, k, runs, buf, start, stop):
    """PBD sweep over ``start:stop`` in vectorised batches of independent constraints.

    inv_mass : (3, m) float, the inverse masses of each triangle's particles (constant for
    a frozen Model, read as vectors by the math loop); rest, k : (m,) float;
    runs : (r,) int sorted boundaries of runs of constraints sharing no particle;
    buf : (BATCH_ROWS * BATCH,) float scratch. Gather the positions, branch-free math of
    ``_solve_area`` giving the projected positions, store them back; equal to the
    sequential sweep in the same order.
    """
    for q in range(runs.shape[0] - 1):
        lo = max(runs[q], start)
        hi = min(runs[q + 1], stop)
        for c0 in range(lo, hi, BATCH):
            n = min(BATCH, hi - c0)
            for t in range(n):  # gather
                j = np.uint64(c0 + t)
                i0 = np.uint64(idx[j, 0])
                i1 = np.uint64(idx[j, 1])
                i2 = np.uint64(idx[j, 2])
                buf[_P0X + t] = x[i0, 0]
                buf[_P0Y + t] = x[i0, 1]
                buf[_P0Z + t] = x[i0, 2]
                buf[_P1X + t] = x[i1, 0]
                buf[_P1Y + t] = x[i1, 1]
                buf[_P1Z + t] = x[i1, 2]
                buf[_P2X + t] = x[i2, 0]
                buf[_P2Y + t] = x[i2, 1]
                buf[_P2Z + t] = x[i2, 2]
            for t in range(n):  # branch-free math
                j = np.uint64(c0 + t)
                p0x = buf[_P0X + t]
                p0y = buf[_P0Y + t]
                p0z = buf[_P0Z + t]
                p1x = buf[_P1X + t]
                p1y = buf[_P1Y + t]
                p1z = buf[_P1Z + t]
                p2x = buf[_P2X + t]
                p2y = buf[_P2Y + t]
                p2z = buf[_P2Z + t]
                d0x, d0y, d0z, d1x, d1y, d1z, d2x, d2y, d2z = _area_increments(
                    p0x, p0y, p0z, p1x, p1y, p1z, p2x, p2y, p2z,
                    inv_mass[0, j], inv_mass[1, j], inv_mass[2, j], rest[j], k[j])
                buf[_Q0X + t] = p0x + d0x
                buf[_Q0Y + t] = p0y + d0y
                buf[_Q0Z + t] = p0z + d0z
                buf[_Q1X + t] = p1x + d1x
                buf[_Q1Y + t] = p1y + d1y
                buf[_Q1Z + t] = p1z + d1z
                buf[_Q2X + t] = p2x + d2x
                buf[_Q2Y + t] = p2y + d2y
                buf[_Q2Z + t] = p2z + d2z
            for t in range(n):  # scatter
                j = np.uint64(c0 + t)
                i0 = np.uint64(idx[j, 0])
                i1 = np.uint64(idx[j, 1])
                i2 = np.uint64(idx[j, 2])
                x[i0, 0] = buf[_Q0X + t]
                x[i0, 1] = buf[_Q0Y + t]
                x[i0, 2] = buf[_Q0Z + t]
                x[i1, 0] = buf[_Q1X + t]
                x[i1, 1] = buf[_Q1Y + t]
                x[i1, 2] = buf[_Q1Z + t]
                x[i2, 0] = buf[_Q2X + t]
                x[i2, 1] = buf[_Q2Y + t]
                x[i2, 2] = buf[_Q2Z + t]


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
