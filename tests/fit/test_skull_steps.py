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
