"""Position targets of every linear muscle of a layer in one compiled call (§5.1.2, Eq. 3, Eq. 4).

Each frame, every linear muscle resamples its four action lines on the current deeper
layers (A0 and A2 at the step ``1 - c kappa`` of Eq. 4, A3 and A1 at the full step), moves
its insertion with the ends of the two fibres, and hands the contour samples to its
bottom particles as position targets; its interior bottom particles get the blend of
their row's two side samples plus their rest offset in the row's basis
(:func:`faceforge.anatomy.muscles.linear.interior_targets`). :meth:`faceforge.anatomy.muscles.muscle.
Muscle.targets_from_line_points` is the plain twin. Done muscle by muscle in numpy that is ~35
small array operations per muscle, ~0.9 ms a frame for the 25 sheets of the default map;
:class:`LinearTargets` does the same arithmetic, in the same order (so the same bits), for
all of a layer's linear muscles in one numba kernel.

Layout (CSR over the layer's linear muscles, ``q`` of them):

* ``lines (q, 4, 2)`` start and stop rows of A0, A1, A2, A3 in the layer's gathered surface
  points ``pts (k, 3)``;
* ``hw (q, 2)`` samples along the fibres and across them; ``kappa (q,)`` fibre shortening
  at c = 1;
* ``cells (t, 2)`` grid cells ``(i, j)`` of every muscle's bound particles (its contour,
  then its interior ones), one muscle after another, and ``cell_start (q + 1,)``; the
  targets come out in the same rows, ``(t, 3)``; ``offsets (t, 3)`` the rest offsets of the
  interior rows in their row's basis (:attr:`faceforge.anatomy.muscles.muscle.Muscle.interior`),
  zero on the contour rows.
"""

from __future__ import annotations

import numba
import numpy as np

from faceforge.anatomy.muscles.action_line import _polyline_samples
from faceforge.constants import FLOAT, INT, NUMBA_OPTIONS

__all__ = ["LinearTargets", "bary_points"]

#: order of the four action lines in ``lines``
LINE_KEYS = ("A0", "A1", "A2", "A3")


@numba.njit(**NUMBA_OPTIONS)
def _linear_targets(pts, lines, hw, kappa, cells, cell_start, offsets, c, active, scratch, out):
    """Fill ``out (t, 3)`` with every muscle's targets (see the module docstring).

    ``c (q,)``: contractions, clipped here to [0, 1] (as ``np.clip``: NaN stays NaN), 0 where
    ``active (q,)`` is False; ``scratch (4, >= max(h, w), 3)``: the four sampled lines."""
    for m in range(len(kappa)):
        h, w = hw[m, 0], hw[m, 1]
        cm = c[m]
        if not active[m]:
            cm = 0.0
        elif cm < 0.0:
            cm = 0.0
        elif cm > 1.0:
            cm = 1.0
        scale = 1.0 - cm * kappa[m]
        a0 = scratch[0, :h]
        a2 = scratch[1, :h]
        a1 = scratch[2, :w]
        a3 = scratch[3, :w]
        _polyline_samples(pts[lines[m, 0, 0]:lines[m, 0, 1]], h, False, scale, a0)
        _polyline_samples(pts[lines[m, 2, 0]:lines[m, 2, 1]], h, False, scale, a2)
        _polyline_samples(pts[lines[m, 3, 0]:lines[m, 3, 1]], w, False, 1.0, a3)
        _polyline_samples(pts[lines[m, 1, 0]:lines[m, 1, 1]], w, False, 1.0, a1)
        if cm > 0.0:  # the insertion travels with the ends of the two fibres
            e0 = lines[m, 0, 1] - 1
            e2 = lines[m, 2, 1] - 1
            step = 1.0 / (w - 1)
            for j in range(w):
                t = j * step if j < w - 1 else 1.0       # numpy.linspace(0, 1, w)
                for d in range(3):   # numpy's order: (a1 + (1 - t) d0) + t d2
                    a1[j, d] = (a1[j, d] + (1.0 - t) * (a0[h - 1, d] - pts[e0, d])) \
                        + t * (a2[h - 1, d] - pts[e2, d])
        for r in range(cell_start[m], cell_start[m + 1]):
            i, j = cells[r, 0], cells[r, 1]
            if 0 < i < h - 1 and 0 < j < w - 1:
                _interior_target(a0, a2, i, j * (1.0 / (w - 1)), offsets[r], out[r])
                continue
            # the grid's borders, written as the twin does: A3, A1, then A0 and A2 over the corners
            if j == 0:
                src, k = a0, i
            elif j == w - 1:
                src, k = a2, i
            elif i == 0:
                src, k = a3, j
            else:
                src, k = a1, j
            for d in range(3):
                out[r, d] = src[k, d]


@numba.njit(**NUMBA_OPTIONS)
def _bary_points(bary, ids, v, out):  # pragma: no cover - numba
    """``out[i] = bary[i, 0] v[ids[i, 0]] + bary[i, 1] v[ids[i, 1]] + bary[i, 2] v[ids[i, 2]]``,
    left to right: the bits of ``np.einsum("ij,ijk->ik", bary, v[ids])`` (its plain twin in
    the tests) without the ``(k, 3, 3)`` gathered copy."""
    for i in range(ids.shape[0]):
        a, b, c = ids[i, 0], ids[i, 1], ids[i, 2]
        for d in range(3):
            out[i, d] = bary[i, 0] * v[a, d] + bary[i, 1] * v[b, d] + bary[i, 2] * v[c, d]


