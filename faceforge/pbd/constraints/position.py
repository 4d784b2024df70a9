"""Position constraint: pull a particle toward a moving target point.

``C(p) = |p - t|`` with ``t`` from ``Control.position_targets`` (paper §3, §5.2.1: the
muscle particles follow their action-line samples; §8: the anchor particles q follow
their surface points). ``grad_p C = (p - t) / |p - t|``; in the PBD modes one
projection moves the particle by ``k (t - p)``. External: it does not conserve
momentum, and a kinematic particle (inverse mass 0) never moves.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from faceforge.pbd.constraints._common import _multiplier, PBD_NUMBA


def init_position(positions: np.ndarray, particles: np.ndarray) -> np.ndarray:
    """Rest targets ``(m, 3) float64``: the particles' own rest positions."""
    return np.asarray(positions, dtype=np.float64)[np.asarray(particles, dtype=np.int64)].copy()


def residual_position(positions, particles, targets) -> np.ndarray:
    """``C`` per constraint, ``(m,) float64``: distance of each particle to its target."""
    p = np.asarray(positions, dtype=np.float64)[np.asarray(particles, dtype=np.int64)]
    return np.linalg.norm(p - np.asarray(targets, dtype=np.float64), axis=1)


@numba.njit(inline="always", **PBD_NUMBA)
def _pull(x, w, i, tx, ty, tz, k, c, lam, xpbd):
    """Move particle ``i`` toward ``t`` (one-sided); return the multiplier increment."""
    wi = w[i]
    if wi == 0.0:
        return 0.0
    dx = x[i, 0] - tx
    dy = x[i, 1] - ty
    dz = x[i, 2] - tz
    d = math.sqrt(dx * dx + dy * dy + dz * dz)
    if d == 0.0:
        return 0.0
    s = _multiplier(d, wi, k, c, lam, xpbd)
    f = s * wi / d
    x[i, 0] += f * dx
    x[i, 1] += f * dy
    x[i, 2] += f * dz
    return s


@numba.njit(inline="always", **PBD_NUMBA)
def _solve_position(x, w, i, target, slot, k, c, lam, xpbd):
    """Project one position constraint (target row ``slot`` of ``target (m, 3)``)."""
    return _pull(x, w, i, target[slot, 0], target[slot, 1], target[slot, 2], k, c, lam, xpbd)


@numba.njit(**PBD_NUMBA)
def _project_position(x, w, idx, target, k, c, lam, xpbd, start, stop):
    """Sweep over constraints ``start:stop`` in order (``xpbd``: accumulate ``lam``)."""
    for j in range(start, stop):
        lam[j] += _solve_position(x, w, idx[j], target, j, k[j], c[j], lam[j], xpbd)


def solve_position(positions, inv_mass, particles, targets, stiffness) -> np.ndarray:
    """One PBD sweep over all position constraints; returns new ``(n, 3)`` positions."""
    x = np.array(positions, dtype=np.float64, order="C")
    idx = np.ascontiguousarray(particles, dtype=np.int64).reshape(-1)
    m = len(idx)
    k = np.broadcast_to(np.asarray(stiffness, dtype=np.float64), (m,)).copy()
    _project_position(x, np.ascontiguousarray(inv_mass, dtype=np.float64), idx,
                      np.ascontiguousarray(targets, dtype=np.float64).reshape(-1, 3), k,
                      np.zeros(m), np.zeros(m), False, 0, m)
    return x
