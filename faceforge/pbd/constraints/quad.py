"""Fused sweep: the two stretch constraints of a bending quad, its dihedral constraint,
and (when the solver fuses them too) one of its triangles' area constraints.

The §8 skin (and every muscle) adds a distance block (stretch on every edge and across
every pair of adjacent triangles) immediately followed by the bending block on the same
quads ``(p0, p1, p2, p3)``. Each interior edge ``(p0, p1)`` and each cross pair
``(p2, p3)`` is then the stretch constraint of exactly one quad. With colouring on, the
solver may project, quad by quad, "stretch (p0, p1), stretch (p2, p3), bending" instead
of "all stretches, then all bendings": still a sequential Gauss-Seidel sweep over the
same constraints, each projected once per iteration with the same update, in another
order (like colouring itself). The four particles are read and written once for three
projections, and the stretch math runs in the vectorised loop. Stretches that belong to
no quad (boundary edges, anchors) stay in their distance block, projected before.
Likewise an area block right after gives each quad at most one triangle lying on it
(:func:`match_quad_triangles`), projected after the quad's bending; the triangles left
over keep their area block, projected after. A closed mesh has 1.5 quads per triangle, so
a third of the quads get none: the solver moves the quads with an area to the front of
each colour run (:func:`areas_first`; the quads of a run are independent, so the bits do
not change) and the sweep skips the area rows of the others.

The bending multiplier ``-k atan(yy / xx) / D`` (Padé branch of ``bending._deviation``)
is evaluated with one division, both Padé polynomials scaled by ``xx^4`` (about
``edge^16``): fine for edge lengths between ~1e-15 and ~1e15 length units. The scatter
stores the projected positions (no reload of the particles); the rare large deviations
(libm atan2) are recomputed lane by lane and fixed up in the scratch rows before it.

Indices are used as unsigned integers (``np.uint64``; the builder guarantees
non-negative ids): numba then skips its negative-index wraparound, which otherwise turns
every per-quad table read of the vectorised loop into a gather instruction (Mesh_D quads
with areas: 18.6 -> 15.4 ns per quad), and the scalar gather/scatter loops lose a select
per index.

Only used in the PBD modes (XPBD keeps separate sweeps and multipliers).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from faceforge.pbd.constraints._common import BATCH, DEGENERATE, PBD_NUMBA
from faceforge.pbd.constraints.area import _area_increments
from faceforge.pbd.constraints.bending import MAX_STEP_ANGLE, SMALL_TAN


def match_quad_stretches(pairs: np.ndarray, quads: np.ndarray) -> np.ndarray:
    """For each quad, the distance constraint on its edge and on its cross pair.

    pairs : (d, 2) int particle ids of candidate distance constraints; quads : (m, 4) int.
    Returns ``(m, 2) int64``: rows ``(edge, cross)`` indexing ``pairs`` (unordered match of
    ``(p0, p1)`` and ``(p2, p3)``), -1 where none. Each distance constraint is matched to
    at most one quad (the first one, in quad order); duplicates of a pair stay unmatched.
    """
    p = np.sort(np.asarray(pairs, dtype=np.int64).reshape(-1, 2), axis=1)
    q = np.asarray(quads, dtype=np.int64).reshape(-1, 4)
    first = {}
    for j, (a, b) in enumerate(p.tolist()):
        first.setdefault((a, b), j)
    out = np.full((len(q), 2), -1, dtype=np.int64)
    for j, (p0, p1, p2, p3) in enumerate(q.tolist()):
        for col, (a, b) in enumerate(((p0, p1), (p2, p3))):
            key = (a, b) if a < b else (b, a)
            hit = first.pop(key, -1)  # pop: one quad per distance constraint
            out[j, col] = hit
    return out


def stretch_table(pairs: np.ndarray, quads: np.ndarray, match: np.ndarray,
                  coef: np.ndarray) -> np.ndarray:
    """``(m, 6) float64`` per quad: ``(l0, share_p0, share_p1)`` of its edge stretch and
    ``(l0, share_p2, share_p3)`` of its cross stretch.

    pairs : (d, 2) int and coef : (d, 3) float, the distance constraints and their PBD
    data (``distance.pbd_coefficients``); quads : (m, 4) int; match : (m, 2) int from
    :func:`match_quad_stretches`. Shares are swapped where a pair is stored the other
    way round. Unmatched: rest 1, shares 0 (the projection moves nothing).
    """
    out = np.zeros((len(match), 6))
    out[:, 0] = out[:, 3] = 1.0
    for col, first in ((0, 0), (1, 2)):
        hit = np.flatnonzero(match[:, col] >= 0)
        c = coef[match[hit, col]]
        same = pairs[match[hit, col], 0] == quads[hit, first]
        out[hit, 3 * col] = c[:, 0]
        out[hit, 3 * col + 1] = np.where(same, c[:, 1], c[:, 2])
        out[hit, 3 * col + 2] = np.where(same, c[:, 2], c[:, 1])
    return out


def match_quad_triangles(triangles: np.ndarray, quads: np.ndarray) -> np.ndarray:
    """A triangle per quad, each triangle given to at most one quad.

    triangles : (t, 3) int; quads : (m, 4) int. A quad holds the triangles
    ``{p0, p1, p2}`` and ``{p0, p1, p3}``. Returns ``(m,) int64`` indices into
    ``triangles`` (-1: none): a maximum matching (greedy in triangle order, then augmenting
    paths in triangle order), deterministic. Duplicated triangles are matched at most
    once each.
    """
    t = np.sort(np.asarray(triangles, dtype=np.int64).reshape(-1, 3), axis=1)
    q = np.asarray(quads, dtype=np.int64).reshape(-1, 4)
    ids = {}
    for j, key in enumerate(map(tuple, t.tolist())):
        ids.setdefault(key, []).append(j)
    cand = [[] for _ in range(len(t))]  # quads holding each triangle, in quad order
    for j, (p0, p1, p2, p3) in enumerate(q.tolist()):
        for third in (p2, p3):
            for tri in ids.get(tuple(sorted((p0, p1, third))), ()):
                cand[tri].append(j)
    owner = np.full(len(q), -1, dtype=np.int64)  # triangle per quad
    for tri, quads_of_tri in enumerate(cand):  # greedy
        for j in quads_of_tri:
            if owner[j] < 0:
                owner[j] = tri
                break
    matched = np.zeros(len(t), dtype=bool)
    matched[owner[owner >= 0]] = True
    for tri in np.flatnonzero(~matched).tolist():  # augmenting paths (breadth first)
        if not cand[tri]:
            continue
        parent = {tri: (-1, -1)}  # triangle -> (previous triangle, quad taken from it)
        frontier = [tri]
        end = None
        while frontier and end is None:
            nxt = []
            for a in frontier:
                for j in cand[a]:
                    b = int(owner[j])
                    if b < 0:
                        end = (a, j)
                        break
                    if b not in parent:
                        parent[b] = (a, j)
                        nxt.append(b)
                if end is not None:
                    break
            frontier = nxt
        if end is None:
            continue
        a, j = end
        while a >= 0:  # flip the path: a takes j, a's previous quad goes back up
            prev, pj = parent[a]
            owner[j] = a
            a, j = prev, pj
    return owner


def area_table(triangles: np.ndarray, quads: np.ndarray, match: np.ndarray,
               rest: np.ndarray, k: np.ndarray) -> np.ndarray:
    """``(m, 3) float64`` per quad: ``(rest area, k, side)`` of its fused area constraint.

    triangles : (t, 3) int with ``rest``, ``k`` : (t,) float (the area constraints);
    quads : (m, 4) int; match : (m,) int from :func:`match_quad_triangles`. ``side`` is 1
    when the triangle's third vertex is ``p2``, 0 when it is ``p3``. Unmatched quads:
    ``(0, 0, 1)`` (the projection moves nothing).
    """
    out = np.zeros((len(match), 3))
    out[:, 2] = 1.0
    hit = np.flatnonzero(match >= 0)
    tri = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)[match[hit]]
    out[hit, 0] = np.asarray(rest, dtype=np.float64)[match[hit]]
    out[hit, 1] = np.asarray(k, dtype=np.float64)[match[hit]]
    out[hit, 2] = (tri == np.asarray(quads)[hit, 2:3]).any(axis=1)
    return out


# scratch rows: gathered positions, the atan2 fix-up flag, projected positions, positions
# after the stretches
_P0X, _P0Y, _P0Z, _P1X, _P1Y, _P1Z, _P2X, _P2Y, _P2Z, _P3X, _P3Y, _P3Z = (
    r * BATCH for r in range(12))
_FIX = 12 * BATCH
_S0X, _S0Y, _S0Z, _S1X, _S1Y, _S1Z, _S2X, _S2Y, _S2Z, _S3X, _S3Y, _S3Z = (
    r * BATCH for r in range(25, 37))
_Q0X, _Q0Y, _Q0Z, _Q1X, _Q1Y, _Q1Z, _Q2X, _Q2Y, _Q2Z, _Q3X, _Q3Y, _Q3Z = (
    r * BATCH for r in range(13, 25))


@numba.njit(inline="always", **PBD_NUMBA)
def _stretch_factor(d2, rest):
    """``(d - l0) / d`` of a distance constraint with ``d^2 = d2``; 0 when degenerate."""
    ok = (d2 > DEGENERATE * rest * rest) & (d2 > 0.0)
    d = math.sqrt(d2 if ok else 1.0)
    return (d - rest) / d if ok else 0.0


@numba.njit(inline="always", **PBD_NUMBA)
def _quad_stretches(buf, t, j, stretch):
    """The two stretches of quad ``j`` gathered in lane ``t`` of ``buf``: reads its ``_P*``
    rows, writes the stretched positions to its ``_S*`` rows (the ``_P*`` rows stay as
    gathered)."""
    p0x = buf[_P0X + t]
    p0y = buf[_P0Y + t]
    p0z = buf[_P0Z + t]
    p1x = buf[_P1X + t]
    p1y = buf[_P1Y + t]
    p1z = buf[_P1Z + t]
    p2x = buf[_P2X + t]
    p2y = buf[_P2Y + t]
    p2z = buf[_P2Z + t]
    p3x = buf[_P3X + t]
    p3y = buf[_P3Y + t]
    p3z = buf[_P3Z + t]
    # stretch of the shared edge (p0, p1)
    dx = p0x - p1x
    dy = p0y - p1y
    dz = p0z - p1z
    g = _stretch_factor(dx * dx + dy * dy + dz * dz, stretch[0, j])
    a = g * stretch[1, j]
    b = g * stretch[2, j]
    p0x = p0x - a * dx
    p0y = p0y - a * dy
    p0z = p0z - a * dz
    p1x = p1x + b * dx
    p1y = p1y + b * dy
    p1z = p1z + b * dz
    # stretch across the two triangles (p2, p3)
    dx = p2x - p3x
    dy = p2y - p3y
    dz = p2z - p3z
    g = _stretch_factor(dx * dx + dy * dy + dz * dz, stretch[3, j])
    a = g * stretch[4, j]
    b = g * stretch[5, j]
    p2x = p2x - a * dx
    p2y = p2y - a * dy
    p2z = p2z - a * dz
    p3x = p3x + b * dx
    p3y = p3y + b * dy
    p3z = p3z + b * dz
    buf[_S0X + t] = p0x
    buf[_S0Y + t] = p0y
    buf[_S0Z + t] = p0z
    buf[_S1X + t] = p1x
    buf[_S1Y + t] = p1y
    buf[_S1Z + t] = p1z
    buf[_S2X + t] = p2x
    buf[_S2Y + t] = p2y
    buf[_S2Z + t] = p2z
    buf[_S3X + t] = p3x
    buf[_S3Y + t] = p3y
    buf[_S3Z + t] = p3z


@numba.njit(inline="always", **PBD_NUMBA)
def _quad_math(buf, t, j, inv_mass, rest_cs, k):
    """Branch-free bending (Padé branch) of quad ``j`` from lane ``t``'s ``_S*`` rows (the
    positions after its stretches). Returns 28 floats: the 12 projected coordinates;
    1.0 if the bending needs the libm atan2 fix-up (then its step is 0 here; also stored
    in the ``_FIX`` row), else 0.0; the 12 bending displacements per unit multiplier; the
    bending denominator and the rotated pair ``(y, x)`` whose atan2 is the deviation. The
    vectorised loop uses the first 13 (LLVM drops the rest); the fix-up loop recomputes
    the rare lanes that need the rest.

    Length: the vectorised body of the compiled quad sweep, kept whole for speed.
    """
    p0x = buf[_S0X + t]
    p0y = buf[_S0Y + t]
    p0z = buf[_S0Z + t]
    p1x = buf[_S1X + t]
    p1y = buf[_S1Y + t]
    p1z = buf[_S1Z + t]
    p2x = buf[_S2X + t]
    p2y = buf[_S2Y + t]
    p2z = buf[_S2Z + t]
    p3x = buf[_S3X + t]
    p3y = buf[_S3Y + t]
    p3z = buf[_S3Z + t]
    # bending (the math of bending._solve_bending, PBD, Padé branch)
    ex = p1x - p0x
    ey = p1y - p0y
    ez = p1z - p0z
    ux = p2x - p0x
    uy = p2y - p0y
    uz = p2z - p0z
    vx = p3x - p1x
    vy = p3y - p1y
    vz = p3z - p1z
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
    # Padé atan of z = yy / xx (bending._deviation) times 1 / denom with one
    # division: both polynomials scaled by xx^4
    xs = xx if small else 1.0
    y2 = yy * yy
    x2 = xs * xs
    num = yy * (945.0 * x2 * x2 + 735.0 * x2 * y2 + 64.0 * y2 * y2)
    den = xs * (945.0 * x2 * x2 + 1050.0 * x2 * y2 + 225.0 * y2 * y2)
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
    step = -k[j] * num / (den * (denom if good else 1.0))
    step = step if good & small else 0.0  # the multiplier s (Padé branch)
    # 1 where s needs libm atan2 (large deviation of a non-degenerate quad)
    fix = (1.0 if good else 0.0) * (0.0 if small else 1.0)
    buf[_FIX + t] = fix
    fa = w0 * a0 * ia
    fb = w0 * b0 * ib
    d0x = fa * ax + fb * bx
    d0y = fa * ay + fb * by
    d0z = fa * az + fb * bz
    q0x = p0x + step * d0x
    q0y = p0y + step * d0y
    q0z = p0z + step * d0z
    fa = w1 * a1 * ia
    fb = w1 * b1 * ib
    d1x = fa * ax + fb * bx
    d1y = fa * ay + fb * by
    d1z = fa * az + fb * bz
    q1x = p1x + step * d1x
    q1y = p1y + step * d1y
    q1z = p1z + step * d1z
    fa = -w2 * elen * ia
    q2x = p2x + step * (fa * ax)
    q2y = p2y + step * (fa * ay)
    q2z = p2z + step * (fa * az)
    fb = -w3 * elen * ib
    q3x = p3x + step * (fb * bx)
    q3y = p3y + step * (fb * by)
    q3z = p3z + step * (fb * bz)
    return (q0x, q0y, q0z, q1x, q1y, q1z, q2x, q2y, q2z, q3x, q3y, q3z, fix,
            d0x, d0y, d0z, d1x, d1y, d1z, fa * ax, fa * ay, fa * az, fb * bx, fb * by, fb * bz,
            denom, yy, xx)


def areas_first(match: np.ndarray, seg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Reorder the quads inside each run so that those with a fused area come first.

    match : (m,) int, the triangle of each quad (-1: none, :func:`match_quad_triangles`);
    seg : (s,) int sorted run boundaries (0 ... m) of quads sharing no particle. Returns
    ``(order (m,) int64, area_stop (s - 1,) int64)``: a stable permutation that moves
    quads only within their run (the quads of a run are independent, so a sweep in the new
    order gives the same bits), and, per run, the end of its quads with an area, for the
    ``area_stop`` of :func:`_project_quads_batched`.
    """
    match = np.asarray(match).reshape(-1)
    seg = np.asarray(seg, dtype=np.int64).reshape(-1)
    run = np.repeat(np.arange(len(seg) - 1), np.diff(seg))
    order = np.lexsort((np.arange(len(match)), match < 0, run)).astype(np.int64)
    count = np.concatenate([[0], np.cumsum(match >= 0)]).astype(np.int64)
    return order, seg[:-1] + count[seg[1:]] - count[seg[:-1]]


