"""Unilateral dihedral limit: quads whose two triangles may bend up to a limit, not past it.

A quad ``(p0, p1, p2, p3)`` as in :mod:`faceforge.pbd.constraints.bending` (``(p0, p1)`` the
shared edge, ``p2`` and ``p3`` the opposite vertices; its unsigned dihedral ``|theta|``, 0 flat,
pi folded flat onto itself). Seen along the edge, ``|theta| = pi - phi`` where ``phi`` is the
angle between the two *wings* ``w2``, ``w3`` (the parts of ``p2 - p0`` and ``p3 - p0``
perpendicular to the edge). When ``|theta|`` exceeds ``limit`` the projection turns both wings
about the edge's axis, apart, each by half the excess: ``p2`` and ``p3`` move on circles round
the edge, so the four edges of the two triangles keep their lengths and the edge itself does
not move; ``|theta|`` becomes ``limit``. Below the limit nothing moves (an inequality
constraint, C = |theta| - limit <= 0, projected at stiffness 1).

**Inverse masses.** As in any PBD constraint, the particles may carry inverse masses ``w``
(:func:`limit_dihedrals`' ``inv_mass``; all 1 by default): the excess is shared between the two
wings in proportion to their opposite vertices' ``w`` (``w2 / (w2 + w3)`` of it turns ``p2``), so a
pinned particle (``w`` 0) stays where it is and its partner's wing turns by the whole excess; a
quad whose ``p2`` and ``p3`` are both pinned is left as it is (turning the edge instead keeps
all six of the tetrahedron's lengths, hence the dihedral). Equal masses split it in halves,
bit for bit the unweighted projection.

It is applied after a solver step, as a contact would be, by :func:`limit_dihedrals`
(Gauss-Seidel over the quads, ``sweeps`` times: a vertex shared by several quads is moved by
each in turn). No velocities are touched (the caller steps quasi-statically). The numba kernel
has a plain-numpy twin in ``tests/pbd/test_dihedral_limit.py``. Knows nothing of faces: the
caller chooses the quads (:func:`faceforge.skin.fold_limit.fold_limits`).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from faceforge.constants import NUMBA_OPTIONS
from faceforge.pbd.model import checked_positions, inverse_masses

__all__ = ["DihedralLimit", "limit_dihedrals", "rest_limits"]


@numba.njit(**NUMBA_OPTIONS)
def _limit(p, quads, limit, below, sweeps, w, touched, tol, vst, qst, clock):  # pragma: no cover - numba
    """In place on ``p (n, 3)``: ``quads (m, 4)`` int64, ``limit (m,)`` radians in (0, pi),
    ``below (m,)`` = -cos(limit + tol), ``sweeps`` >= 1, ``w (n,)`` inverse masses >= 0;
    ``touched (n,)`` bool, set where a particle moved (or ``(0,)``: not recorded); ``tol``
    radians >= 0: an excess up to it is left. Returns the number of projections made.

    Incremental (``qst`` of length m; ``(0,)``: every quad checked): ``vst (n,)`` int64, the
    clock at which each particle last moved; ``qst (m,)`` int64, the clock at which each quad
    was last found with nothing to do (-1: never); ``clock (2,)`` int64, [0] advanced at each
    move, [1] counting the quads checked.
    A quad none of whose particles moved since it was found with nothing to do is skipped: its
    check reads the same bits and would find nothing again (:func:`_mark_changed` stamps what
    moved between calls), so the result is bit for bit a full pass's."""
    mark = touched.shape[0] > 0
    inc = qst.shape[0] > 0
    moved = 0
    for _ in range(sweeps):
        before = moved
        for j in range(quads.shape[0]):
            i0, i1, i2, i3 = quads[j, 0], quads[j, 1], quads[j, 2], quads[j, 3]
            if inc:
                q = qst[j]
                if q >= 0 and q >= vst[i0] and q >= vst[i1] and q >= vst[i2] and q >= vst[i3]:
                    continue
                qst[j] = clock[0]        # nothing to do unless it projects below
                clock[1] += 1            # quads checked
            wsum = w[i2] + w[i3]
            if wsum <= 0.0:
                continue
            ex = p[i1, 0] - p[i0, 0]
            ey = p[i1, 1] - p[i0, 1]
            ez = p[i1, 2] - p[i0, 2]
            ee = ex * ex + ey * ey + ez * ez
            if ee <= 0.0:
                continue
            # most quads are well within their limit: the wings' cosine against -cos(limit + tol)
            # without a square root per wing or an arc cosine
            rx, ry, rz = p[i2, 0] - p[i0, 0], p[i2, 1] - p[i0, 1], p[i2, 2] - p[i0, 2]
            s2 = (rx * ex + ry * ey + rz * ez) / ee
            w2x, w2y, w2z = rx - s2 * ex, ry - s2 * ey, rz - s2 * ez
            rx, ry, rz = p[i3, 0] - p[i0, 0], p[i3, 1] - p[i0, 1], p[i3, 2] - p[i0, 2]
            s3 = (rx * ex + ry * ey + rz * ez) / ee
            w3x, w3y, w3z = rx - s3 * ex, ry - s3 * ey, rz - s3 * ez
            if w2x * w3x + w2y * w3y + w2z * w3z <= below[j] * math.sqrt(
                    (w2x * w2x + w2y * w2y + w2z * w2z) * (w3x * w3x + w3y * w3y + w3z * w3z)):
                continue
            el = math.sqrt(ee)
            ax, ay, az = ex / el, ey / el, ez / el
            # wings: perpendicular parts of p2 - p0 and p3 - p0
            rx, ry, rz = p[i2, 0] - p[i0, 0], p[i2, 1] - p[i0, 1], p[i2, 2] - p[i0, 2]
            s2 = rx * ax + ry * ay + rz * az
            w2x, w2y, w2z = rx - s2 * ax, ry - s2 * ay, rz - s2 * az
            rx, ry, rz = p[i3, 0] - p[i0, 0], p[i3, 1] - p[i0, 1], p[i3, 2] - p[i0, 2]
            s3 = rx * ax + ry * ay + rz * az
            w3x, w3y, w3z = rx - s3 * ax, ry - s3 * ay, rz - s3 * az
            l2 = math.sqrt(w2x * w2x + w2y * w2y + w2z * w2z)
            l3 = math.sqrt(w3x * w3x + w3y * w3y + w3z * w3z)
            if l2 <= 1e-12 * el or l3 <= 1e-12 * el:
                continue
            u2x, u2y, u2z = w2x / l2, w2y / l2, w2z / l2
            u3x, u3y, u3z = w3x / l3, w3y / l3, w3z / l3
            c = u2x * u3x + u2y * u3y + u2z * u3z
            c = min(1.0, max(-1.0, c))
            phi = math.acos(c)
            excess = (math.pi - limit[j]) - phi
            if excess <= tol:
                continue
            # each wing's share of the excess (equal masses: half each)
            h3 = excess * (w[i3] / wsum)
            h2 = excess * (w[i2] / wsum)
            # b3 = a x u3: p3 turns towards -b3 when u2 lies on +b3's side (away from u2)
            b3x, b3y, b3z = ay * u3z - az * u3y, az * u3x - ax * u3z, ax * u3y - ay * u3x
            t3 = -h3 if (u2x * b3x + u2y * b3y + u2z * b3z) >= 0.0 else h3
            b2x, b2y, b2z = ay * u2z - az * u2y, az * u2x - ax * u2z, ax * u2y - ay * u2x
            t2 = -h2 if (u3x * b2x + u3y * b2y + u3z * b2z) > 0.0 else h2
            c3, n3 = math.cos(t3), math.sin(t3)
            c2, n2 = math.cos(t2), math.sin(t2)
            if mark:
                touched[i2] = touched[i2] or w[i2] > 0.0
                touched[i3] = touched[i3] or w[i3] > 0.0
            if inc:
                qst[j] = -1              # projected: checked again at the next visit
                clock[0] += 1
                if w[i2] > 0.0:
                    vst[i2] = clock[0]
                if w[i3] > 0.0:
                    vst[i3] = clock[0]
            if w[i3] > 0.0:   # a pinned particle keeps its bits
                p[i3, 0] = p[i0, 0] + s3 * ax + l3 * (c3 * u3x + n3 * b3x)
                p[i3, 1] = p[i0, 1] + s3 * ay + l3 * (c3 * u3y + n3 * b3y)
                p[i3, 2] = p[i0, 2] + s3 * az + l3 * (c3 * u3z + n3 * b3z)
            if w[i2] > 0.0:
                p[i2, 0] = p[i0, 0] + s2 * ax + l2 * (c2 * u2x + n2 * b2x)
                p[i2, 1] = p[i0, 1] + s2 * ay + l2 * (c2 * u2y + n2 * b2y)
                p[i2, 2] = p[i0, 2] + s2 * az + l2 * (c2 * u2z + n2 * b2z)
            moved += 1
        if moved == before:   # a sweep with nothing to do: the next would find nothing either
            break
    return moved


