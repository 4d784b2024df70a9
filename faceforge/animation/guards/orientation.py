"""Skin triangles keep their orientation (beyond the paper).

The §8 skin preserves each triangle's *unsigned* area: a triangle turned over
keeps its rest area and the area constraint (k 0.95) accepts it. Where the skin
is made of slivers (the lip corners of a dense head: triangles of 0.1-20 % of
the median area, nearly collinear in the plane of the lips' contact surface),
a small shear between neighbouring vertices turns them over. On the ICT head
this happens where the jaw drags the lower lip away from the upper lip: the
inner lip skin between them (the lip band, :func:`faceforge.skin.rules.lip_band`;
measured while it had no anchor of its own), carried by anchors on different bodies
(depressor labii and mandible below, orbicularis oris and cranium above), lags
behind the anchored skin while the jaw moves and overshoots when it stops; with the jaw wide open, the upper lip, dragged back
by the orbicularis oris, crushes its inner skin against the teeth.

:class:`OrientationGuard` is a pass over the skin positions after each PBD
step (like :class:`faceforge.animation.guards.skull.SkullGuard`): every triangle keeps
a signed area, measured along its rest normal ``n0``, of at least ``min_area``
times its rest area ``A0``::

    C(x) = 0.5 n0 . ((x1 - x0) x (x2 - x0)) - min_area * A0 >= 0

projected Gauss-Seidel with stiffness 1 and equal masses (the skin's; a
violated triangle is projected a quarter above its floor, :data:`AIM`), with the
gradients ``0.5 n0 x (x2 - x1)``, ``0.5 n0 x (x0 - x2)``, ``0.5 n0 x (x1 - x0)``
(or with per-vertex inverse masses ``w``, ``inv_mass``: each vertex moves ``w_k lambda g_k``
with ``lambda = -C / sum w_k |g_k|^2``; a vertex of ``w`` 0 is pinned, a triangle whose three
vertices are pinned is left as it is; equal masses of 1 are bit for bit the unweighted pass)
(they lie in the plane normal to ``n0``: the pass moves vertices sideways, it
does not lift them). Only triangles turned more than ``watch_angle`` from their
rest normal or below the floor are examined, so the pass costs one cross
product per triangle per frame when nothing is wrong, and a triangle that keeps
its orientation is never moved: the paper's skin stiffness values are
untouched. The rest normal is the reference because the head does not turn in
the simulation (the cranium is fixed; the jaw opens a few tens of degrees): a
triangle's normal more than 90 degrees from its rest normal is a fold, which is
also what :func:`faceforge.animation.checks.inverted_faces` counts. (A
reference turned with each triangle's neighbourhood, fitted by Kabsch on the
2- to 6-ring, was tried on ICT: the corner neighbourhoods deform far from
rigidly, the fitted rotations were 25-90 degrees for a 3-degree jaw opening,
and 20-55 triangles per frame stayed turned over.)
"""

from __future__ import annotations

import numba
import numpy as np

from faceforge.constants import FLOAT, INT, NUMBA_OPTIONS
from faceforge.pbd.model import inverse_masses

__all__ = ["OrientationGuard"]

#: a triangle below its floor is projected to (1 + AIM) times the floor: aiming exactly at
#: the floor, the next push of a neighbour re-triggers it and the sweeps go on (ICT fear.fap:
#: 3.3 million projections over the file with AIM 0, 12 thousand with 0.25, same result)
AIM = 0.25


