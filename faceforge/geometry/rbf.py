"""Hardy multiquadric scattered-data interpolation (§4, Eq. 2).

``G(p) = sum_i w_i sqrt(1 + (eps |p - p_i|)^2) + A p + b`` with the affine part
solved jointly (``degree=1``), so ``G(p_i) = q_i`` exactly and any affine map
``q = M p + t`` is reproduced exactly everywhere — §5.1.2 relies on this when
it says that the size and orientation of the template mesh do not matter.

Shape parameter: Hardy's multiquadric ``sqrt(r^2 + R^2)`` equals
``R sqrt(1 + (r / R)^2)``, i.e. scipy's multiquadric with ``epsilon = 1 / R``
(scipy's kernel is the negated form, which changes nothing). We take Hardy's
own recommendation ``R = 0.815 d`` with ``d`` the mean distance from each
source to its nearest other source, so the kernel is scale-free: scaling the
data scales ``R`` with it and the interpolant commutes with the scaling.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from faceforge.constants import FLOAT

__all__ = ["hardy_rbf", "hardy_epsilon"]

#: Hardy (1990): R = 0.815 x mean nearest-neighbour distance
HARDY_FACTOR = 0.815


def hardy_epsilon(src) -> float:
    """scipy ``epsilon`` (1 / length) for Hardy's shape parameter of the sources ``(n, 3)``."""
    from scipy.spatial import cKDTree

    p = np.asarray(src, dtype=FLOAT)
    if len(p) < 2:
        return 1.0
    dist, _ = cKDTree(p).query(p, k=2)
    d = float(np.mean(dist[:, 1]))
    if not np.isfinite(d) or d <= 0:
        raise ValueError("hardy_rbf: sources contain only coincident points")
    return 1.0 / (HARDY_FACTOR * d)


def hardy_rbf(src, dst, epsilon: float | None = None) -> Callable[[np.ndarray], np.ndarray]:
    """Build ``G`` with ``G(src[i]) = dst[i]``.

    Parameters
    ----------
    src, dst : (n, 3) float
        Corresponding points; ``src`` must be distinct and not all coplanar
        (the affine part needs four affinely independent points, n >= 4).
    epsilon : float, optional
        scipy shape parameter in 1 / length; default :func:`hardy_epsilon`.

    Returns
    -------
    callable
        ``G(points (k, 3)) -> (k, 3) float64``.
    """
    from scipy.interpolate import RBFInterpolator

    p = np.asarray(src, dtype=FLOAT)
    q = np.asarray(dst, dtype=FLOAT)
    if p.ndim != 2 or p.shape[1] != 3 or q.shape != p.shape:
        raise ValueError(f"hardy_rbf: src {p.shape} and dst {q.shape} must both be (n, 3)")
    if len(p) < 4:
        raise ValueError(f"hardy_rbf: need at least 4 sources for the affine part, got {len(p)}")
    centred = p - p.mean(axis=0)
    sv = np.linalg.svd(centred, compute_uv=False)
    if sv[-1] <= 1e-9 * max(sv[0], 1e-300):
        raise ValueError("hardy_rbf: sources are coplanar; the affine part is undetermined")
    eps = hardy_epsilon(p) if epsilon is None else float(epsilon)
    interp = RBFInterpolator(p, q, kernel="multiquadric", epsilon=eps, degree=1)

    def G(points) -> np.ndarray:
        x = np.asarray(points, dtype=FLOAT)
        return interp(x.reshape(-1, 3)).reshape(x.shape)

    return G