@numba.njit(**NUMBA_OPTIONS)
def _mark_changed(bits, snap, vst, clock):  # pragma: no cover - numba
    """Stamp the particles whose position bits changed since the last call: ``bits (n, 3)`` int64
    (the positions viewed as integers), ``snap (n, 3)`` int64 (the bits seen last, updated in
    place), ``vst (n,)`` int64 set to the advanced ``clock[0]`` where they differ. Returns the
    number of particles that changed."""
    clock[0] += 1
    now = clock[0]
    changed = 0
    for i in range(bits.shape[0]):
        if bits[i, 0] != snap[i, 0] or bits[i, 1] != snap[i, 1] or bits[i, 2] != snap[i, 2]:
            vst[i] = now
            snap[i, 0], snap[i, 1], snap[i, 2] = bits[i, 0], bits[i, 1], bits[i, 2]
            changed += 1
    return changed


class DihedralLimit:
    """A dihedral limit over fixed quads, checked once and applied as often as needed (a solver
    applies it after every step: :func:`limit_dihedrals` checks and converts its arguments on
    each call, which cost as much as the pass itself over a whole skin).

    quads : (m, 4) int (particle ids; (p0, p1) the shared edge); limit : radians in (0, pi), one
    for all or (m,) per quad (:func:`rest_limits`: never below a quad's rest angle); n : the
    number of particles of the positions it will be applied to; inv_mass : (n,) float >= 0, the
    particles' inverse masses (0: pinned; module docstring), None: all 1; tol : radians >= 0, a
    quad past its limit by at most this is left as it is (neighbouring quads projected in turn
    keep nudging each other a hair past; a caller that repeats the pass until it has nothing to
    do needs a tolerance to stop); incremental : check again only the quads one of whose particles
    moved since they were last found within their limit (the same bits, the same projections: a
    caller applying it many times a frame to a mostly still skin pays for what moved).
    """

    def __init__(self, quads: np.ndarray, limit, n: int, inv_mass: np.ndarray | None = None,
                 tol: float = 0.0, incremental: bool = False):
        self.quads = np.ascontiguousarray(quads, dtype=np.int64).reshape(-1, 4)
        self.limit = np.ascontiguousarray(np.broadcast_to(np.asarray(limit, dtype=np.float64),
                                                          (len(self.quads),)))
        if not np.all((self.limit > 0.0) & (self.limit < math.pi)):
            raise ValueError(f"limit must be in (0, pi) radians, got {limit}")
        if len(self.quads) and (self.quads.min() < 0 or self.quads.max() >= n):
            raise ValueError(f"quads index particles outside [0, {n})")
        if not tol >= 0.0:
            raise ValueError(f"tol must be >= 0 radians, got {tol}")
        self.n, self.tol = int(n), float(tol)
        self.inv_mass = inverse_masses(inv_mass, self.n)
        self._below = -np.cos(np.minimum(self.limit + self.tol, math.pi))
        #: incremental: a quad is checked again only once one of its particles moved (its
        #: previous check found nothing to do on the same bits; bit for bit a full pass)
        self.incremental = bool(incremental)
        none = np.zeros(0, dtype=np.int64)
        self._clock = np.zeros(2, dtype=np.int64)      # [0] the moves' clock, [1] quads checked
        self._vst = np.zeros(self.n, dtype=np.int64) if incremental else none
        self._qst = np.full(len(self.quads), -1, dtype=np.int64) if incremental else none
        self._snap = np.zeros((self.n, 3), dtype=np.int64) if incremental else none.reshape(0, 3)

    @property
    def checked(self) -> int:
        """Quads checked so far by an incremental limit (skipped ones not counted; 0 otherwise)."""
        return int(self._clock[1])

    def set_limit(self, limit) -> None:
        """Hold the quads to ``limit`` from now on (radians in (0, pi), one for all or (m,) per quad), as the
        constructor's; an incremental limit checks every quad again at its next pass."""
        limit = np.ascontiguousarray(np.broadcast_to(np.asarray(limit, dtype=np.float64), (len(self.quads),)))
        if not np.all((limit > 0.0) & (limit < math.pi)):
            raise ValueError(f"limit must be in (0, pi) radians, got {limit}")
        self.limit = limit
        self._below = -np.cos(np.minimum(self.limit + self.tol, math.pi))
        if self.incremental:
            self._qst[:] = -1

    def __call__(self, positions: np.ndarray, sweeps: int = 2, touched: np.ndarray | None = None) -> int:
        """Keep every quad's unsigned dihedral at most its limit (+ tol), in place on
        ``positions`` ((n, 3) float64, C-contiguous), in at most ``sweeps`` Gauss-Seidel passes (a
        pass that projects nothing ends them). ``touched`` (n,) bool, optional: set True (never
        cleared) where a particle moved. Returns the number of projections made (0: every quad
        was within its limit or could not move)."""
        touched = checked_positions(positions, touched, self.n)
        if not len(self.quads):
            return 0
        if self.incremental:
            _mark_changed(positions.view(np.int64), self._snap, self._vst, self._clock)
        return int(_limit(positions, self.quads, self.limit, self._below, int(sweeps), self.inv_mass,
                          touched, self.tol, self._vst, self._qst, self._clock))