@numba.njit(inline="always", **NUMBA_OPTIONS)
def _is_watched(x, faces, normal0, floor, cos_watch, t):  # pragma: no cover - numba
    """Whether triangle ``t`` of ``faces (m, 3)`` on ``x (n, 3)`` is turned more than the watch
    angle from its unit rest normal ``normal0[t]`` (``c . n0 <= cos_watch |c|``) or has a signed
    area along it below ``floor[t]``."""
    a, b, c = faces[t, 0], faces[t, 1], faces[t, 2]
    e1x, e1y, e1z = x[b, 0] - x[a, 0], x[b, 1] - x[a, 1], x[b, 2] - x[a, 2]
    e2x, e2y, e2z = x[c, 0] - x[a, 0], x[c, 1] - x[a, 1], x[c, 2] - x[a, 2]
    cx = e1y * e2z - e1z * e2y
    cy = e1z * e2x - e1x * e2z
    cz = e1x * e2y - e1y * e2x
    along = cx * normal0[t, 0] + cy * normal0[t, 1] + cz * normal0[t, 2]
    if 0.5 * along < floor[t]:
        return True
    # along <= cos_watch |c|, squared (no square root: a fifth of this test's time)
    cc = cos_watch * cos_watch * (cx * cx + cy * cy + cz * cz)
    if cos_watch >= 0.0:
        return along <= 0.0 or along * along <= cc
    return along < 0.0 and along * along >= cc


@numba.njit(**NUMBA_OPTIONS)
def _watched(x, faces, normal0, floor, cos_watch, active):  # pragma: no cover - numba
    """Indices (ascending) of the triangles ``faces (m, 3)`` of ``x (n, 3)`` that
    :func:`_is_watched` picks; ``active (m,)`` bool masks the rest."""
    out = np.empty(faces.shape[0], np.int64)
    k = 0
    for t in range(faces.shape[0]):
        if active[t] and _is_watched(x, faces, normal0, floor, cos_watch, t):
            out[k] = t
            k += 1
    return out[:k]


@numba.njit(**NUMBA_OPTIONS)
def _rewatched(x, faces, normal0, floor, cos_watch, active, rows, moved, vstart, vtris,
               mark):  # pragma: no cover - numba
    """:func:`_watched` of ``x (n, 3)`` when its last result was ``rows (k,)`` (ascending) and
    only the vertices ``moved (p,)`` (repeats allowed) have changed since: the triangles
    around them are tested again, every other triangle keeps its verdict. Same result as
    :func:`_watched`. ``vstart (n + 1,)``, ``vtris``: the triangles of each vertex
    (``vtris[vstart[v]:vstart[v + 1]]``); ``mark (m,)`` uint8 scratch, all 0 (left so)."""
    total = 0
    for i in range(moved.shape[0]):
        total += vstart[moved[i] + 1] - vstart[moved[i]]
    cand = np.empty(total, np.int64)
    nc = 0
    for i in range(moved.shape[0]):
        v = moved[i]
        for q in range(vstart[v], vstart[v + 1]):
            t = vtris[q]
            if mark[t] == 0:
                mark[t] = 1
                cand[nc] = t
                nc += 1
    for i in range(nc):
        t = cand[i]
        if active[t] and _is_watched(x, faces, normal0, floor, cos_watch, t):
            mark[t] = 2
    out = np.empty(rows.shape[0] + nc, np.int64)
    k = 0
    for i in range(rows.shape[0]):   # the old verdict of the triangles no moved vertex touches
        if mark[rows[i]] == 0:
            out[k] = rows[i]
            k += 1
    for i in range(nc):
        t = cand[i]
        if mark[t] == 2:
            out[k] = t
            k += 1
        mark[t] = 0
    return np.sort(out[:k])


