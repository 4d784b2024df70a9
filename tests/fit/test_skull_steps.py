"""The step limit of the enhancement flows (:func:`faceforge.fit.skull.limit_steps`, issue 28)."""

from __future__ import annotations

import numpy as np

from faceforge.fit.skull import limit_steps


def test_a_pair_moves_at_most_ratio_times_its_distance_to_the_nearest_held_target():
    held = np.array([[0.0, 0, 0], [10, 0, 0]])
    start = np.array([[1.0, 0, 0], [5, 0, 0], [9.5, 0, 0]])
    target = start + np.array([[0.0, 4, 0], [0, 0.5, 0], [0, 0, 0.1]])
    out = limit_steps(start, target, held, 0.25)
    step = np.linalg.norm(out - start, axis=1)
    assert np.allclose(step, [0.25, 0.5, 0.1])               # 0.25 * 1; short of 0.25 * 5; short of 0.125
    assert np.allclose(np.cross(out - start, target - start), 0.0)   # along the same direction
    assert np.array_equal(limit_steps(start, target, held, 0.0), target)
    assert np.array_equal(limit_steps(start, target, np.zeros((0, 3)), 0.25), target)


def _height_field(h, n: int = 161, half: float = 1.0):
    """A grid mesh z = h(x, y) over [-half, half]^2, faces wound up (+Z)."""
    x, y = np.meshgrid(np.linspace(-half, half, n), np.linspace(-half, half, n))
    v = np.stack([x.ravel(), y.ravel(), h(x, y).ravel()], axis=1)
    i = np.arange(n * n).reshape(n, n)
    a, b, c, d = i[:-1, :-1].ravel(), i[:-1, 1:].ravel(), i[1:, :-1].ravel(), i[1:, 1:].ravel()
    return v, np.vstack([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])


def test_the_tissue_normal_is_that_of_the_face_around_a_point_not_of_a_fold_it_sits_on():
    from faceforge.fit.skull import smoothed_normals
    from faceforge.fit.surface import SkinSurface

    # a flat face with a narrow, steep ridge (a lid fold); a point on the ridge's flank
    v, f = _height_field(lambda x, y: 0.08 * np.exp(-(x / 0.03) ** 2))
    skin = SkinSurface.build(v, f, close_holes=False)
    p = np.array([[0.03, 0.0, 0.08 * np.exp(-1.0)]])
    own = smoothed_normals(skin, p, 0.0)[0]
    assert own[2] < 0.6                                     # the fold's own normal leans far over
    avg = smoothed_normals(skin, p, 0.5)[0]
    assert np.isclose(np.linalg.norm(avg), 1.0) and avg[2] > 0.97
    assert np.allclose(smoothed_normals(skin, np.array([[0.5, 0.5, 0.0]]), 0.2)[0], [0, 0, 1], atol=1e-9)
    # a gentle slope is no fold: the point keeps its own normal
    v, f = _height_field(lambda x, y: 0.3 * x)
    skin = SkinSurface.build(v, f, close_holes=False)
    p = np.array([[0.0, 0.0, 0.0]])
    assert np.array_equal(smoothed_normals(skin, p, 0.5), smoothed_normals(skin, p, 0.0))
