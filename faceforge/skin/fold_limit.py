"""Skin that creases but does not fold over (``skin.fold_deg``, beyond §8).

Skin is a sheet a few mm thick: it wrinkles and creases, but it does not fold flat onto itself.
The §8 layer's bending constraint only pulls each edge back toward its rest dihedral, with the
rest of the solver (the anchors, the stretch) and the guards after it (the skull guard pushing
vertices out along the bone's normals, the bone collision) free to bend an edge past 90 deg: the
jaw's opening folded the upper lids of the ICT sample, the pucker its upper lip, each guard's
push a quad or two where it moved one vertex (docs/notes/foldlimit13.md).

**The influence map's blend** ``rest + w (skin - rest)`` (the weighted frame) can bend a quad
the simulation kept within its limit: where ``w`` differs across a quad that moved far, each
vertex is pulled back toward rest by its own share (ICT's jawOpen: two quads at the jaw's angle,
bent 66 and 77 deg in the simulation, 107 and 92 deg weighted, one vertex of each at ``w`` 0.974).
Limiting the weighted frame's dihedrals turned skin into the skull (the limit turns the wings,
and no bone guard runs on the weighted frame). :class:`BlendLimit` instead raises the blend's
weights, on the four vertices of each quad the blend bends past its limit, toward 1 (toward the
simulated skin, which the guards have kept out of the bones) just far enough: each vertex stays on
the segment between its rest place and its simulated place.

:func:`fold_limits` picks the skin's bending quads that are flat at rest (bent less than
:data:`FLAT_DEG`) and gives each the limit ``skin.fold_deg``, and the quads across the lip line
at the lip corners (:func:`faceforge.skin.lip_contact.commissure_quads`) the tighter
``skin.commissure_fold_deg``. The skin layer keeps them within it after each solver step and
the guards' alternation after each of its passes (:class:`faceforge.skin.layer.SkinSimulation`,
:mod:`faceforge.animation.guards.alternate`;
the projection itself is :func:`faceforge.pbd.dihedral_limit.limit_dihedrals`, which turns the
two wings about their shared edge and keeps every edge length). Quads already bent at rest
(nostril rims, the lid creases, the lip line) are left to the bending constraint: they crease
by nature.
"""

from __future__ import annotations

import numpy as np

__all__ = ["FLAT_DEG", "BlendLimit", "fold_limits"]

#: quads bent less than this at rest (degrees) are the skin's flat sheet, the ones the fold limit
#: holds (the lids' limit uses the same, :data:`faceforge.animation.lid_folds.FOLD_FLAT_DEG`)
FLAT_DEG = 60.0


def fold_limits(rest, faces, fold_deg: float, commissure=None, commissure_deg: float = 0.0,
                flat_deg: float = FLAT_DEG):
    """``(quads (m, 4) int64, limits (m,) radians)`` the skin may not bend past, or None when
    there are none.

    rest (n, 3) skin positions; faces (f, 3); fold_deg: the limit (degrees, 0: off) of every
    bending quad (:func:`faceforge.skin.layer.skin_topology`) bent less than ``flat_deg`` at rest;
    commissure (c, 4) int quads (optional) held within ``commissure_deg`` (degrees, 0: off), or
    the smaller of the two where both apply. Each quad appears once. A quad's limit is never
    below its rest dihedral (:func:`faceforge.pbd.dihedral_limit.rest_limits`, applied by the
    skin layer).
    """
    from faceforge.pbd.constraints.bending import dihedral_angle
    from faceforge.skin.layer import skin_topology

    quads = np.asarray(skin_topology(faces).bending_quads, np.int64).reshape(-1, 4)
    limits = np.full(len(quads), np.inf)
    if fold_deg and float(fold_deg) > 0:
        flat = np.abs(dihedral_angle(np.asarray(rest, float), quads)) < np.radians(flat_deg)
        limits[flat] = np.radians(float(fold_deg))
    c = np.zeros((0, 4), np.int64) if commissure is None else np.asarray(commissure, np.int64).reshape(-1, 4)
    if len(c) and commissure_deg and float(commissure_deg) > 0:
        row = {tuple(q): i for i, q in enumerate(quads.tolist())}
        at = np.array([row[tuple(q)] for q in c.tolist()], dtype=np.int64)
        limits[at] = np.minimum(limits[at], np.radians(float(commissure_deg)))
    keep = np.isfinite(limits)
    return (np.ascontiguousarray(quads[keep]), limits[keep]) if keep.any() else None


