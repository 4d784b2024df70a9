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

from faceforge.pbd.constraints._common import BATCH, DEGENERATE, PBD_NUMBA, _multiplier


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

#: PBD mode: one projection turns a quad by at most this deviation (radians); a larger one is
#: taken over several iterations. The projection is a linearisation of the angle: from a
#: deviation of a few radians it overshoots, and a stiff sheet whose quads fold that far
#: (the orbicularis oris ring at MakeHuman's right corner, risorius_R at c = 0.45: deviations
#: up to 3.1 rad) grew without bound, faster with more iterations. The solution (deviation 0)
#: is unchanged, and so is every projection of a smaller deviation; XPBD is not clamped (its
#: compliant equilibrium depends on the deviation itself). 0.5 also stopped the blow-up but
#: left the template's ring folded at the jaw's full opening (tests/anatomy/test_build.py).
MAX_STEP_ANGLE = 1.0


@numba.njit(inline="always", **PBD_NUMBA)
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


@numba.njit(inline="always", **PBD_NUMBA)
def _solve_bending(x, w, i0, i1, i2, i3, rest_cos, rest_sin, k, c, lam, xpbd):
    """Project one dihedral constraint in place on ``x (n, 3)``; return the multiplier increment.

    The rest angle enters as its cosine and sine: the deviation is
    ``atan2(sin(theta - theta0), cos(theta - theta0))``, so no wrapping is needed.

    Length: one compiled kernel; split into calls, the hot loop would depend on numba inlining
    them.
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
    if not xpbd:
        value = min(max(value, -MAX_STEP_ANGLE), MAX_STEP_ANGLE)
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


@numba.njit(**PBD_NUMBA)
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
_E_X, _E_Y, _E_Z, _U_X, _U_Y, _U_Z, _V_X, _V_Y, _V_Z = (r * BATCH for r in range(9))
_STEP, _GAIN, _DEV_Y, _DEV_X = (r * BATCH for r in range(9, 13))
_D0X, _D0Y, _D0Z, _D1X, _D1Y, _D1Z, _D2X, _D2Y, _D2Z, _D3X, _D3Y, _D3Z = (
    r * BATCH for r in range(13, 25))


@numba.njit(**PBD_NUMBA)
def _project_bending_batched(x, idx, inv_mass, rest_cs, k, seg, buf, start, stop):
    """PBD sweep over ``start:stop`` whose constraints are grouped in independent runs.

    inv_mass : (4, m) float, the inverse masses of each quad's particles (constant for a
    frozen Model; contiguous per row so the math loop reads them as vectors);
    rest_cs : (2, m) float, cosine and sine of the rest angles; k : (m,) PBD stiffness;
    seg : (s,) int sorted boundaries of runs of constraints sharing no particle (one
    colour of a block); buf : (BATCH_ROWS * BATCH,) float scratch (one row per quantity).
    Each batch is gathered (edge and opposite-vertex vectors only), computed in a
    branch-free loop that the compiler vectorises (the math of ``_solve_bending``, Padé
    branch, giving per-particle displacements per unit multiplier), fixed up with libm
    atan2 where the deviation is large, then scattered. Constraints of a batch share no
    particle, so the result is that of the sequential sweep in the same order.

    Length: one compiled sweep (gather, three branch-free vector loops, scalar fix-up, scatter
    per batch); split into calls, the hot loop would depend on numba inlining them.
    """
    for q in range(seg.shape[0] - 1):
        lo = max(seg[q], start)
        hi = min(seg[q + 1], stop)
        for c0 in range(lo, hi, BATCH):
            n = min(BATCH, hi - c0)
            for t in range(n):  # gather
                j = np.uint64(c0 + t)
                i0 = np.uint64(idx[j, 0])
                i1 = np.uint64(idx[j, 1])
                i2 = np.uint64(idx[j, 2])
                i3 = np.uint64(idx[j, 3])
                p0x = x[i0, 0]
                p0y = x[i0, 1]
                p0z = x[i0, 2]
                p1x = x[i1, 0]
                p1y = x[i1, 1]
                p1z = x[i1, 2]
                buf[_E_X + t] = p1x - p0x
                buf[_E_Y + t] = p1y - p0y
                buf[_E_Z + t] = p1z - p0z
                buf[_U_X + t] = x[i2, 0] - p0x
                buf[_U_Y + t] = x[i2, 1] - p0y
                buf[_U_Z + t] = x[i2, 2] - p0z
                buf[_V_X + t] = x[i3, 0] - p1x
                buf[_V_Y + t] = x[i3, 1] - p1y
                buf[_V_Z + t] = x[i3, 2] - p1z
            for t in range(n):  # branch-free math of _solve_bending
                j = np.uint64(c0 + t)
                ex = buf[_E_X + t]
                ey = buf[_E_Y + t]
                ez = buf[_E_Z + t]
                ux = buf[_U_X + t]
                uy = buf[_U_Y + t]
                uz = buf[_U_Z + t]
                vx = buf[_V_X + t]
                vy = buf[_V_Y + t]
                vz = buf[_V_Z + t]
                w0 = inv_mass[0, j]
                w1 = inv_mass[1, j]
                w2 = inv_mass[2, j]
                w3 = inv_mass[3, j]
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
                rc = rest_cs[0, j]
                rs = rest_cs[1, j]
                yy = sin * rc - cos * rs
                xx = cos * rc + sin * rs
                small = (xx > 0.0) & (abs(yy) <= SMALL_TAN * xx)
                z = yy / (xx if small else 1.0)
                z2 = z * z
                value = z * (945.0 + z2 * (735.0 + 64.0 * z2)) / (945.0 + z2 * (1050.0 + 225.0 * z2))
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
                denom = (w0 * (a0 * a0 * ia + a0 * b0 * cab + b0 * b0 * ib)
                         + w1 * (a1 * a1 * ia + a1 * b1 * cab + b1 * b1 * ib)
                         + (w2 * ia + w3 * ib) * ee1)
                good = ok & (denom > 0.0)
                gain = -k[j] / (denom if good else 1.0) if good else 0.0
                buf[_STEP + t] = gain * value if small else 0.0  # the multiplier s
                buf[_GAIN + t] = 0.0 if small else gain  # nonzero: s needs libm atan2
                buf[_DEV_Y + t] = yy
                buf[_DEV_X + t] = xx
                fa = w0 * a0 * ia
                fb = w0 * b0 * ib
                buf[_D0X + t] = fa * ax + fb * bx
                buf[_D0Y + t] = fa * ay + fb * by
                buf[_D0Z + t] = fa * az + fb * bz
                fa = w1 * a1 * ia
                fb = w1 * b1 * ib
                buf[_D1X + t] = fa * ax + fb * bx
                buf[_D1Y + t] = fa * ay + fb * by
                buf[_D1Z + t] = fa * az + fb * bz
                fa = -w2 * elen * ia
                buf[_D2X + t] = fa * ax
                buf[_D2Y + t] = fa * ay
                buf[_D2Z + t] = fa * az
                fb = -w3 * elen * ib
                buf[_D3X + t] = fb * bx
                buf[_D3Y + t] = fb * by
                buf[_D3Z + t] = fb * bz
            for t in range(n):  # scatter dp_i = s w_i grad_i C
                j = np.uint64(c0 + t)
                s = buf[_STEP + t]
                gain = buf[_GAIN + t]
                if gain != 0.0:  # large deviation: libm atan2
                    s = gain * min(max(math.atan2(buf[_DEV_Y + t], buf[_DEV_X + t]), -MAX_STEP_ANGLE),
                                   MAX_STEP_ANGLE)
                i0 = np.uint64(idx[j, 0])
                i1 = np.uint64(idx[j, 1])
                i2 = np.uint64(idx[j, 2])
                i3 = np.uint64(idx[j, 3])
                x[i0, 0] += s * buf[_D0X + t]
                x[i0, 1] += s * buf[_D0Y + t]
                x[i0, 2] += s * buf[_D0Z + t]
                x[i1, 0] += s * buf[_D1X + t]
                x[i1, 1] += s * buf[_D1Y + t]
                x[i1, 2] += s * buf[_D1Z + t]
                x[i2, 0] += s * buf[_D2X + t]
                x[i2, 1] += s * buf[_D2Y + t]
                x[i2, 2] += s * buf[_D2Z + t]
                x[i3, 0] += s * buf[_D3X + t]
                x[i3, 1] += s * buf[_D3Y + t]
                x[i3, 2] += s * buf[_D3Z + t]


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