def limit_dihedrals(positions: np.ndarray, quads: np.ndarray, limit, sweeps: int = 2,
                    inv_mass: np.ndarray | None = None, touched: np.ndarray | None = None,
                    tol: float = 0.0) -> int:
    """Keep the unsigned dihedral of every quad at most ``limit`` (see the module docstring and
    :class:`DihedralLimit`, whose arguments these are; positions (n, 3) float64, C-contiguous,
    changed in place). Returns the number of projections made."""
    if positions.dtype != np.float64 or positions.ndim != 2 or positions.shape[1] != 3 \
            or not positions.flags.c_contiguous:
        raise ValueError("positions must be a C-contiguous (n, 3) float64 array")
    return DihedralLimit(quads, limit, len(positions), inv_mass, tol)(positions, sweeps, touched)


def rest_limits(rest: np.ndarray, quads: np.ndarray, limit) -> np.ndarray:
    """(m,) radians: ``limit`` (radians, one for all or (m,) per quad) for each quad, or its
    unsigned dihedral in ``rest (n, 3)`` where that is larger (a quad bent past the limit at rest
    may stay as bent; rest stays a fixed point)."""
    from faceforge.pbd.constraints.bending import dihedral_angle

    q = np.asarray(quads, dtype=np.int64).reshape(-1, 4)
    return np.minimum(np.maximum(np.asarray(limit, dtype=np.float64), np.abs(dihedral_angle(rest, q))),
                      math.pi - 1e-9)