@numba.njit(**PBD_NUMBA)
def _project_quads_batched(x, idx, inv_mass, rest_cs, k, stretch, area, with_area, seg,
                           area_stop, buf, start, stop):
    """PBD sweep over quads ``start:stop``: per quad, stretch (p0, p1), stretch (p2, p3),
    the dihedral constraint, then (``with_area``) its fused area constraint (see the
    module docstring).

    idx : (m, 4) int quads; inv_mass : (4, m) float; rest_cs : (2, m) float rest cosines
    and sines; k : (m,) bending stiffness; stretch : (6, m) float, the transpose of
    :func:`stretch_table` (rows read as vectors); area : (3, m) float, the transpose of
    :func:`area_table` (read only when ``with_area``); seg : (s,) int sorted boundaries
    of runs of quads sharing no particle; area_stop : (s - 1,) int, per run, the end of
    the quads ``seg[q]:area_stop[q]`` that have an area constraint, the others having none
    (:func:`areas_first`; ``seg[1:]``: every quad's area row is projected, an unmatched
    row of :func:`area_table` moving nothing); buf : (BATCH_ROWS * BATCH,) float scratch. The
    math per quad is that of ``distance._project_distance_pbd`` twice, then
    ``bending._solve_bending`` (PBD), then ``area._area_increments``, each on the updated
    positions.

    Length: the compiled quad sweep (issue 24 allows it to stay whole: splitting would cost
    speed).
    """
    for q in range(seg.shape[0] - 1):
        lo = max(seg[q], start)
        hi = min(seg[q + 1], stop)
        for c0 in range(lo, hi, BATCH):
            n = min(BATCH, hi - c0)
            n_area = min(n, max(0, area_stop[q] - c0)) if with_area else 0
            any_fix = 0
            for t in range(n):  # gather
                j = np.uint64(c0 + t)
                i0 = np.uint64(idx[j, 0])
                i1 = np.uint64(idx[j, 1])
                i2 = np.uint64(idx[j, 2])
                i3 = np.uint64(idx[j, 3])
                buf[_P0X + t] = x[i0, 0]
                buf[_P0Y + t] = x[i0, 1]
                buf[_P0Z + t] = x[i0, 2]
                buf[_P1X + t] = x[i1, 0]
                buf[_P1Y + t] = x[i1, 1]
                buf[_P1Z + t] = x[i1, 2]
                buf[_P2X + t] = x[i2, 0]
                buf[_P2Y + t] = x[i2, 1]
                buf[_P2Z + t] = x[i2, 2]
                buf[_P3X + t] = x[i3, 0]
                buf[_P3Y + t] = x[i3, 1]
                buf[_P3Z + t] = x[i3, 2]
            # three branch-free vectorised loops rather than one: shorter bodies let the CPU
            # overlap more lanes of the long sqrt/division chains (12.3 vs 13.7 ns a quad)
            for t in range(n):  # the two stretches
                _quad_stretches(buf, t, np.uint64(c0 + t), stretch)
            for t in range(n):  # bending
                r = _quad_math(buf, t, np.uint64(c0 + t), inv_mass, rest_cs, k)
                any_fix |= 1 if r[12] != 0.0 else 0
                buf[_Q0X + t] = r[0]
                buf[_Q0Y + t] = r[1]
                buf[_Q0Z + t] = r[2]
                buf[_Q1X + t] = r[3]
                buf[_Q1Y + t] = r[4]
                buf[_Q1Z + t] = r[5]
                buf[_Q2X + t] = r[6]
                buf[_Q2Y + t] = r[7]
                buf[_Q2Z + t] = r[8]
                buf[_Q3X + t] = r[9]
                buf[_Q3Y + t] = r[10]
                buf[_Q3Z + t] = r[11]
            for t in range(n_area):  # the fused area constraint
                j = np.uint64(c0 + t)
                side = area[2, j] != 0.0  # third vertex p2, else p3
                w2 = inv_mass[2, j]
                w3 = inv_mass[3, j]
                q2x = buf[_Q2X + t]
                q2y = buf[_Q2Y + t]
                q2z = buf[_Q2Z + t]
                q3x = buf[_Q3X + t]
                q3y = buf[_Q3Y + t]
                q3z = buf[_Q3Z + t]
                d0x, d0y, d0z, d1x, d1y, d1z, d2x, d2y, d2z = _area_increments(
                    buf[_Q0X + t], buf[_Q0Y + t], buf[_Q0Z + t], buf[_Q1X + t],
                    buf[_Q1Y + t], buf[_Q1Z + t], q2x if side else q3x, q2y if side else q3y,
                    q2z if side else q3z, inv_mass[0, j], inv_mass[1, j],
                    w2 if side else w3, area[0, j],
                    0.0 if buf[_FIX + t] != 0.0 else area[1, j])
                buf[_Q0X + t] += d0x
                buf[_Q0Y + t] += d0y
                buf[_Q0Z + t] += d0z
                buf[_Q1X + t] += d1x
                buf[_Q1Y + t] += d1y
                buf[_Q1Z + t] += d1z
                buf[_Q2X + t] = q2x + (d2x if side else 0.0)
                buf[_Q2Y + t] = q2y + (d2y if side else 0.0)
                buf[_Q2Z + t] = q2z + (d2z if side else 0.0)
                buf[_Q3X + t] = q3x + (0.0 if side else d2x)
                buf[_Q3Y + t] = q3y + (0.0 if side else d2y)
                buf[_Q3Z + t] = q3z + (0.0 if side else d2z)
            for t in range(n if any_fix else 0):  # large deviations: libm atan2, displacement
                if buf[_FIX + t] != 0.0:  # recompute the lane (its S rows are unchanged)
                    j = np.uint64(c0 + t)
                    r = _quad_math(buf, t, j, inv_mass, rest_cs, k)
                    turn = min(max(math.atan2(r[26], r[27]), -MAX_STEP_ANGLE), MAX_STEP_ANGLE)
                    step = -k[j] / r[25] * turn
                    for c in range(12):
                        buf[_Q0X + c * BATCH + t] = r[c] + step * r[13 + c]
                    if t < n_area:  # the fused area constraint, after the bending
                        third = _Q2X if area[2, j] != 0.0 else _Q3X
                        w3 = inv_mass[2, j] if area[2, j] != 0.0 else inv_mass[3, j]
                        d = _area_increments(
                            buf[_Q0X + t], buf[_Q0Y + t], buf[_Q0Z + t], buf[_Q1X + t],
                            buf[_Q1Y + t], buf[_Q1Z + t], buf[third + t],
                            buf[third + BATCH + t], buf[third + 2 * BATCH + t],
                            inv_mass[0, j], inv_mass[1, j], w3, area[0, j], area[1, j])
                        for r in range(6):
                            buf[_Q0X + r * BATCH + t] += d[r]
                        for r in range(3):
                            buf[third + r * BATCH + t] += d[6 + r]
            for t in range(n):  # scatter
                j = np.uint64(c0 + t)
                i0 = np.uint64(idx[j, 0])
                i1 = np.uint64(idx[j, 1])
                i2 = np.uint64(idx[j, 2])
                i3 = np.uint64(idx[j, 3])
                x[i0, 0] = buf[_Q0X + t]
                x[i0, 1] = buf[_Q0Y + t]
                x[i0, 2] = buf[_Q0Z + t]
                x[i1, 0] = buf[_Q1X + t]
                x[i1, 1] = buf[_Q1Y + t]
                x[i1, 2] = buf[_Q1Z + t]
                x[i2, 0] = buf[_Q2X + t]
                x[i2, 1] = buf[_Q2Y + t]
                x[i2, 2] = buf[_Q2Z + t]
                x[i3, 0] = buf[_Q3X + t]
                x[i3, 1] = buf[_Q3Y + t]
                x[i3, 2] = buf[_Q3Z + t]
