"""Hardy multiquadric RBF (§4): exact at the sources, reproduces affine maps (§5.1.2)."""

import numpy as np
import pytest

from faceforge.geometry.rbf import hardy_epsilon, hardy_rbf


def cloud(n=40, seed=0):
    return np.random.default_rng(seed).normal(size=(n, 3))


def test_exact_at_sources():
    src = cloud()
    dst = src + 0.3 * np.sin(3 * src)
    G = hardy_rbf(src, dst)
    np.testing.assert_allclose(G(src), dst, atol=1e-9)


def test_affine_map_reproduced_everywhere():
    src = cloud()
    A = np.array([[1.2, 0.3, -0.1], [0.0, 0.8, 0.4], [0.2, -0.5, 1.1]])
    t = np.array([3.0, -2.0, 0.5])
    G = hardy_rbf(src, src @ A.T + t)
    far = cloud(200, seed=5) * 3
    np.testing.assert_allclose(G(far), far @ A.T + t, atol=1e-8)


def test_commutes_with_uniform_scaling():
    """The shape parameter follows the data scale, so scaling data scales the result."""
    src = cloud()
    dst = src + 0.2 * np.cos(2 * src)
    q = cloud(30, seed=9)
    a = hardy_rbf(src, dst)(q)
    b = hardy_rbf(src * 1000, dst * 1000)(q * 1000)
    np.testing.assert_allclose(b, a * 1000, rtol=1e-7, atol=1e-6)
    assert hardy_epsilon(src * 1000) == pytest.approx(hardy_epsilon(src) / 1000)


def test_rejects_coplanar_and_mismatched():
    flat = cloud()
    flat[:, 2] = 0
    with pytest.raises(ValueError, match="coplanar"):
        hardy_rbf(flat, flat)
    with pytest.raises(ValueError, match=r"\(n, 3\)"):
        hardy_rbf(cloud(), cloud()[:-1])