#: bisection steps of :class:`BlendLimit` on a weight raise (the raise is found within 2^-STEPS
#: of the least that keeps the quad or triangle within its bound, erring toward the simulation)
BLEND_STEPS = 10

#: rounds of :class:`BlendLimit`: a raise on one quad changes its neighbours; each round looks again
#: only at the quads (and triangles) around the vertices raised in the round before
BLEND_ROUNDS = 8


class BlendLimit:
    """A per-vertex blend ``rest + w (skin - rest)`` kept within the skin's fold limit (module
    docstring), and optionally its triangles upright: in a blended frame, every quad of ``quads``
    bent past its limit (and past its dihedral in ``skin``, when that is already past), and every
    triangle of ``faces`` whose signed area along its rest normal is below ``min_area`` x its rest
    area (and below its area in ``skin``), has the weights of its vertices raised toward 1,
    ``w + s (1 - w)`` with the least ``s`` in [0, 1] (bisection, :data:`BLEND_STEPS`) that brings
    it back within; at ``s`` 1 it is ``skin``'s own. Each vertex moves by its weight's raise times
    ``skin - rest``, so a vertex whose weight is 1 never moves: other passes' changes to the frame
    elsewhere are kept.

    Two blends use it: the influence map's weighted frame (``skin`` the simulated skin, ``weights``
    the map; :class:`faceforge.animation.playback.Rig`'s ``blend``), and the eyelids' take-back of a
    moving jaw's drift (``skin`` the simulated frame, ``w`` one less the share taken back, given per
    call, where the lids' guard and limit left the skin folded or turned over;
    :class:`faceforge.animation.eyelids.Eyelids`).

    rest (n, 3) skin at rest; weights (n,) in [0, 1]: the blend's weights, or where a per-call
    blend may go below 1 (only quads and triangles with a vertex below 1 are looked at, and with
    the weights fixed, one above 0 too); quads (m, 4) int and limits (m,) radians
    (:func:`fold_limits`; each never below the quad's rest dihedral); faces (f, 3) int or None;
    min_area: the triangles' floor, a fraction of their rest area.
    """

    def __init__(self, rest, weights, quads, limits, tol: float = 1e-3, faces=None, min_area: float = 0.0):
        from faceforge.pbd.dihedral_limit import DihedralLimit, rest_limits

        self.rest = np.asarray(rest, dtype=np.float64).reshape(-1, 3)
        self.weights = np.asarray(weights, dtype=np.float64).reshape(-1)
        n = len(self.rest)
        q = np.asarray(quads, dtype=np.int64).reshape(-1, 4)
        wq = self.weights[q]
        keep = (wq.min(axis=1) < 1.0) & (wq.max(axis=1) > 0.0)
        self.quads = np.ascontiguousarray(q[keep])
        self.limits = rest_limits(self.rest, self.quads, np.broadcast_to(limits, (len(q),))[keep]) \
            if len(self.quads) else np.zeros(0)
        self.tol = float(tol)
        t = np.zeros((0, 3), np.int64) if faces is None else np.asarray(faces, dtype=np.int64).reshape(-1, 3)
        t = t[(self.weights[t].min(axis=1) < 1.0) & (self.weights[t].max(axis=1) > 0.0)] if len(t) else t
        self.faces = np.ascontiguousarray(t)
        r = self.rest[t]
        c = np.cross(r[:, 1] - r[:, 0], r[:, 2] - r[:, 0])
        a = np.linalg.norm(c, axis=1)
        self._normal = c / np.where(a > 0, a, 1.0)[:, None]
        self._floor = float(min_area) * 0.5 * a
        # the first look at the quads, every frame: the dihedral limit's own pass (its cheap cosine
        # test) on a scratch copy; the quads round the particles it would move are then measured
        self._check = DihedralLimit(self.quads, self.limits, n, tol=self.tol) if len(self.quads) else None
        self._scratch = np.empty_like(self.rest)
        self._mark = np.zeros(n, dtype=bool)
        self._qstart, self._qof = _incidence(self.quads, n)
        self._tstart, self._tof = _incidence(self.faces, n)
        #: the vertices the last call raised, (p,) int
        self.raised = np.zeros(0, dtype=np.int64)

    def _area(self, x, rows):
        """(k,) signed areas of the triangles ``rows`` of :attr:`faces` on ``x (n, 3)`` along their rest normals."""
        p = x[self.faces[rows]]
        return 0.5 * np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), self._normal[rows])

    def below(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(rows of :attr:`quads` bent past their limit, rows of :attr:`faces` whose signed area along
        the rest normal is below their floor) in ``x (n, 3)``."""
        from faceforge.pbd.constraints.bending import dihedral_angle

        q, t = np.arange(len(self.quads)), np.arange(len(self.faces))
        return (q[np.abs(dihedral_angle(x, self.quads)) > self.limits + self.tol] if len(q) else q,
                t[self._area(x, t) < self._floor])

    def __call__(self, frame: np.ndarray, skin: np.ndarray, weights=None, look=None) -> int:
        """In place on the blended ``frame (n, 3)`` of ``skin (n, 3)`` (``weights (n,)``: this blend's,
        None: the constructor's; ``look``: (rows of :attr:`quads`, rows of :attr:`faces`) to look at
        first, None: all);
        returns the number of quads and triangles whose weights were raised (0: the blend bent none
        past its limit nor turned one over, ``frame`` is untouched)."""
        from faceforge.pbd.constraints.bending import dihedral_angle

        self.raised = np.zeros(0, dtype=np.int64)
        quads = np.zeros(0, dtype=np.int64) if look is None else np.asarray(look[0], dtype=np.int64)
        if self._check is not None and look is None:
            np.copyto(self._scratch, frame)
            self._mark[:] = False
            if self._check(self._scratch, sweeps=1, touched=self._mark):
                quads = _around(self._qstart, self._qof, np.flatnonzero(self._mark))
        tris = np.arange(len(self.faces)) if look is None else np.asarray(look[1], dtype=np.int64)
        w0 = self.weights if weights is None else np.asarray(weights, dtype=np.float64)
        w, done = None, 0
        skin = np.asarray(skin, dtype=np.float64)
        for _ in range(BLEND_ROUNDS):
            qo = quads[np.abs(dihedral_angle(frame, self.quads[quads])) > self.limits[quads] + self.tol]
            to = tris[self._area(frame, tris) < self._floor[tris]]
            if not len(qo) and not len(to):
                break
            if w is None:
                w = w0.copy()
            qt = np.maximum(self.limits[qo], np.abs(dihedral_angle(skin, self.quads[qo]))) + self.tol
            tt = np.minimum(self._floor[to], self._area(skin, to))
            jobs = [(self.quads[j], lambda p, t=t: abs(dihedral_angle(p, _QUAD)[0]) <= t) for j, t in zip(qo, qt)]
            jobs += [(self.faces[j], lambda p, j=j, t=t: self._tri_area(p, j) >= t) for j, t in zip(to, tt)]
            moved = []
            for v, ok in jobs:
                if ok(frame[v]):   # an earlier raise this round brought it back
                    continue
                wv, p0, d = w[v], frame[v], skin[v] - self.rest[v]
                lo, hi = 0.0, 1.0
                for _ in range(BLEND_STEPS):
                    s = 0.5 * (lo + hi)
                    lo, hi = (lo, s) if ok(p0 + (s * (1.0 - wv))[:, None] * d) else (s, hi)
                frame[v] = p0 + (hi * (1.0 - wv))[:, None] * d
                w[v] = wv + hi * (1.0 - wv)
                moved.append(v)
                done += 1
            if not moved:
                break
            raised = np.unique(np.concatenate(moved))
            self.raised = np.union1d(self.raised, raised)
            quads = _around(self._qstart, self._qof, raised)
            tris = _around(self._tstart, self._tof, raised)
        return done

    def _tri_area(self, p, j) -> float:
        """Signed area of ``p (3, 3)`` along triangle ``j``'s rest normal."""
        return 0.5 * float(np.cross(p[1] - p[0], p[2] - p[0]) @ self._normal[j])


def _incidence(cells: np.ndarray, n: int):
    """(start (n + 1,), cell of each slot): the cells ((k, c) int) round each vertex."""
    v = cells.reshape(-1)
    order = np.argsort(v, kind="stable")
    return np.searchsorted(v[order], np.arange(n + 1)), order // max(cells.shape[1], 1)


def _around(start, cell_of, vertices) -> np.ndarray:
    """(k,) sorted ids of the cells that hold any of ``vertices``."""
    parts = [cell_of[start[v]:start[v + 1]] for v in vertices]
    return np.unique(np.concatenate(parts)) if parts else np.zeros(0, dtype=np.int64)


_QUAD = np.arange(4, dtype=np.int64).reshape(1, 4)
