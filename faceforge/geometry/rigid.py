"""Least-squares alignment of corresponding point sets: the similarity and rigid transforms
(Umeyama 1991), and a rigid transform fitted to the points that move least (a posed copy of a
mesh whose whole head also moved: the head's motion, not the face's)."""

from __future__ import annotations

import numpy as np


def _umeyama(src, dst, with_scale: bool) -> np.ndarray:
    src = np.asarray(src, dtype=np.float64)
    dst = np.asarray(dst, dtype=np.float64)
    if src.shape != dst.shape or src.ndim != 2 or src.shape[1] != 3 or len(src) < 3:
        name = "similarity_transform" if with_scale else "rigid_transform"
        raise ValueError(f"{name}: src {src.shape} and dst {dst.shape} must be (n>=3, 3)")
    mu_s, mu_d = src.mean(0), dst.mean(0)
    xs, xd = src - mu_s, dst - mu_d
    cov = xd.T @ xs / len(src)
    u, sig, vt = np.linalg.svd(cov)
    e = np.eye(3)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:
        e[2, 2] = -1.0
    rot = u @ e @ vt
    scale = 1.0
    if with_scale:
        var_s = (xs ** 2).sum() / len(src)
        scale = float(np.trace(np.diag(sig) @ e) / var_s)
    out = np.eye(4)
    out[:3, :3] = scale * rot
    out[:3, 3] = mu_d - scale * rot @ mu_s
    return out


def similarity_transform(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Least-squares similarity (4, 4) with ``dst ~ s R src + t`` (Umeyama 1991).

    src, dst : (n, 3) float, n >= 3 corresponding points. R is a proper rotation.
    """
    return _umeyama(src, dst, True)


def rigid_transform(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Least-squares rigid motion (4, 4) with ``dst ~ R src + t`` (R a proper rotation).

    src, dst : (n, 3) float, n >= 3 corresponding points.
    """
    return _umeyama(src, dst, False)


def still_part_motion(src: np.ndarray, dst: np.ndarray, keep: float = 0.5, rounds: int = 5) -> tuple:
    """The rigid motion (4, 4) of the points that move least from ``src`` (n, 3) to ``dst`` (n, 3):
    fitted to all, then ``rounds`` times refitted to the ``keep`` share of points it leaves the
    smallest residual (a trimmed least squares: a face's expression moves a minority of a head's
    vertices, its head motion all of them). Returns (transform, (n,) bool the points of the last fit)."""
    src = np.asarray(src, dtype=np.float64)
    dst = np.asarray(dst, dtype=np.float64)
    used = np.ones(len(src), dtype=bool)
    t = rigid_transform(src, dst)
    count = max(3, int(round(keep * len(src))))
    for _ in range(rounds):
        residual = np.linalg.norm(src @ t[:3, :3].T + t[:3, 3] - dst, axis=1)
        nxt = np.zeros(len(src), dtype=bool)
        nxt[np.argsort(residual, kind="stable")[:count]] = True
        if np.array_equal(nxt, used):
            break
        used = nxt
        t = rigid_transform(src[used], dst[used])
    return t, used
