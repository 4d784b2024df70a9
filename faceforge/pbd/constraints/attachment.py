"""One-way attachment of a particle to a surface point of another (deeper) body.

The target is the barycentric point ``t = b0 q0 + b1 q1 + b2 q2`` of a triangle of
particles ``(q0, q1, q2)``; ``C(p) = |p - t|`` and only ``p`` moves (the triangle is
treated as infinitely heavy), so a deeper layer drives a shallower one and never
the reverse (paper §6: "each layer influences the deformation of the layers on top
of it, but not those underlying it").
"""

from __future__ import annotations

import numba
import numpy as np

from faceforge.pbd.constraints._common import PBD_NUMBA

from faceforge.pbd.constraints.position import _pull


def attachment_targets(positions, triangles, bary) -> np.ndarray:
    """Barycentric points ``(m, 3) float64`` of ``triangles (m, 3)`` with ``bary (m, 3)``."""
    p = np.asarray(positions, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    return np.einsum("mk,mkd->md", np.asarray(bary, dtype=np.float64).reshape(-1, 3), p[t])


def init_attachment(positions, particles, triangles, bary) -> np.ndarray:
    """Rest distance ``(m,) float64`` of each particle to its surface point (0 if on it)."""
    return residual_attachment(positions, particles, triangles, bary)


def residual_attachment(positions, particles, triangles, bary) -> np.ndarray:
    """``C`` per constraint, ``(m,) float64``: distance of each particle to its surface point."""
    p = np.asarray(positions, dtype=np.float64)[np.asarray(particles, dtype=np.int64)]
    return np.linalg.norm(p - attachment_targets(positions, triangles, bary), axis=1)


@numba.njit(inline="always", **PBD_NUMBA)
def _solve_attachment(x, w, i, t0, t1, t2, b0, b1, b2, k, c, lam, xpbd):
    """Project one attachment in place (moves ``x[i]`` only); return the multiplier increment."""
    tx = b0 * x[t0, 0] + b1 * x[t1, 0] + b2 * x[t2, 0]
    ty = b0 * x[t0, 1] + b1 * x[t1, 1] + b2 * x[t2, 1]
    tz = b0 * x[t0, 2] + b1 * x[t1, 2] + b2 * x[t2, 2]
    return _pull(x, w, i, tx, ty, tz, k, c, lam, xpbd)


@numba.njit(**PBD_NUMBA)
def _project_attachment(x, w, idx, tri, bary, k, c, lam, xpbd, start, stop):
    """Sweep over constraints ``start:stop`` in order (``xpbd``: accumulate ``lam``)."""
    for j in range(start, stop):
        lam[j] += _solve_attachment(x, w, idx[j], tri[j, 0], tri[j, 1], tri[j, 2],
                                    bary[j, 0], bary[j, 1], bary[j, 2], k[j], c[j], lam[j], xpbd)


def solve_attachment(positions, inv_mass, particles, triangles, bary, stiffness) -> np.ndarray:
    """One PBD sweep over all attachments; returns new ``(n, 3)`` positions."""
    x = np.array(positions, dtype=np.float64, order="C")
    idx = np.ascontiguousarray(particles, dtype=np.int64).reshape(-1)
    m = len(idx)
    k = np.broadcast_to(np.asarray(stiffness, dtype=np.float64), (m,)).copy()
    _project_attachment(x, np.ascontiguousarray(inv_mass, dtype=np.float64), idx,
                        np.ascontiguousarray(triangles, dtype=np.int64).reshape(-1, 3),
                        np.ascontiguousarray(bary, dtype=np.float64).reshape(-1, 3), k,
                        np.zeros(m), np.zeros(m), False, 0, m)
    return x
