"""The linear muscle's contraction (§5.2.1, Eq. 4): the fibres shorten toward the origin.

Linear contraction (§5.2.1, Eq. 4): the fibre lines A0, A2 are sampled with
``step' = step (1 - kappa c)`` so their samples slide toward the origin (sample 0
stays on the origin). The origin line A3 is sampled normally (the fixed site).
The interior insertion samples (A1, ``0 < j < w-1``) have no fibre of their
own: each is moved by the linear blend (in ``j``) of the displacements of the
two insertion corners, so the whole insertion edge travels with the fibres.
The interior bottom particles (``0 < i < h-1``, ``0 < j < w-1``) have no sample of the
contour either; left free (the paper binds only the contour), nothing drives them along
the fibres: with the stiffness of §5.2.1 the bottom sheet has no distance constraint at
all, the top sheet no shear, and ``k_longitudinal^up = 0.1`` alone drags them. Under fast
contraction the bound insertion sample then runs over the lagging interior node next to
it and single bottom faces turn over (the depressor anguli at the modiolus, issue 4).
"When it contracts, the fibers shorten by equal amounts" (§5.2.1), so each interior node
is bound like the contour, with ``k_position``, to a target that keeps its rest place
between the two side fibres' samples of its row ``i``: their blend in ``j`` (the rule of
the insertion edge, applied to every row) plus the node's rest offset from that blend,
kept in the row's basis (:func:`row_bases`: the row ``a2[i] - a0[i]``, the fibres' mean
step, the unit normal), so its part in the sheet scales with the row's width and with the
fibre step as the fibres shorten, and its normal part (mostly the layer's sag under the
chord) keeps its length; all of it turns with the anatomy, e.g. the jaw. At rest the
targets are the rest positions. (A surface point of the layer under the node, tried
first, does not do: a deeper muscle's contraction carries it along with that muscle's
fibres while the action lines' samples stay evenly spread along the lines; with every
muscle at c = 1 the depressor labii inferioris, on the platysma and mentalis, folded.)
``kappa`` (``max_contraction``, default :data:`LINEAR_MAX_CONTRACTION` = 0.5) is
the fibre shortening at c = 1. The paper's literal kappa = 1 collapses every
fibre sample onto the origin at c = 1; on the synthetic head the muscle then
folds over itself (its bottom sheet turns over from c ~ 0.9 at rest and
under smooth random driving). A fibre cannot shorten to nothing anyway
(skeletal muscle shortens by roughly half at most), so c = 1 here means
"half the rest fibre length"; pass ``max_contraction=1.0`` for the literal
Eq. 4. The FAP -> contraction calibration absorbs the scale.
"""

from __future__ import annotations

import numpy as np

from faceforge.constants import FLOAT, INT


LINEAR_MAX_CONTRACTION = 0.5


def _cross(a, b):
    """``a x b`` over the last axis, component by component (the compiled twin's arithmetic)."""
    return np.stack([a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
                     a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
                     a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]], -1)


def row_bases(a0, a2) -> np.ndarray:
    """Basis of each interior row ``i = 1..h-2`` of a linear muscle, ``(h-2, 3, 3)``.

    ``a0, a2 (h, 3)``: the samples of the two side fibres. Rows of each basis: ``e_u =
    a2[i] - a0[i]`` across the row, ``e_v = ((a0[i+1] - a0[i-1]) + (a2[i+1] - a2[i-1])) / 4``
    the mean fibre step there, and the unit normal ``n`` along ``e_u x e_v``.
    """
    a0 = np.asarray(a0, FLOAT)
    a2 = np.asarray(a2, FLOAT)
    eu = a2[1:-1] - a0[1:-1]
    ev = ((a0[2:] - a0[:-2]) + (a2[2:] - a2[:-2])) * 0.25
    n = _cross(eu, ev)
    length = np.sqrt((n[..., 0] * n[..., 0] + n[..., 1] * n[..., 1]) + n[..., 2] * n[..., 2])
    return np.stack([eu, ev, n / np.maximum(length, 1e-300)[..., None]], 1)


def _row_blend(a0, a2, w: int) -> np.ndarray:
    """``(1 - t_j) a0[i] + t_j a2[i]``, ``t = linspace(0, 1, w)``, for the interior rows
    and columns, ``(h-2, w-2, 3)``."""
    t = np.linspace(0.0, 1.0, w)[None, 1:-1, None]
    return (1.0 - t) * np.asarray(a0, FLOAT)[1:-1, None] + t * np.asarray(a2, FLOAT)[1:-1, None]


def interior_targets(a0, a2, offset) -> np.ndarray:
    """Targets of the interior bottom particles, ``(h-2, w-2, 3)`` (module docstring).

    ``a0, a2 (h, 3)`` the current (contracted) samples of the side fibres; ``offset
    (h-2, w-2, 3)`` :attr:`Muscle.interior`. Per component: ``blend + ((k_u e_u + k_v e_v) + k_n n)``.
    """
    fr = row_bases(a0, a2)[:, None]                   # (h-2, 1, 3, 3)
    k = np.asarray(offset, FLOAT)
    off = (k[..., 0:1] * fr[..., 0, :] + k[..., 1:2] * fr[..., 1, :]) + k[..., 2:3] * fr[..., 2, :]
    return _row_blend(a0, a2, k.shape[1] + 2) + off


def interior_grid(h: int, w: int) -> np.ndarray:
    """``((h-2) (w-2), 2)`` grid cells ``(i, j)``, ``0 < i < h-1``, ``0 < j < w-1``, row-major."""
    i, j = np.meshgrid(np.arange(1, h - 1), np.arange(1, w - 1), indexing="ij")
    return np.stack([i.ravel(), j.ravel()], 1).astype(INT)
