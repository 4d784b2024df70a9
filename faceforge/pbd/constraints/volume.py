"""Volume of a triangulated surface (one constraint per body).

``V = 1/6 sum_f (p_a - r) . ((p_b - r) x (p_c - r))`` summed over the body's oriented
triangles ``(a, b, c)`` and ``C = V - V0`` (Müller et al. 2007, section 4.4 / paper §8).

The reference point ``r`` is the centroid of the *reference particles*: the boundary
vertices of the surface (vertices on an edge used by one triangle only), or every
vertex when the surface is closed. For a closed surface V does not depend on r. An
open surface is closed virtually by the fan of triangles from r to its boundary
edges: those triangles contain r and add nothing to the sum, so V is the volume of
that closed surface. Because r moves with the boundary, V is invariant under
translation and rotation of the body, and the chain-rule term ``dV/dr`` (spread
evenly over the reference particles) makes the gradient sum to zero, so the
projection conserves linear momentum.

Per body the model stores a CSR block: the body's particles, its triangles and
its reference particles (the solver passes all three in global ids).
"""

from __future__ import annotations

import numba
import numpy as np

from faceforge.pbd.constraints._common import _multiplier, PBD_NUMBA


def boundary_vertices(triangles: np.ndarray) -> np.ndarray:
    """Sorted vertex ids ``(b,) int64`` on edges used by exactly one of ``triangles (f, 3)``."""
    t = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    edges = np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1)
    uniq, counts = np.unique(edges, axis=0, return_counts=True)
    return np.unique(uniq[counts == 1])


def reference_vertices(triangles: np.ndarray) -> np.ndarray:
    """The vertices whose centroid is the reference point: boundary, or all if closed."""
    b = boundary_vertices(triangles)
    return b if len(b) else np.unique(np.asarray(triangles, dtype=np.int64))


