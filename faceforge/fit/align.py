"""Alignment (§7): Hardy RBF warps and the enhancement flow, and the sampling of new landmark
pairs (the similarity transform is :mod:`faceforge.geometry.rigid`'s)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from faceforge.geometry.rbf import hardy_rbf


# ----------------------------------------------------------------------------- alignment


def apply_affine(matrix: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply a (4, 4) affine map to points (..., 3)."""
    p = np.asarray(points, dtype=np.float64)
    return p @ matrix[:3, :3].T + matrix[:3, 3]


def map_directions(warp: Callable, points: np.ndarray, directions: np.ndarray, step: float) -> np.ndarray:
    """Unit directions (k, 3) after ``warp``: map ``p`` and ``p + step d``, normalise."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    a, b = warp(p - 0.5 * step * d), warp(p + 0.5 * step * d)
    out = b - a
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def enhancement_field(held: np.ndarray, start: np.ndarray, displacement: np.ndarray,
                      epsilon: float) -> Callable[[np.ndarray], np.ndarray]:
    """The displacement field of one enhancement round: a Hardy RBF (affine part included)
    that is zero at ``held`` (h, 3) (the targets of the pairs already placed)
    and ``displacement`` (k, 3) at ``start`` (k, 3) (the new pairs' bone points), all head
    space, length units; ``epsilon``: the shape parameter (1 / length) of the landmarks.
    Returns ``u(points (q, 3)) -> (q, 3)`` displacement (length units)."""
    held = np.asarray(held, dtype=np.float64).reshape(-1, 3)
    start = np.asarray(start, dtype=np.float64).reshape(-1, 3)
    value = np.vstack([np.zeros_like(held), np.asarray(displacement, dtype=np.float64).reshape(-1, 3)])
    return hardy_rbf(np.vstack([held, start]), value, epsilon=epsilon)


def integrate_flow(u: Callable, points: np.ndarray, steps: int) -> np.ndarray:
    """Carry ``points`` (..., 3) along the stationary velocity field ``u`` ((q, 3) -> (q, 3),
    length per unit time) for unit time: ``steps`` explicit midpoint (RK2) steps of 1/steps.
    A point where ``u`` is zero does not move; for a smooth ``u`` and enough steps distinct
    points stay distinct (the flow is one-to-one), so a surface carried along cannot turn
    over. Returns the moved points, same shape."""
    p = np.asarray(points, dtype=np.float64)
    x = p.reshape(-1, 3).copy()
    h = 1.0 / int(steps)
    for _ in range(int(steps)):
        x = x + h * u(x + 0.5 * h * u(x))
    return x.reshape(p.shape)


@dataclass(frozen=True)
class Flow:
    """One enhancement round as a map in the :class:`Warp` composition: ``integrate_flow(field,
    points, steps)``. ``field``: :func:`enhancement_field`."""

    field: Callable
    steps: int = 8

    def __call__(self, points) -> np.ndarray:
        return integrate_flow(self.field, points, self.steps)


@dataclass
class Warp:
    """The fitted map template -> head: similarity, then RBFs in order."""

    similarity: np.ndarray
    rbfs: list = field(default_factory=list)

    def __call__(self, points) -> np.ndarray:
        p = np.asarray(points, dtype=np.float64)
        out = apply_affine(self.similarity, p.reshape(-1, 3))
        for g in self.rbfs:
            out = g(out)
        return out.reshape(p.shape)


# ----------------------------------------------------------------------------- queries


def worst_first_sample(points: np.ndarray, badness: np.ndarray, k: int, existing: np.ndarray,
                       min_distance: float) -> np.ndarray:
    """Indices (<= k,) of ``points`` (n, 3), worst (largest ``badness`` (n,)) first, each at
    least ``min_distance`` from ``existing`` (e, 3) and from the ones already taken.
    Deterministic (ties by index)."""
    if len(points) == 0 or k <= 0:
        return np.zeros(0, dtype=np.int64)
    if len(existing):
        from scipy.spatial import cKDTree

        free = cKDTree(existing).query(points)[0] >= min_distance
    else:
        free = np.ones(len(points), bool)
    chosen = []
    for i in np.argsort(-badness, kind="stable"):
        if not free[i]:
            continue
        chosen.append(int(i))
        if len(chosen) == k:
            break
        free &= np.linalg.norm(points - points[i], axis=1) >= min_distance
    return np.asarray(chosen, dtype=np.int64)


def grid_subsample(points: np.ndarray, cell: float) -> np.ndarray:
    """Bool (n,): the first point (by index) of every occupied cubic cell of size ``cell``."""
    keys = np.floor((points - points.min(axis=0)) / cell).astype(np.int64)
    _, first = np.unique(keys, axis=0, return_index=True)
    mask = np.zeros(len(points), bool)
    mask[first] = True
    return mask