@numba.njit(**NUMBA_OPTIONS)
def _project_signed_areas(x, tris, nref, floor, aim, iterations, hit, w, reach):  # pragma: no cover - numba
    """Gauss-Seidel over the triangles ``tris (k, 3)``: signed area along ``nref (k, 3)``
    (unit) at least ``floor (k,)``; a triangle below its floor is projected (linearised) to
    ``(1 + aim) floor``, so that the next small push of a neighbour does not bring it back
    below. ``w (n,)``: the vertices' inverse masses (>= 0; 0 pinned). ``reach (k,)``: no vertex
    moves farther than this in one projection (the step is scaled down to it: a triangle seen
    edge-on along its rest normal has gradients near 0, and the linearised step threw a vertex
    across the face).
    ``x (n, 3)`` in place; ``hit (k,)`` uint8 is set to 1 for each triangle projected
    at least once (its three vertices may have moved; the others' did not, unless shared).
    Returns how many projections moved a vertex."""
    moved = 0
    for _ in range(iterations):
        changed = 0
        for t in range(tris.shape[0]):
            a, b, c = tris[t, 0], tris[t, 1], tris[t, 2]
            n0, n1, n2 = nref[t, 0], nref[t, 1], nref[t, 2]
            e1x, e1y, e1z = x[b, 0] - x[a, 0], x[b, 1] - x[a, 1], x[b, 2] - x[a, 2]
            e2x, e2y, e2z = x[c, 0] - x[a, 0], x[c, 1] - x[a, 1], x[c, 2] - x[a, 2]
            s = 0.5 * (n0 * (e1y * e2z - e1z * e2y) + n1 * (e1z * e2x - e1x * e2z)
                       + n2 * (e1x * e2y - e1y * e2x))
            cval = s - floor[t]
            if cval >= 0.0:
                continue
            # gradients 0.5 n x (x_next2 - x_next1) for each corner
            g = np.empty((3, 3))
            for k in range(3):
                p = tris[t, (k + 1) % 3]
                q = tris[t, (k + 2) % 3]
                dx, dy, dz = x[q, 0] - x[p, 0], x[q, 1] - x[p, 1], x[q, 2] - x[p, 2]
                g[k, 0] = 0.5 * (n1 * dz - n2 * dy)
                g[k, 1] = 0.5 * (n2 * dx - n0 * dz)
                g[k, 2] = 0.5 * (n0 * dy - n1 * dx)
            denom = 0.0
            for k in range(3):
                denom += w[tris[t, k]] * (g[k, 0] * g[k, 0] + g[k, 1] * g[k, 1] + g[k, 2] * g[k, 2])
            if denom <= 1e-300:
                continue
            lam = -(cval - aim * floor[t]) / denom
            step = 0.0
            for k in range(3):
                m = w[tris[t, k]] * abs(lam) * np.sqrt(g[k, 0] * g[k, 0] + g[k, 1] * g[k, 1] + g[k, 2] * g[k, 2])
                step = max(step, m)
            if step > reach[t]:
                lam *= reach[t] / step
            for k in range(3):
                v = tris[t, k]
                if w[v] > 0.0:
                    wl = w[v] * lam
                    x[v, 0] += wl * g[k, 0]
                    x[v, 1] += wl * g[k, 1]
                    x[v, 2] += wl * g[k, 2]
            hit[t] = 1
            changed += 1
        moved += changed
        if changed == 0:
            break
    return moved


@numba.njit(**NUMBA_OPTIONS)
def _guard_rounds(x, faces, normal0, floor, cos_watch, active, rows, aim, rounds, iterations, vstart,
                  vtris, mark, w, reach):  # pragma: no cover - numba
    """The rounds of :meth:`OrientationGuard.apply` from ``rows``, the :func:`_watched` rows of
    ``x (n, 3)`` (in place): project them (:func:`_project_signed_areas`), test again around
    the projected triangles (:func:`_rewatched`), until a test finds nothing, a projection
    moves nothing or ``rounds`` are done. Returns ``(projections, rows, known, touched)``:
    ``rows`` is the last test's result, which holds for ``x`` as left when ``known``;
    ``touched``, a list of int64 arrays, holds every vertex that may have moved (repeats)."""
    moved = 0
    touched = [np.empty(0, np.int64)]
    for r in range(rounds):
        k = rows.shape[0]
        if k == 0:
            break
        tris = np.empty((k, 3), np.int64)
        nref = np.empty((k, 3))
        fl = np.empty(k)
        rc = np.empty(k)
        for i in range(k):
            t = rows[i]
            for d in range(3):
                tris[i, d] = faces[t, d]
                nref[i, d] = normal0[t, d]
            fl[i] = floor[t]
            rc[i] = reach[t]
        hit = np.zeros(k, np.uint8)
        done = _project_signed_areas(x, tris, nref, fl, aim, iterations, hit, w, rc)
        moved += done
        if done == 0:
            break
        verts = np.empty(3 * k, np.int64)
        nv = 0
        for i in range(k):
            if hit[i]:
                for d in range(3):
                    verts[nv] = tris[i, d]
                    nv += 1
        touched.append(verts[:nv])
        if r == rounds - 1:
            return moved, rows, False, touched      # moved after the last test
        rows = _rewatched(x, faces, normal0, floor, cos_watch, active, rows, verts[:nv], vstart, vtris, mark)
    return moved, rows, True, touched


