"""Greedy graph colouring of constraints (optional projection order).

Constraints of one colour share no particle, so consecutive projections in a colour
are independent and the CPU can overlap them (about 2x faster for distance
constraints). Colouring is applied *within* each builder block (a block keeps its
place in the order, so deeper layers are still projected first); inside a block the
constraints are visited colour by colour, in builder order within a colour. This is
still a sequential Gauss-Seidel sweep, just in a different order; results differ
from the builder order in the rounding, not in the solution.
"""

from __future__ import annotations

import numba
import numpy as np

from faceforge.constants import NUMBA_OPTIONS


@numba.njit(**NUMBA_OPTIONS)
def _greedy(idx, n_particles, words):
    """Smallest colour not used by any constraint sharing a particle, in order.

    idx : (m, k) int particle ids; words : 64-colour words per particle (enough for
    the maximum possible colour). Returns (m,) int64 colours.
    """
    mask = np.zeros((n_particles, words), dtype=np.uint64)
    out = np.empty(idx.shape[0], dtype=np.int64)
    one = np.uint64(1)
    for j in range(idx.shape[0]):
        colour = -1
        for wd in range(words):
            used = np.uint64(0)
            for t in range(idx.shape[1]):
                used |= mask[idx[j, t], wd]
            if used != np.uint64(0xFFFFFFFFFFFFFFFF):
                bit = 0
                while (used >> np.uint64(bit)) & one:
                    bit += 1
                colour = wd * 64 + bit
                break
        out[j] = colour
        wd = colour // 64
        b = np.uint64(colour % 64)
        for t in range(idx.shape[1]):
            mask[idx[j, t], wd] |= one << b
    return out


def greedy_colouring(indices: np.ndarray, n_particles: int) -> np.ndarray:
    """Colours ``(m,) int64`` of constraints ``indices (m, k)`` (greedy, in order).

    No two constraints of one colour share a particle.
    """
    idx = np.ascontiguousarray(indices, dtype=np.int64)
    if idx.ndim == 1:
        idx = idx[:, None]
    if len(idx) == 0:
        return np.zeros(0, dtype=np.int64)
    if idx.min() < 0 or idx.max() >= n_particles:
        raise ValueError(f"indices hold particle ids outside [0, {n_particles})")
    incidence = np.bincount(idx.ravel(), minlength=n_particles).max()
    max_colours = idx.shape[1] * (int(incidence) - 1) + 1
    return _greedy(idx, n_particles, (max_colours + 63) // 64)


def colour_order(indices: np.ndarray, n_particles: int, blocks: np.ndarray):
    """Order one kind's constraints colour by colour within each block.

    indices : (m, k) int; blocks : (b, 2) int rows (start, stop) of this kind's blocks.
    Returns ``(order (m,) int64, runs (r,) int64)``: the permutation (stable sort by greedy
    colour inside each block) and the sorted boundaries, in the permuted order, of the
    runs of constraints that share no particle (one colour of one block; starts with 0
    and ends with m).
    """
    idx = np.asarray(indices)
    order = np.arange(len(idx), dtype=np.int64)
    runs = [0, len(idx)]
    for start, stop in blocks:
        colours = greedy_colouring(idx[start:stop], n_particles)
        perm = np.argsort(colours, kind="stable")
        order[start:stop] = start + perm
        sorted_colours = colours[perm]
        runs.extend([start, stop])
        runs.extend((start + 1 + np.flatnonzero(np.diff(sorted_colours))).tolist())
    return order, np.unique(np.array(runs, dtype=np.int64))
