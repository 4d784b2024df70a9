"""Joined insertions (``skin.join_insertions``, beyond §8): a skin vertex carried by several
muscles goes where the muscle that pulls it goes.

The brow's dermis receives the frontalis, the corrugator and the depressor supercilii together
(``bind.insertions``, ``bind.brow_shared_mm``), so the brow skin is anchored to two or more of
them. §8's anchors each pull the vertex toward their own surface point, so the vertex went to
the *mean* of its anchors: a relaxed muscle held it back as firmly as a contracting one pulled
it (MakeHuman, corrugator L at c = 1: its anchors near FDP 4.1 moved 46 ES toward the midline,
the depressor supercilii's on the same vertices 0, the brow 27; the squeeze FAP 37 then stopped
at 27 of the 75 ES the Xface files ask, and calibration, whose first probe saw nothing, stopped
at 0.8). A relaxed muscle in the dermis is slack and holds nothing back.

Here each vertex's carried anchors (``p0 + (s_i - s0_i)``, :meth:`faceforge.skin.layer.
SkinSimulation.carry_targets`) are replaced by one common target ``p0 + d`` with ``d`` the
displacements ``d_i = s_i - s0_i`` weighted by their squared length,
``d = sum |d_i|^2 d_i / sum |d_i|^2``: the muscle that moves its surface most leads; where every
anchor moves alike (the frontalis raising both depressors it carries) ``d`` is that motion,
as before; at rest ``d`` is 0 (the rest state stays a fixed point).
"""

from __future__ import annotations

import numba
import numpy as np

from faceforge.constants import FLOAT, INT, NUMBA_OPTIONS


def joined_groups(vertex_ids, carried) -> tuple[np.ndarray, np.ndarray]:
    """The carried anchors of the vertices that have two or more: ``(rows (g,) int, starts
    (m + 1,) int)``, group ``j`` being ``rows[starts[j]:starts[j + 1]]`` (anchor rows of one
    vertex). ``vertex_ids`` (k,) int, ``carried`` (k,) bool."""
    ids = np.asarray(vertex_ids)
    rows = np.flatnonzero(np.asarray(carried, bool))
    rows = rows[np.argsort(ids[rows], kind="stable")]
    v = ids[rows]
    if not len(v):
        return np.zeros(0, INT), np.zeros(1, INT)
    cut = np.flatnonzero(np.diff(v)) + 1
    starts = np.concatenate([[0], cut, [len(v)]])
    size = np.diff(starts)
    keep = np.repeat(size >= 2, size)
    rows = rows[keep]
    size = size[size >= 2]
    return rows.astype(INT), np.concatenate([[0], np.cumsum(size)]).astype(INT)


def join_plain(t: np.ndarray, rows: np.ndarray, starts: np.ndarray, p0: np.ndarray) -> np.ndarray:
    """The plain twin of :func:`join`: ``t (k, 3)`` anchor targets, ``p0 (g, 3)`` the rest
    position of each row's skin vertex. Returns ``t`` updated."""
    for j in range(len(starts) - 1):
        r = rows[starts[j]:starts[j + 1]]
        d = t[r] - p0[starts[j]:starts[j + 1]]
        w = (d * d).sum(axis=1)
        if w.sum() <= 0.0:
            continue
        t[r] = p0[starts[j]:starts[j + 1]] + (w[:, None] * d).sum(axis=0) / w.sum()
    return t


@numba.njit(**NUMBA_OPTIONS)
def join(t, rows, starts, p0):  # pragma: no cover - numba
    """In place, compiled (:func:`join_plain` is the twin): each group's carried targets ``t``
    (k, 3) become ``p0 + sum |d_i|^2 d_i / sum |d_i|^2`` with ``d_i = t[row_i] - p0_i``."""
    for j in range(starts.shape[0] - 1):
        a, b = starts[j], starts[j + 1]
        ax = ay = az = wsum = 0.0          # scalars: no array allocated per group
        for i in range(a, b):
            r = rows[i]
            dx, dy, dz = t[r, 0] - p0[i, 0], t[r, 1] - p0[i, 1], t[r, 2] - p0[i, 2]
            w = dx * dx + dy * dy + dz * dz
            ax += w * dx
            ay += w * dy
            az += w * dz
            wsum += w
        if wsum <= 0.0:
            continue
        for i in range(a, b):
            r = rows[i]
            t[r, 0] = p0[i, 0] + ax / wsum
            t[r, 1] = p0[i, 1] + ay / wsum
            t[r, 2] = p0[i, 2] + az / wsum


def join_args(rest, vertex_ids, carried):
    """``(rows, starts, p0)`` for :func:`join` (``p0 (g, 3)``: each row's skin vertex at rest,
    ``rest (n, 3)``), or None when no vertex has two carried anchors."""
    rows, starts = joined_groups(vertex_ids, carried)
    if not len(rows):
        return None
    p0 = np.ascontiguousarray(np.asarray(rest, FLOAT)[np.asarray(vertex_ids)[rows]])
    return rows, starts, p0
