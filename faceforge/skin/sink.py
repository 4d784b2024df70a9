"""A one-sided hold (``skin.lid_hold_sink``, beyond §8): held skin may sink and draw toward
the nose, not rise nor be drawn outward.

``skin.lid_hold`` tethers the upper lids' skin to its rest place (:func:`faceforge.skin.brow.
lid_hold`): a raised brow no longer drags it up (the MakeHuman brow units move it 0-0.4 mm
where each frontalis part lifted it 3-4.7 mm), but a lowered or frowning brow, which in a real
face hoods the lid, was held back as firmly: the played lowered brows stopped short
(docs/notes/brows15.md: MediaPipe's FAPs 31/32 @ -70 0.3 / 0.7 -> 10.5 / 11.6 %) and so did the
squeeze (37/38, the corrugator drawing the brow toward the nose). Here each held anchor's target,
its skin vertex's rest place ``p0``, follows that vertex by ``share`` of its sinking along ``up``
and of its motion along ``medial`` (a unit vector across ``up``, toward the nose; zero: none),
``t = p0 + share * (min(h, 0) * up + max(g, 0) * medial)`` with ``h = (p - p0) . up`` and
``g = (p - p0) . medial`` read at the step's start: at ``share`` 1 the tether pulls back only a
rise, a pull outward and any motion in depth; at 0 it is the two-sided hold. At rest ``h = g = 0``,
so the rest state stays a fixed point. The target lags the vertex by one step; once settled they
agree. (docs/notes/brow22.md: a hold free in every direction but up keeps half of the units'
gain; the lateral and depth hold is the other half.)
"""

from __future__ import annotations

import numba
import numpy as np

from faceforge.constants import FLOAT, INT, NUMBA_OPTIONS


def sink_args(rest, vertex_ids, rows, up=(0.0, 1.0, 0.0), medial=None) -> tuple:
    """``(rows (h,) int, vertex (h,) int, p0 (h, 3) float, up (3,) unit float, medial (h, 3)
    float)`` for :func:`sink`: the anchor rows ``rows`` (into ``vertex_ids`` (k,) int), their
    skin vertices, those vertices' rest places from ``rest`` (n, 3), the unit ``up`` and per row
    the direction toward the nose (``medial`` (h, 3), made unit and across ``up``; None: zeros,
    no freedom across)."""
    rows = np.asarray(rows, INT).reshape(-1)
    vid = np.asarray(vertex_ids, INT)[rows]
    u = np.asarray(up, FLOAT) / np.linalg.norm(up)
    m = np.zeros((len(rows), 3), FLOAT)
    if medial is not None:
        m = np.asarray(medial, FLOAT).reshape(-1, 3)
        m = m - (m @ u)[:, None] * u[None, :]
        n = np.linalg.norm(m, axis=1)
        m = np.where(n[:, None] > 0, m / np.maximum(n, 1e-300)[:, None], 0.0)
    return (rows, vid, np.ascontiguousarray(np.asarray(rest, FLOAT)[vid]), np.ascontiguousarray(u),
            np.ascontiguousarray(m))


def sink_plain(t, rows, vertex, p0, up, medial, positions, share: float) -> np.ndarray:
    """The plain twin of :func:`sink`: ``t (k, 3)`` anchor targets, ``positions (n, 3)`` the
    skin vertices now (skin units); each row ``rows[i]`` gets ``share * (min(h_i, 0) * up +
    max(g_i, 0) * medial[i])`` added, ``h_i = d_i . up``, ``g_i = d_i . medial[i]``, ``d_i =
    positions[vertex[i]] - p0[i]``. Returns ``t`` updated."""
    d = np.asarray(positions)[vertex] - p0
    h = np.minimum(d @ up, 0.0)
    g = np.maximum((d * medial).sum(axis=1), 0.0)
    t[rows] += share * (h[:, None] * up[None, :] + g[:, None] * medial)
    return t


@numba.njit(**NUMBA_OPTIONS)
def sink(t, rows, vertex, p0, up, medial, positions, share):  # pragma: no cover - numba
    """In place, compiled (:func:`sink_plain` is the twin): ``t[rows[i]] += share * (min(h_i, 0)
    * up + max(g_i, 0) * medial[i])``."""
    for i in range(rows.shape[0]):
        v, r = vertex[i], rows[i]
        h = 0.0
        g = 0.0
        for d in range(3):
            x = positions[v, d] - p0[i, d]
            h += x * up[d]
            g += x * medial[i, d]
        h = min(h, 0.0)
        g = max(g, 0.0)
        for d in range(3):
            t[r, d] += share * (h * up[d] + g * medial[i, d])
