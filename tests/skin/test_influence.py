"""The influence map (Fig. 9): geodesic weights, normalisation, picture."""

import numpy as np

from faceforge.skin.influence import (apply_influence, influence_weights, save_influence_png,
                                         smoothstep_falloff)
from tests.skin.synthetic import sphere


def test_falloff_ends_and_monotone():
    t = np.linspace(-0.5, 1.5, 201)
    w = smoothstep_falloff(t)
    assert np.all(w[t <= 0] == 1.0) and np.all(w[t >= 1] == 0.0)
    assert np.all(np.diff(w) <= 0)


def test_weights_one_at_sources_zero_at_the_back():
    v, f = sphere(1.0, 3)
    front = np.flatnonzero(v[:, 2] > 0.8)
    back = int(np.argmin(v[:, 2]))
    w, d, scale = influence_weights(v, f, front, back_vertex=back)
    assert np.all(w[front] == 1.0) and w[back] == 0.0
    assert np.all((w >= 0) & (w <= 1))
    # the heat-method distance approximates the great-circle distance to the
    # sources within its smoothing error (~1.5 edge lengths on this coarse sphere)
    great = np.arccos(np.clip(v @ v[front].T, -1, 1)).min(axis=1)
    edge = np.linalg.norm(v[f[:, 0]] - v[f[:, 1]], axis=1).mean()
    assert np.abs(d - great).max() < 1.5 * edge
    assert np.corrcoef(d, great)[0, 1] > 0.99
    assert abs(scale - d[back]) < 1e-12
    # weights fall with distance
    order = np.argsort(d)
    assert np.all(np.diff(w[order]) <= 1e-12)


def test_unreachable_vertices_get_zero():
    v1, f1 = sphere(1.0, 1)
    v2, f2 = sphere(1.0, 1, center=(5, 0, 0))
    v = np.concatenate([v1, v2])
    f = np.concatenate([f1, f2 + len(v1)])
    w, d, _ = influence_weights(v, f, [0])
    assert np.all(w[len(v1):] == 0.0) and np.all(np.isinf(d[len(v1):]))


def test_apply_influence_interpolates():
    rest = np.zeros((3, 3))
    sim = np.ones((3, 3))
    out = apply_influence(rest, sim, [1.0, 0.5, 0.0])
    np.testing.assert_allclose(out[:, 0], [1.0, 0.5, 0.0])


def test_png_is_written(tmp_path):
    import matplotlib.image as mpimg

    v, f = sphere(1.0, 2)
    w = np.clip(v[:, 2], 0, 1)
    path = tmp_path / "influence.png"
    save_influence_png(path, v, f, w)
    img = mpimg.imread(path)
    red = (img[:, :, 0] > 0.45) & (img[:, :, 2] < 0.2)
    blue = (img[:, :, 2] > 0.45) & (img[:, :, 0] < 0.2)
    assert red.any() and blue.any()
