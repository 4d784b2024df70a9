"""geometry.rigid: the similarity and rigid transforms, and the motion of the still part."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from faceforge.geometry.rigid import rigid_transform, similarity_transform, still_part_motion


def _points(n=200, seed=0):
    return np.random.default_rng(seed).normal(size=(n, 3))


def test_rigid_and_similarity_recover_their_transforms():
    p = _points()
    R = Rotation.from_euler("xyz", [10, -35, 60], degrees=True).as_matrix()
    t = np.array([1.0, -2.0, 0.5])
    rigid = rigid_transform(p, p @ R.T + t)
    assert np.allclose(rigid[:3, :3], R) and np.allclose(rigid[:3, 3], t)
    sim = similarity_transform(p, 1.7 * p @ R.T + t)
    assert np.allclose(sim[:3, :3], 1.7 * R) and np.allclose(sim[:3, 3], t)
    # a mirror image is fitted by the nearest proper rotation, never a reflection
    assert np.linalg.det(rigid_transform(p, p * [-1, 1, 1])[:3, :3]) == pytest.approx(1.0)


def test_still_part_motion_ignores_the_part_that_moves_on_its_own():
    """A third of the points moves by itself (an expression) on top of the whole set's motion (the
    head's): the trimmed fit gives the head's motion exactly; a plain fit to all does not."""
    p = _points(300, 1)
    R = Rotation.from_euler("xyz", [4, 15, -2], degrees=True).as_matrix()
    t = np.array([0.3, 0.1, -0.4])
    q = p.copy()
    moving = np.arange(len(p)) < 100
    q[moving] += np.array([0.0, -0.8, 0.3])
    q = q @ R.T + t
    motion, used = still_part_motion(p, q)
    assert np.allclose(motion[:3, :3], R, atol=1e-9) and np.allclose(motion[:3, 3], t, atol=1e-9)
    assert not used[moving].any()
    plain = rigid_transform(p, q)
    assert not np.allclose(plain[:3, 3], t, atol=1e-2)
