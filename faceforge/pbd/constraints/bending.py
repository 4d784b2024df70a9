"""Dihedral bending constraint between two triangles sharing an edge.

A quad ``(p0, p1, p2, p3)``: ``(p0, p1)`` is the shared edge, ``p2`` the opposite vertex
of triangle A = ``(p0, p1, p2)`` and ``p3`` that of triangle B = ``(p1, p0, p3)`` (so
A and B are consistently oriented when the surface is). With the area-weighted
normals ``nA = (p1 - p0) x (p2 - p0)``, ``nB = (p0 - p1) x (p3 - p1)`` and
``e = p1 - p0`` the signed dihedral angle is

    theta = atan2((nA x nB) . e / |e|, nA . nB)            (0 when flat, in (-pi, pi])

and ``C = wrap(theta - theta0)`` (Müller et al. 2007, appendix A, here with a signed
angle so that flat and folded configurations stay well defined). The kernel
evaluates ``C`` as ``atan2`` of the rotated pair (sin, cos) (see ``_deviation``). With
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
from faceforge.pbd.constraints._common import BATCH, BATCH_ROWS, DEGENERATE, _multiplier  # noqa: F401


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


#: below this |tan(theta - theta0)| the deviation uses a rational approximation of atan
SMALL_TAN = 0.25


@numba.njit(inline="always", **NUMBA_OPTIONS)
def _deviation(y, x):
    """``atan2(y, x)`` for the angle deviation: libm for large angles, and for
    ``x > 0, |y| <= SMALL_TAN x`` (within 14 degrees) the [5/4] Padé approximant of atan,
    ``z (945 + 735 z^2 + 64 z^4) / (945 + 1050 z^2 + 225 z^4)`` with ``z = y / x``
    (relative error < 1.3e-9 there). Odd, monotone and exact at 0, so the constraint's
    solution (deviation 0) is unchanged; only the step length differs by < 1.3e-9
    relative. It saves the ~30 ns of a libm atan2 in the common case."""
    if x > 0.0 and abs(y) <= SMALL_TAN * x:
        z = y / x
        z2 = z * z
        return z * (945.0 + z2 * (735.0 + 64.0 * z2)) / (945.0 + z2 * (1050.0 + 225.0 * z2))
    return math.atan2(y, x)


@numba.njit(inline="always", **NUMBA_OPTIONS)
def _solve_bending(x, w, i0, i1, i2, i3, rest_cos, rest_sin, k, c, lam, xpbd):
    """Project one dihedral constraint in place on ``x (n, 3)``; return the multiplier increment.

    The rest angle enters as its cosine and sine: the deviation is
    ``atan2(sin(theta - theta0), cos(theta - theta0))``, so no wrapping is needed.
    """
    w0 = w[i0]
    w1 = w[i1]
    w2 = w[i2]
    w3 = w[i3]
    if w0 + w1 + w2 + w3 == 0.0:
        return 0.0
    p0x = x[i0, 0]
    p0y = x[i0, 1]
    p0z = x[i0, 2]
    p1x = x[i1, 0]
    p1y = x[i1, 1]
    p1z = x[i1, 2]
    ex = p1x - p0x
    ey = p1y - p0y
    ez = p1z - p0z
    ux = x[i2, 0] - p0x  # p2 - p0
    uy = x[i2, 1] - p0y
    uz = x[i2, 2] - p0z
    vx = x[i3, 0] - p1x  # p3 - p1
    vy = x[i3, 1] - p1y
    vz = x[i3, 2] - p1z
    ax = ey * uz - ez * uy  # nA = e x u
    ay = ez * ux - ex * uz
    az = ex * uy - ey * ux
    bx = vy * ez - vz * ey  # nB = v x e
    by = vz * ex - vx * ez
    bz = vx * ey - vy * ex
    ee = ex * ex + ey * ey + ez * ez
    na2 = ax * ax + ay * ay + az * az
    nb2 = bx * bx + by * by + bz * bz
    if not (na2 > DEGENERATE * ee * ee and nb2 > DEGENERATE * ee * ee):
        return 0.0  # zero-length edge or zero-area triangle: no normal
    elen = math.sqrt(ee)
    # sin-part (nA x nB) . e / |e| = -det(e, u, v) |e| with det(e, u, v) = u . (v x e) = u . nB;
    # cos-part nA . nB
    sin = -(ux * bx + uy * by + uz * bz) * elen
    cos = ax * bx + ay * by + az * bz
    value = _deviation(sin * rest_cos - cos * rest_sin, cos * rest_cos + sin * rest_sin)
    prod = na2 * nb2
    inv = 1.0 / (prod * elen)
    ia = nb2 * elen * inv  # 1 / |nA|^2
    ib = na2 * elen * inv  # 1 / |nB|^2
    ie = prod * inv        # 1 / |e|
    ue = (ux * ex + uy * ey + uz * ez) * ie
    ve = (vx * ex + vy * ey + vz * ez) * ie
    # grad_p0 = a0 nA/|nA|^2 + b0 nB/|nB|^2, grad_p1 likewise, grad_p2 = -|e| nA/|nA|^2, ...
    a0 = elen - ue
    b0 = -ve
    a1 = ue
    b1 = ve + elen
    cab = 2.0 * cos * ia * ib
    denom = (w0 * (a0 * a0 * ia + a0 * b0 * cab + b0 * b0 * ib)
             + w1 * (a1 * a1 * ia + a1 * b1 * cab + b1 * b1 * ib)
             + (w2 * ia + w3 * ib) * ee)
    if not denom > 0.0:
        return 0.0
    s = _multiplier(value, denom, k, c, lam, xpbd)
    f = s * w0
    fa = f * a0 * ia
    fb = f * b0 * ib
    x[i0, 0] = p0x + fa * ax + fb * bx
    x[i0, 1] = p0y + fa * ay + fb * by
    x[i0, 2] = p0z + fa * az + fb * bz
    f = s * w1
    fa = f * a1 * ia
    fb = f * b1 * ib
    x[i1, 0] = p1x + fa * ax + fb * bx
    x[i1, 1] = p1y + fa * ay + fb * by
    x[i1, 2] = p1z + fa * az + fb * bz
    f = -s * w2 * elen * ia
    x[i2, 0] += f * ax
    x[i2, 1] += f * ay
    x[i2, 2] += f * az
    f = -s * w3 * elen * ib
    x[i3, 0] += f * bx
    x[i3, 1] += f * by
    x[i3, 2] += f * bz
    return s


@numba.njit(**NUMBA_OPTIONS)
def _project_bending(x, w, idx, rest_cs, k, c, lam, xpbd, start, stop):
    """Gauss-Seidel sweep over constraints ``start:stop`` in order (``xpbd``: accumulate ``lam``).

    rest_cs : (m, 2) float, cosine and sine of the rest angles.
    """
    if xpbd:
        for j in range(start, stop):
            lam[j] += _solve_bending(x, w, idx[j, 0], idx[j, 1], idx[j, 2], idx[j, 3],
                                     rest_cs[j, 0], rest_cs[j, 1], k[j], c[j], lam[j], True)
    else:
        for j in range(start, stop):
            _solve_bending(x, w, idx[j, 0], idx[j, 1], idx[j, 2], idx[j, 3],
                           rest_cs[j, 0], rest_cs[j, 1], k[j], 0.0, 0.0, False)


# offsets of the scratch rows in the flat buffer: one flat array with constant row offsets
# lets LLVM prove the rows independent and vectorise the math loop (separate arrays do not)
_E_X = 0 * BATCH
_E_Y = 1 * BATCH
_E_Z = 2 * BATCH
_U_X = 3 * BATCH
_U_Y = 4 * BATCH
_U_Z = 5 * BATCH
_V_X = 6 * BATCH
_V_Y = 7 * BATCH
_V_Z = 8 * BATCH
_W_0 = 9 * BATCH
_W_1 = 10 * BATCH
_W_2 = 11 * BATCH
_W_3 = 12 * BATCH
_R_C = 13 * BATCH
_R_S = 14 * BATCH
_K_J = 15 * BATCH
_A_X = 16 * BATCH
_A_Y = 17 * BATCH
_A_Z = 18 * BATCH
_B_X = 19 * BATCH
_B_Y = 20 * BATCH
_B_Z = 21 * BATCH
_F0A = 22 * BATCH
_F0B = 23 * BATCH
_F1A = 24 * BATCH
_F1B = 25 * BATCH
_F2A = 26 * BATCH
_F3B = 27 * BATCH
_VAL = 28 * BATCH
_DEV_Y = 29 * BATCH
_DEV_X = 30 * BATCH
_GAIN = 31 * BATCH


@numba.njit(**NUMBA_OPTIONS)
def _project_bending_batched(x, w, idx, rest_cs, k, seg, buf, start, stop):
    """PBD sweep over ``start:stop`` whose constraints are grouped in independent runs.

    seg : (s,) int sorted boundaries of runs of constraints sharing no particle (one
    colour of a block); buf : (BATCH_ROWS * BATCH,) float scratch (one row per quantity). Each batch is gathered,
    computed in a branch-free loop that the compiler vectorises (the math of
    ``_solve_bending``, Padé branch), fixed up with libm atan2 where the deviation is
    large, then scattered. Constraints of a batch share no particle, so the result is
    that of the sequential sweep in the same order.
    """
    for q in range(seg.shape[0] - 1):
        lo = max(seg[q], start)
        hi = min(seg[q + 1], stop)
        for c0 in range(lo, hi, BATCH):
            n = min(BATCH, hi - c0)
            for t in range(n):  # gather
                j = c0 + t
                i0 = idx[j, 0]
                i1 = idx[j, 1]
                i2 = idx[j, 2]
                i3 = idx[j, 3]
                buf[_E_X + t] = x[i1, 0] - x[i0, 0]
                buf[_E_Y + t] = x[i1, 1] - x[i0, 1]
                buf[_E_Z + t] = x[i1, 2] - x[i0, 2]
                buf[_U_X + t] = x[i2, 0] - x[i0, 0]
                buf[_U_Y + t] = x[i2, 1] - x[i0, 1]
                buf[_U_Z + t] = x[i2, 2] - x[i0, 2]
                buf[_V_X + t] = x[i3, 0] - x[i1, 0]
                buf[_V_Y + t] = x[i3, 1] - x[i1, 1]
                buf[_V_Z + t] = x[i3, 2] - x[i1, 2]
                buf[_W_0 + t] = w[i0]
                buf[_W_1 + t] = w[i1]
                buf[_W_2 + t] = w[i2]
                buf[_W_3 + t] = w[i3]
                buf[_R_C + t] = rest_cs[j, 0]
                buf[_R_S + t] = rest_cs[j, 1]
                buf[_K_J + t] = k[j]
            for t in range(n):  # branch-free math of _solve_bending
                ex = buf[_E_X + t]
                ey = buf[_E_Y + t]
                ez = buf[_E_Z + t]
                ux = buf[_U_X + t]
                uy = buf[_U_Y + t]
                uz = buf[_U_Z + t]
                vx = buf[_V_X + t]
                vy = buf[_V_Y + t]
                vz = buf[_V_Z + t]
                ax = ey * uz - ez * uy
                ay = ez * ux - ex * uz
                az = ex * uy - ey * ux
                bx = vy * ez - vz * ey
                by = vz * ex - vx * ez
                bz = vx * ey - vy * ex
                ee = ex * ex + ey * ey + ez * ez
                na2 = ax * ax + ay * ay + az * az
                nb2 = bx * bx + by * by + bz * bz
                ok = (na2 > DEGENERATE * ee * ee) & (nb2 > DEGENERATE * ee * ee)
                ee1 = ee if ok else 1.0
                na1 = na2 if ok else 1.0
                nb1 = nb2 if ok else 1.0
                elen = math.sqrt(ee1)
                sin = -(ux * bx + uy * by + uz * bz) * elen
                cos = ax * bx + ay * by + az * bz
                yy = sin * buf[_R_C + t] - cos * buf[_R_S + t]
                xx = cos * buf[_R_C + t] + sin * buf[_R_S + t]
                small = (xx > 0.0) & (abs(yy) <= SMALL_TAN * xx)
                z = yy / (xx if small else 1.0)
                z2 = z * z
                buf[_VAL + t] = z * (945.0 + z2 * (735.0 + 64.0 * z2)) / (945.0 + z2 * (1050.0 + 225.0 * z2))
                buf[_DEV_Y + t] = yy
                buf[_DEV_X + t] = xx
                prod = na1 * nb1
                inv = 1.0 / (prod * elen)
                ia = nb1 * elen * inv
                ib = na1 * elen * inv
                ie = prod * inv
                ue = (ux * ex + uy * ey + uz * ez) * ie
                ve = (vx * ex + vy * ey + vz * ez) * ie
                a0 = elen - ue
                b0 = -ve
                a1 = ue
                b1 = ve + elen
                cab = 2.0 * cos * ia * ib
                denom = (buf[_W_0 + t] * (a0 * a0 * ia + a0 * b0 * cab + b0 * b0 * ib)
                         + buf[_W_1 + t] * (a1 * a1 * ia + a1 * b1 * cab + b1 * b1 * ib)
                         + (buf[_W_2 + t] * ia + buf[_W_3 + t] * ib) * ee1)
                good = ok & (denom > 0.0)
                buf[_GAIN + t] = -buf[_K_J + t] / (denom if good else 1.0) if good else 0.0
                buf[_A_X + t] = ax
                buf[_A_Y + t] = ay
                buf[_A_Z + t] = az
                buf[_B_X + t] = bx
                buf[_B_Y + t] = by
                buf[_B_Z + t] = bz
                buf[_F0A + t] = buf[_W_0 + t] * a0 * ia
                buf[_F0B + t] = buf[_W_0 + t] * b0 * ib
                buf[_F1A + t] = buf[_W_1 + t] * a1 * ia
                buf[_F1B + t] = buf[_W_1 + t] * b1 * ib
                buf[_F2A + t] = -buf[_W_2 + t] * elen * ia
                buf[_F3B + t] = -buf[_W_3 + t] * elen * ib
            for t in range(n):  # scatter (libm atan2 for the large deviations)
                j = c0 + t
                value = buf[_VAL + t]
                if not (buf[_DEV_X + t] > 0.0 and abs(buf[_DEV_Y + t]) <= SMALL_TAN * buf[_DEV_X + t]):
                    value = math.atan2(buf[_DEV_Y + t], buf[_DEV_X + t])
                s = buf[_GAIN + t] * value
                i0 = idx[j, 0]
                i1 = idx[j, 1]
                i2 = idx[j, 2]
                i3 = idx[j, 3]
                fa = s * buf[_F0A + t]
                fb = s * buf[_F0B + t]
                x[i0, 0] += fa * buf[_A_X + t] + fb * buf[_B_X + t]
                x[i0, 1] += fa * buf[_A_Y + t] + fb * buf[_B_Y + t]
                x[i0, 2] += fa * buf[_A_Z + t] + fb * buf[_B_Z + t]
                fa = s * buf[_F1A + t]
                fb = s * buf[_F1B + t]
                x[i1, 0] += fa * buf[_A_X + t] + fb * buf[_B_X + t]
                x[i1, 1] += fa * buf[_A_Y + t] + fb * buf[_B_Y + t]
                x[i1, 2] += fa * buf[_A_Z + t] + fb * buf[_B_Z + t]
                fa = s * buf[_F2A + t]
                x[i2, 0] += fa * buf[_A_X + t]
                x[i2, 1] += fa * buf[_A_Y + t]
                x[i2, 2] += fa * buf[_A_Z + t]
                fb = s * buf[_F3B + t]
                x[i3, 0] += fb * buf[_B_X + t]
                x[i3, 1] += fb * buf[_B_Y + t]
                x[i3, 2] += fb * buf[_B_Z + t]


def rest_cos_sin(rest_angle) -> np.ndarray:
    """``(m, 2) float64`` cosine and sine of ``rest_angle (m,)`` (the kernel's rest input)."""
    a = np.asarray(rest_angle, dtype=np.float64).reshape(-1)
    return np.ascontiguousarray(np.c_[np.cos(a), np.sin(a)])


def solve_bending(positions, inv_mass, quads, rest_angle, stiffness) -> np.ndarray:
    """One PBD Gauss-Seidel sweep over all bending constraints; returns new ``(n, 3)`` positions."""
    x = np.array(positions, dtype=np.float64, order="C")
    idx = np.ascontiguousarray(quads, dtype=np.int64).reshape(-1, 4)
    m = len(idx)
    k = np.broadcast_to(np.asarray(stiffness, dtype=np.float64), (m,)).copy()
    _project_bending(x, np.ascontiguousarray(inv_mass, dtype=np.float64), idx,
                     rest_cos_sin(rest_angle), k,
                     np.zeros(m), np.zeros(m), False, 0, m)
    return x
