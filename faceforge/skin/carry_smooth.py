"""The carried anchors' motion spread over the tissue between the skin and the muscle.

A carried anchor (``skin.carry``) moves its skin vertex as its surface point on the muscle moves:
``p0 + (s - s0)`` (:meth:`faceforge.skin.layer.SkinSimulation.carry_targets`). One surface point
per vertex passes on every unevenness of the binding: where neighbouring skin vertices are bound
to surface points far apart (ICT's upper lip: vertices 1.8 mm apart bound to points of the ring
1.5 cm apart, their targets 7 mm apart when the sphincter purses), the skin is told to crumple.
The tissue under the skin (subcutaneous fat, a few mm thick) spreads a muscle's pull over a patch
about as wide: here each carried vertex moves by the Gaussian-weighted mean motion of the carried
anchors within ``radius`` of it at rest (sigma ``radius / 2``), itself included. A uniform motion
(the jaw, a rigid shift) passes unchanged, and the rest state stays a fixed point (every motion 0).
``skin.carry_radius_mm`` (an average adult's mm, scaled by ES0); 0 turns it off.
"""

from __future__ import annotations

import numba
import numpy as np

from faceforge.constants import FLOAT, INT, NUMBA_OPTIONS


def smoothing_rows(p0: np.ndarray, radius: float, groups=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Row-normalised weights of the carried anchors' motion, as CSR ``(indptr (c + 1,) int,
    indices (nnz,) int, weights (nnz,) float)``: row ``i`` the anchors within ``radius`` (skin
    units) of ``p0[i]`` (``p0 (c, 3)``, the rest positions of their skin vertices), weighted
    ``exp(-(2 d / radius)^2)``; each row sums to 1. With ``groups (c,) int`` (each anchor's
    body) only anchors of the same group are mixed: a muscle's pull is spread over its own
    anchors, not diluted by a relaxed neighbour's (MakeHuman's brow squeeze, FAP 37, lost half
    its travel to the frontalis' anchors around the corrugator's)."""
    from scipy.sparse import csr_matrix
    from scipy.spatial import cKDTree

    p0 = np.asarray(p0, dtype=FLOAT).reshape(-1, 3)
    c = len(p0)
    pairs = cKDTree(p0).query_pairs(float(radius), output_type="ndarray") if c else np.zeros((0, 2), INT)
    i = np.concatenate([pairs[:, 0], pairs[:, 1], np.arange(c)])
    j = np.concatenate([pairs[:, 1], pairs[:, 0], np.arange(c)])
    w = np.exp(-(2.0 * np.linalg.norm(p0[i] - p0[j], axis=1) / float(radius)) ** 2)
    if groups is not None:
        g = np.asarray(groups).reshape(-1)
        w = w * (g[i] == g[j])
    m = csr_matrix((w, (i, j)), shape=(c, c))
    m.sort_indices()
    w = m.data / np.repeat(np.asarray(m.sum(axis=1)).ravel(), np.diff(m.indptr))
    return m.indptr.astype(INT), m.indices.astype(INT), np.ascontiguousarray(w, dtype=FLOAT)


def carry_smoothed_plain(t, rows, s0, p0, indptr, indices, weights) -> np.ndarray:
    """The plain twin of :func:`carry_smoothed`: ``t[rows] = p0 + W (t[rows] - s0)``, ``t (k, 3)``
    anchor targets (updated and returned), ``rows (c,)``, ``s0, p0 (c, 3)``, ``W`` the CSR rows of
    :func:`smoothing_rows`."""
    d = t[rows] - s0
    out = np.empty_like(d)
    for i in range(len(rows)):
        a, b = indptr[i], indptr[i + 1]
        out[i] = weights[a:b] @ d[indices[a:b]]
    t[rows] = p0 + out
    return t


@numba.njit(**NUMBA_OPTIONS)
def carry_smoothed(t, rows, s0, p0, indptr, indices, weights, buf):  # pragma: no cover - numba
    """In place, compiled (:func:`carry_smoothed_plain` is the twin); ``buf (c, 3)`` scratch."""
    for i in range(rows.shape[0]):
        r = rows[i]
        for d in range(3):
            buf[i, d] = t[r, d] - s0[i, d]
    for i in range(rows.shape[0]):
        r = rows[i]
        x = y = z = 0.0
        for n in range(indptr[i], indptr[i + 1]):
            j = indices[n]
            w = weights[n]
            x += w * buf[j, 0]
            y += w * buf[j, 1]
            z += w * buf[j, 2]
        t[r, 0] = p0[i, 0] + x
        t[r, 1] = p0[i, 1] + y
        t[r, 2] = p0[i, 2] + z