class OrientationGuard:
    """Keeps every skin triangle from turning over (see the module docstring).

    Parameters
    ----------
    rest : (n, 3) float
        Skin at rest (the working mesh), skin units.
    faces : (m, 3) int
    min_area : float in [0, 1)
        Least signed area along the rest normal, as a fraction of the rest area
        (0.1: a triangle of rest area may turn up to ~84 degrees).
    watch_angle : float, degrees
        A triangle is examined when its normal turns more than this from its rest normal
        (or its area projected on the rest normal drops below the floor).
    rounds : int
        At most this many rounds (find the violated triangles, project them); a round
        ends the pass when nothing was violated. A frame that needs many costs them; the
        others stop after one or two. (8 left one triangle turned over in a weighted frame of
        calibrated ICT hate.fap: each round's projections pushed a neighbour below its floor;
        it was upright after 9.)
    iterations : int
        Gauss-Seidel sweeps per round.
    inv_mass : (n,) float >= 0, optional
        The vertices' inverse masses (0: pinned, the pass bends the skin around it; module
        docstring); None: all 1.
    reach : float, optional
        A projection moves no vertex farther than this many times its triangle's longest rest
        edge (the step is scaled down): on a triangle seen nearly edge-on along its rest normal
        the gradients are near 0 and the linearised step threw a vertex across the face. None:
        unbounded (a kinematic field that moves the skin far in one frame, the eyelids', needs
        its whole step).

    Triangles of zero rest area (numerically degenerate, area <= 1e-12 of the squared
    bounding-box diagonal) have no orientation and are left alone.
    """

    def __init__(self, rest, faces, min_area: float = 0.1, watch_angle: float = 60.0,
                 rounds: int = 32, iterations: int = 50, inv_mass=None, reach: float | None = None):
        if not 0.0 <= min_area < 1.0:
            raise ValueError(f"min_area must be in [0, 1), got {min_area}")
        self.rest = np.array(rest, dtype=FLOAT)
        self.inv_mass = inverse_masses(inv_mass, len(self.rest))
        self.faces = np.asarray(faces, dtype=INT)
        r = self.rest[self.faces]
        n0 = np.cross(r[:, 1] - r[:, 0], r[:, 2] - r[:, 0])
        two_a0 = np.linalg.norm(n0, axis=1)
        diag2 = float(np.sum(np.ptp(self.rest, axis=0) ** 2)) if len(self.rest) else 0.0
        self.active = 0.5 * two_a0 > 1e-12 * diag2
        self.normal0 = np.zeros_like(n0)
        self.normal0[self.active] = n0[self.active] / two_a0[self.active, None]
        self.area0 = 0.5 * two_a0
        self.floor = min_area * self.area0
        #: (m,) how far a projection may move a vertex of each triangle (inf: unbounded)
        self.reach = (np.full(len(self.faces), np.inf) if reach is None
                      else float(reach) * np.linalg.norm(r - np.roll(r, 1, axis=1), axis=2).max(axis=1))
        self.cos_watch = float(np.cos(np.radians(watch_angle)))
        self.rounds = int(rounds)
        self.iterations = int(iterations)
        # the triangles of each vertex (CSR), for the rescans of :meth:`apply`
        corner = self.faces.reshape(-1)
        self._vtris = (np.argsort(corner, kind="stable") // 3).astype(INT)
        self._vstart = np.concatenate([[0], np.cumsum(np.bincount(corner, minlength=len(self.rest)))]).astype(INT)
        self._mark = np.zeros(len(self.faces), np.uint8)
        self._last = None   # (array, rows): the watched rows of the array the last apply left
        self.touched = np.zeros(0, INT)

    def watched(self, positions) -> np.ndarray:
        """(m,) bool: triangles turned more than ``watch_angle`` from their rest normal, or
        whose area projected on it is below the floor."""
        t = np.asarray(positions, FLOAT)[self.faces]
        c = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        along = np.einsum("ij,ij->i", c, self.normal0)
        turned = along <= self.cos_watch * np.linalg.norm(c, axis=1)
        return self.active & (turned | (0.5 * along < self.floor))

    def apply(self, positions: np.ndarray, moved=None) -> int:
        """Project the watched triangles of ``positions`` ((n, 3) float64, C-contiguous,
        modified in place).

        ``moved`` (optional, (p,) int): the vertices of ``positions`` changed since the last
        call on this same array object returned; the first test then looks again only at the
        triangles around them (the others keep the last call's final verdict). After a
        projection, the next test likewise looks only around the projected triangles. Either
        way the rows tested and projected, hence the result, are those of a full test.

        Returns how many triangle projections moved vertices (0: no triangle was turned
        over or below its floor); :attr:`touched` then holds every vertex it may have moved
        ((p,) int, repeats allowed; the others kept their bits).
        """
        if positions.dtype != FLOAT or not positions.flags.c_contiguous:
            raise ValueError("positions must be a C-contiguous float64 array (modified in place)")
        last, self._last = self._last, None
        if moved is not None and last is not None and last[0] is positions:
            rows = self._rewatched(positions, last[1], np.asarray(moved, dtype=INT))
        else:
            rows = _watched(positions, self.faces, self.normal0, self.floor, self.cos_watch, self.active)
        if not len(rows):   # nothing to project (most frames)
            self._last = (positions, rows)
            self.touched = rows
            return 0
        done, rows, known, touched = _guard_rounds(
            positions, self.faces, self.normal0, self.floor, self.cos_watch, self.active, rows, AIM,
            self.rounds, self.iterations, self._vstart, self._vtris, self._mark, self.inv_mass, self.reach)
        if known:
            self._last = (positions, rows)
        self.touched = np.concatenate(touched)
        return int(done)

    def warm_up(self) -> None:
        """Compile (or load from numba's cache) every kernel :meth:`apply` may call, on a copy
        of the rest mesh, so none compiles in the middle of a playback (``_rewatched`` first ran
        at frame 9 of a first animate and made that frame take 2.75 s, issue 28). Leaves the
        guard as it was."""
        x = self.rest.copy()
        rows = _watched(x, self.faces, self.normal0, self.floor, self.cos_watch, self.active)
        _rewatched(x, self.faces, self.normal0, self.floor, self.cos_watch, self.active, rows,
                   np.zeros(0, INT), self._vstart, self._vtris, self._mark)
        _guard_rounds(x, self.faces, self.normal0, self.floor, self.cos_watch, self.active, rows, AIM,
                      1, 1, self._vstart, self._vtris, self._mark, self.inv_mass, self.reach)
        self._mark[:] = 0

    def _rewatched(self, positions, rows, moved) -> np.ndarray:
        return _rewatched(positions, self.faces, self.normal0, self.floor, self.cos_watch, self.active,
                          rows, moved, self._vstart, self._vtris, self._mark)