def bary_points(bary: np.ndarray, ids: np.ndarray, vertices: np.ndarray,
                out: np.ndarray | None = None) -> np.ndarray:
    """Surface points ``(k, 3)`` from barycentric coordinates ``bary (k, 3)`` float64 on the
    triangles ``ids (k, 3)`` int64 (vertex ids, all in range) of ``vertices (n, 3)`` float64,
    one compiled pass (:func:`_bary_points`; same bits as the einsum). ``out`` (k, 3) float64,
    filled and returned when given."""
    if bary.shape != ids.shape or ids.ndim != 2 or ids.shape[1] != 3:
        raise ValueError(f"bary {bary.shape} and ids {ids.shape} must both be (k, 3)")
    if out is None:
        out = np.empty((len(ids), 3))
    _bary_points(bary, ids, vertices, out)
    return out


@numba.njit(**NUMBA_OPTIONS)
def _interior_target(a0, a2, i, t, k, out):
    """``out (3,)``: the interior target of row ``i`` at ``t`` (muscle.interior_targets, same
    arithmetic in the same order; ``t = j / (w - 1)`` as numpy.linspace for 0 < j < w - 1)."""
    u0, u1, u2 = a2[i, 0] - a0[i, 0], a2[i, 1] - a0[i, 1], a2[i, 2] - a0[i, 2]
    v0 = ((a0[i + 1, 0] - a0[i - 1, 0]) + (a2[i + 1, 0] - a2[i - 1, 0])) * 0.25
    v1 = ((a0[i + 1, 1] - a0[i - 1, 1]) + (a2[i + 1, 1] - a2[i - 1, 1])) * 0.25
    v2 = ((a0[i + 1, 2] - a0[i - 1, 2]) + (a2[i + 1, 2] - a2[i - 1, 2])) * 0.25
    n0, n1, n2 = u1 * v2 - u2 * v1, u2 * v0 - u0 * v2, u0 * v1 - u1 * v0
    nn = max(np.sqrt((n0 * n0 + n1 * n1) + n2 * n2), 1e-300)
    n0, n1, n2 = n0 / nn, n1 / nn, n2 / nn
    out[0] = ((1.0 - t) * a0[i, 0] + t * a2[i, 0]) + ((k[0] * u0 + k[1] * v0) + k[2] * n0)
    out[1] = ((1.0 - t) * a0[i, 1] + t * a2[i, 1]) + ((k[0] * u1 + k[1] * v1) + k[2] * n1)
    out[2] = ((1.0 - t) * a0[i, 2] + t * a2[i, 2]) + ((k[0] * u2 + k[1] * v2) + k[2] * n2)


class LinearTargets:
    """The compiled target plan of a layer's linear muscles.

    Parameters
    ----------
    muscles : list of :class:`~faceforge.anatomy.muscles.muscle.Muscle` (the linear ones of a layer)
    pieces : list of ``{line key: slice}``, each muscle's rows in the layer's gathered points
    slots : list of ``(s_i,)`` int arrays, each muscle's position slots in the layer's Control

    Attributes
    ----------
    slots : (t,) int, the position slots of every target row, in muscle order
    """

    def __init__(self, muscles, pieces, slots):
        self.names = [m.name for m in muscles]
        self.active = np.array([m.active for m in muscles], dtype=bool)
        q = len(muscles)
        self.lines = np.zeros((q, 4, 2), dtype=INT)
        for i, own in enumerate(pieces):
            for k, key in enumerate(LINE_KEYS):
                self.lines[i, k] = own[key].start, own[key].stop
        self.hw = np.array([[m.topology.h, m.topology.w] for m in muscles], dtype=INT).reshape(q, 2)
        self.kappa = np.array([m.max_contraction for m in muscles], dtype=FLOAT)
        grids = [m.bound_grid for m in muscles]
        self.cells = np.ascontiguousarray(np.concatenate(grids) if grids else np.zeros((0, 2)), dtype=INT)
        self.cell_start = np.cumsum([0] + [len(g) for g in grids]).astype(INT)
        offsets = [np.zeros((len(g), 3)) for g in grids]
        for m, o in zip(muscles, offsets):
            if m.interior is not None:
                o[len(m.topology.contour):] = np.asarray(m.interior, FLOAT).reshape(-1, 3)
        self.offsets = np.ascontiguousarray(np.concatenate(offsets) if offsets else np.zeros((0, 3)))
        self.slots = np.concatenate(slots).astype(INT) if slots else np.zeros(0, INT)
        if len(self.slots) != len(self.cells):
            raise ValueError(f"{len(self.slots)} position slots for {len(self.cells)} targets")
        self._out = np.empty((len(self.cells), 3))
        #: (q,) int, each muscle's column in the system's contraction array (set by the system)
        self.columns = np.arange(q, dtype=INT)
        self._scratch = np.empty((4, int(self.hw.max()) if q else 0, 3))

    def __call__(self, pts: np.ndarray, contractions, out: np.ndarray | None = None) -> np.ndarray:
        """Targets ``(t, 3)`` (rows as :attr:`slots`) from the gathered points ``pts (k, 3)`` and
        the contractions (clipped to [0, 1]; passive muscles at 0): an array in the order of
        the system's controls, read at :attr:`columns` (set by the system), or ``{muscle: c}``
        (absent names 0). ``out`` (t, 3) float64 C-contiguous, filled and returned when given."""
        if isinstance(contractions, dict):
            c = np.array([contractions.get(n, 0.0) for n in self.names], dtype=FLOAT)
        else:
            c = np.ascontiguousarray(np.asarray(contractions, dtype=FLOAT)[self.columns])
        out = self._out if out is None else out
        _linear_targets(np.ascontiguousarray(pts, dtype=FLOAT), self.lines, self.hw, self.kappa,
                        self.cells, self.cell_start, self.offsets, c, self.active, self._scratch, out)
        return out