def signed_volume(positions: np.ndarray, triangles: np.ndarray) -> float:
    """Volume (cubed length units) enclosed by ``triangles`` closed virtually (see module doc)."""
    p = np.asarray(positions, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    r = p[reference_vertices(t)].mean(axis=0)
    a, b, c = p[t[:, 0]] - r, p[t[:, 1]] - r, p[t[:, 2]] - r
    return float(np.einsum("ij,ij->", a, np.cross(b, c)) / 6.0)


def init_volume(positions: np.ndarray, triangles: np.ndarray) -> float:
    """Rest volume of one body (cubed length units)."""
    return signed_volume(positions, triangles)


def residual_volume(positions, triangles, rest_volume) -> float:
    """``C`` of one body, in cubed length units."""
    return signed_volume(positions, triangles) - float(rest_volume)


def pair_triangles(triangles: np.ndarray) -> np.ndarray:
    """Rows ``(f', 4) int64`` for the volume kernel: triangles paired across shared edges.

    triangles : (f, 3) int, oriented. Greedy in triangle order: an unpaired triangle
    takes, over its edges in order, the first unpaired triangle holding the reversed edge
    (consistently oriented neighbours only): row ``(a, b, c, d)`` for the triangles
    ``(a, b, c)`` and ``(b, a, d)``. Triangles left alone follow as ``(a, b, c, -1)``.
    Every triangle is in exactly one row, with its orientation.
    """
    t = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    half = {}  # directed edge -> (first triangle holding it, its opposite vertex)
    for j, (a, b, c) in enumerate(t.tolist()):
        for u, v, o in ((a, b, c), (b, c, a), (c, a, b)):
            half.setdefault((u, v), (j, o))
    taken = np.zeros(len(t), dtype=bool)
    pairs, singles = [], []
    for i, (a, b, c) in enumerate(t.tolist()):
        if taken[i]:
            continue
        for u, v, o in ((a, b, c), (b, c, a), (c, a, b)):
            j, d = half.get((v, u), (-1, -1))
            if j >= 0 and j != i and not taken[j]:
                taken[i] = taken[j] = True
                pairs.append((u, v, o, d))
                break
        else:
            singles.append((a, b, c, -1))
    return np.array(pairs + singles, dtype=np.int64).reshape(-1, 4)


@numba.njit(inline="always", **PBD_NUMBA)
def _volume_centroid(x, ref):
    """Centroid ``(rx, ry, rz)`` of the reference particles ``ref (r,)``, ``r > 0``."""
    nref = ref.shape[0]
    rx = 0.0
    ry = 0.0
    rz = 0.0
    for q in range(nref):
        i = np.uint64(ref[q])
        rx += x[i, 0]
        ry += x[i, 1]
        rz += x[i, 2]
    return rx / nref, ry / nref, rz / nref


@numba.njit(inline="always", **PBD_NUMBA)
def _volume_rows(x, tris, rx, ry, rz, g):
    """Six times the volume of the triangle rows ``tris (f, 4)`` (see :func:`_solve_volume`)
    about the reference point ``(rx, ry, rz)``; adds their gradient terms into ``g``."""
    vol = 0.0
    for f in range(tris.shape[0]):
        ia = np.uint64(tris[f, 0])
        ib = np.uint64(tris[f, 1])
        ic = np.uint64(tris[f, 2])
        ax = x[ia, 0] - rx
        ay = x[ia, 1] - ry
        az = x[ia, 2] - rz
        bx = x[ib, 0] - rx
        by = x[ib, 1] - ry
        bz = x[ib, 2] - rz
        cx = x[ic, 0] - rx
        cy = x[ic, 1] - ry
        cz = x[ic, 2] - rz
        # a x b (the gradient term of c)
        px = ay * bz - az * by
        py = az * bx - ax * bz
        pz = ax * by - ay * bx
        g[ic, 0] += px
        g[ic, 1] += py
        g[ic, 2] += pz
        if tris[f, 3] >= 0:  # a pair (a, b, c) + (b, a, d): three cross products
            i_d = np.uint64(tris[f, 3])
            ex = cx - (x[i_d, 0] - rx)  # e = c - d
            ey = cy - (x[i_d, 1] - ry)
            ez = cz - (x[i_d, 2] - rz)
            g[i_d, 0] -= px
            g[i_d, 1] -= py
            g[i_d, 2] -= pz
        else:  # a single triangle (a, b, c): e = c
            ex = cx
            ey = cy
            ez = cz
        qx = by * ez - bz * ey  # b x e (the gradient term of a)
        qy = bz * ex - bx * ez
        qz = bx * ey - by * ex
        vol += ax * qx + ay * qy + az * qz
        g[ia, 0] += qx
        g[ia, 1] += qy
        g[ia, 2] += qz
        g[ib, 0] += ey * az - ez * ay  # e x a (the gradient term of b)
        g[ib, 1] += ez * ax - ex * az
        g[ib, 2] += ex * ay - ey * ax
    return vol


@numba.njit(inline="always", **PBD_NUMBA)
def _group_sums(w, particles, g):
    """``(sum g_x, sum g_y, sum g_z, sum w |g|^2)`` over the particles ``particles (p,)``."""
    sx = 0.0
    sy = 0.0
    sz = 0.0
    denom = 0.0
    for q in range(particles.shape[0]):
        i = np.uint64(particles[q])
        gx = g[i, 0]
        gy = g[i, 1]
        gz = g[i, 2]
        sx += gx
        sy += gy
        sz += gz
        denom += w[i] * (gx * gx + gy * gy + gz * gz)
    return sx, sy, sz, denom


@numba.njit(inline="always", **PBD_NUMBA)
def _volume_scale(w, ref, vol, sx, sy, sz, denom, rest, k, c, lam, g, xpbd):
    """The projection's scale once ``vol`` (six times the volume), the triangle terms of ``g``
    and their sums (:func:`_group_sums` over the body) are known: the ``dV/dr`` share of the
    reference particles ``ref (r,)`` goes into their ``g``. Returns ``(s, s / 6, moved)``:
    the multiplier increment, the update's factor and whether the body moves (see
    :func:`_volume_apply`)."""
    nref = ref.shape[0]
    sx /= nref
    sy /= nref
    sz /= nref
    before = 0.0  # the reference particles' terms of denom, before and after the share
    after = 0.0
    for q in range(nref):
        i = np.uint64(ref[q])
        gx = g[i, 0]
        gy = g[i, 1]
        gz = g[i, 2]
        before += w[i] * (gx * gx + gy * gy + gz * gz)
        gx -= sx
        gy -= sy
        gz -= sz
        after += w[i] * (gx * gx + gy * gy + gz * gz)
        g[i, 0] = gx
        g[i, 1] = gy
        g[i, 2] = gz
    denom = (denom - before + after) / 36.0
    if denom > 0.0:
        s = _multiplier(vol / 6.0 - rest, denom, k, c, lam, xpbd)
        return s, s / 6.0, True
    return 0.0, 0.0, False


@numba.njit(inline="always", **PBD_NUMBA)
def _volume_apply(x, w, particles, g, f6, moved):
    """The update of :func:`_volume_scale` on ``particles (p,)``, ``x += f6 w g`` when
    ``moved``; their ``g`` cleared either way."""
    if moved:
        for q in range(particles.shape[0]):
            i = np.uint64(particles[q])
            f = f6 * w[i]
            x[i, 0] += f * g[i, 0]
            x[i, 1] += f * g[i, 1]
            x[i, 2] += f * g[i, 2]
            g[i, 0] = 0.0
            g[i, 1] = 0.0
            g[i, 2] = 0.0
    else:
        for q in range(particles.shape[0]):
            i = np.uint64(particles[q])
            g[i, 0] = 0.0
            g[i, 1] = 0.0
            g[i, 2] = 0.0


@numba.njit(inline="always", **PBD_NUMBA)
def _solve_volume(x, w, particles, pcuts, tris, cuts, ref, rest, k, c, lam, g, xpbd):
    """Project one volume constraint in place on ``x (n, 3)``.

    particles : (p,) int global ids of the body, in ``s + 1`` groups ``pcuts (s + 2,)`` (one, or
    one per part and those of no part, :mod:`faceforge.pbd.partition`); tris : (f, 4) int global
    ids, the rows of :func:`pair_triangles` (pairs ``(a, b, c, d)``, singles ``(a, b, c, -1)``),
    the body's being ``cuts[0]:cuts[-1]``; cuts : (s + 2,) int, the body's rows in groups:
    one per part, the last joining parts (empty without parts); ref : (r,) int global ids of
    the reference particles (distinct); g : (n, 3) float scratch indexed by particle, all zero
    on entry and left all zero (only the body's rows are used). Sums are added group by
    group, the rows joining parts first, as :func:`_solve_volume_parts` adds them. Returns the
    multiplier increment.

    Passes: reference centroid, one over the triangles (volume and gradient; a pair of
    triangles sharing an edge needs three cross products and 12 gradient updates instead
    of six and 18: ``g_a += b x (c - d)``, ``g_b += (c - d) x a``, ``g_c += a x b``,
    ``g_d -= a x b``, ``6 V += a . (b x (c - d))``, corners relative to r), one over
    the particles (gradient sum and ``sum w |g|^2``), one over the reference particles
    (the ``dV/dr`` share and its effect on the denominator), one update that also clears
    ``g``.
    """
    if particles.shape[0] == 0 or ref.shape[0] == 0:
        return 0.0
    rx, ry, rz = _volume_centroid(x, ref)
    n = cuts.shape[0] - 2
    vol = _volume_rows(x, tris[cuts[n]:cuts[n + 1]], rx, ry, rz, g)
    for q in range(n):
        vol += _volume_rows(x, tris[cuts[q]:cuts[q + 1]], rx, ry, rz, g)
    sx = 0.0
    sy = 0.0
    sz = 0.0
    denom = 0.0
    for q in range(pcuts.shape[0] - 1):
        ax, ay, az, ad = _group_sums(w, particles[pcuts[q]:pcuts[q + 1]], g)
        sx += ax
        sy += ay
        sz += az
        denom += ad
    s, f6, moved = _volume_scale(w, ref, vol, sx, sy, sz, denom, rest, k, c, lam, g, xpbd)
    _volume_apply(x, w, particles, g, f6, moved)
    return s


@numba.njit(parallel=True, **PBD_NUMBA)
def _solve_volume_parts(x, w, particles, pcuts, tris, cuts, ref, rest, k, c, lam, g, xpbd,
                        sums, defer):
    """:func:`_solve_volume` of a body whose rows and particles are grouped by part
    (:mod:`faceforge.pbd.partition`): the rows joining parts first, then each part ``p < n``
    at once, one thread each: its rows ``cuts[p]:cuts[p + 1]`` (they touch only its particles)
    and then its particles' sums ``pcuts[p]:pcuts[p + 1]`` (into ``sums[p, :5]``); the
    particles of no part last. The same projection as :func:`_solve_volume`, to the bit.

    With ``defer`` the update is left to the caller (:func:`_volume_apply` with the returned
    factor, part by part: nothing may read the body's positions before). Returns ``(s, s / 6,
    moved)`` (:func:`_volume_scale`)."""
    if particles.shape[0] == 0 or ref.shape[0] == 0:
        return 0.0, 0.0, False
    rx, ry, rz = _volume_centroid(x, ref)
    n = cuts.shape[0] - 2
    vol = _volume_rows(x, tris[cuts[n]:cuts[n + 1]], rx, ry, rz, g)
    for p in numba.prange(n):
        sums[p, 0] = _volume_rows(x, tris[cuts[p]:cuts[p + 1]], rx, ry, rz, g)
        ax, ay, az, ad = _group_sums(w, particles[pcuts[p]:pcuts[p + 1]], g)
        sums[p, 1] = ax
        sums[p, 2] = ay
        sums[p, 3] = az
        sums[p, 4] = ad
    sx = 0.0
    sy = 0.0
    sz = 0.0
    denom = 0.0
    for p in range(n):
        vol += sums[p, 0]
        sx += sums[p, 1]
        sy += sums[p, 2]
        sz += sums[p, 3]
        denom += sums[p, 4]
    ax, ay, az, ad = _group_sums(w, particles[pcuts[n]:pcuts[n + 1]], g)
    sx += ax
    sy += ay
    sz += az
    denom += ad
    s, f6, moved = _volume_scale(w, ref, vol, sx, sy, sz, denom, rest, k, c, lam, g, xpbd)
    if not defer:
        _volume_apply(x, w, particles, g, f6, moved)
    return s, f6, moved


@numba.njit(**PBD_NUMBA)
def _project_volume(x, w, pstart, particles, pcuts, cuts, tris, rstart, ref, rest, k, c, lam,
                    g, xpbd, start, stop):
    """Sweep over bodies ``start:stop`` in order (CSR starts ``pstart``, ``rstart``; body
    ``j``'s particles ``particles[pstart[j]:pstart[j + 1]]`` grouped by ``pcuts[j]`` (offsets
    in that slice), its rows of ``tris (f, 4)`` (:func:`pair_triangles`)
    ``cuts[j, 0]:cuts[j, -1]`` grouped by ``cuts[j]``; all ids global)."""
    for j in range(start, stop):
        lam[j] += _solve_volume(x, w, particles[pstart[j]:pstart[j + 1]], pcuts[j], tris, cuts[j],
                                ref[rstart[j]:rstart[j + 1]], rest[j], k[j], c[j], lam[j], g,
                                xpbd)


def localize(triangles: np.ndarray):
    """Split one body's ``triangles (f, 3)`` (global ids) into solver data.

    Returns ``(particles (p,) int64 global ids, local_triangles (f, 3) int64,
    reference (r,) int64 local ids)``.
    """
    t = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    particles, inverse = np.unique(t, return_inverse=True)
    local = inverse.reshape(-1, 3).astype(np.int64)
    ref = np.searchsorted(particles, reference_vertices(t)).astype(np.int64)
    return particles, local, ref


def solve_volume(positions, inv_mass, triangles, rest_volume, stiffness) -> np.ndarray:
    """One PBD projection of one body's volume constraint; returns new ``(n, 3)`` positions."""
    x = np.array(positions, dtype=np.float64, order="C")
    tris = np.ascontiguousarray(triangles, dtype=np.int64).reshape(-1, 3)
    if tris.size and (tris.min() < 0 or tris.max() >= len(x)):  # the kernel reads ids unsigned
        raise ValueError(f"particle ids outside [0, {len(x)})")
    particles, _, ref = localize(tris)
    rows = pair_triangles(tris)
    one = np.ones(1, dtype=np.float64)
    _project_volume(x, np.ascontiguousarray(inv_mass, dtype=np.float64),
                    np.array([0, len(particles)]), particles, np.array([[0, len(particles)]]),
                    np.array([[0, len(rows)]]), rows,
                    np.array([0, len(ref)]), particles[ref], np.array([float(rest_volume)]),
                    one * float(stiffness), one * 0.0, one * 0.0, np.zeros_like(x), False, 0, 1)
    return x
