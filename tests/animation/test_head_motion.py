"""Rigid head motion from FAPs 48-50 (animation.head_motion)."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from faceforge.animation.head_motion import (AU, HEAD_FAPS, head_angles, head_rotations, neck_weights,
                                           turn_head)

FORWARD, UP, LEFT = np.eye(3)[2], np.eye(3)[1], np.eye(3)[0]


def test_angles_come_from_faps_48_to_50_in_angle_units():
    faps = np.zeros((2, 68))
    faps[1, [47, 48, 49]] = [1000.0, -2000.0, np.nan]
    faps[1, 46] = 5e5                       # FAP 47 is not a head FAP
    assert HEAD_FAPS == (48, 49, 50)
    np.testing.assert_array_equal(head_angles(faps), [[0, 0, 0], [1000 * AU, -2000 * AU, 0]])
    with pytest.raises(ValueError, match="68"):
        head_angles(np.zeros((2, 40)))


def test_signs_follow_the_fap_table():
    """pitch positive down, yaw positive to the subject's left (+X), roll positive right: the
    top of the head tilts to the subject's right (-X)."""
    pitch, yaw, roll = head_rotations(np.diag([0.1, 0.1, 0.1]))
    assert (pitch @ FORWARD)[1] < -0.09 and (pitch @ LEFT) == pytest.approx(LEFT)
    assert (yaw @ FORWARD)[0] > 0.09 and (yaw @ UP) == pytest.approx(UP)
    assert (roll @ UP)[0] < -0.09 and (roll @ FORWARD) == pytest.approx(FORWARD)


def test_composition_is_yaw_pitch_roll():
    """The plain twin: scipy's intrinsic Y-X-Z Euler angles (yaw about Y, then pitch about the
    turned X, then roll about the turned Z) are R_yaw @ R_pitch @ R_roll."""
    rng = np.random.default_rng(3)
    a = rng.uniform(-0.6, 0.6, (20, 3))
    r = head_rotations(a)
    twin = Rotation.from_euler("YXZ", a[:, [1, 0, 2]]).as_matrix()
    np.testing.assert_allclose(r, twin, atol=1e-14)
    np.testing.assert_allclose(r @ r.transpose(0, 2, 1), np.broadcast_to(np.eye(3), r.shape), atol=1e-14)
    assert np.allclose(np.linalg.det(r), 1.0)


def test_turn_is_rigid_about_the_pivot_and_exact_where_still():
    rng = np.random.default_rng(4)
    frames = rng.normal(size=(3, 50, 3))
    pivot = np.array([0.2, -0.1, 0.4])
    frames[:, 0] = pivot
    angles = np.array([[0.0, 0.0, 0.0], [0.05, -0.02, 0.03], [0.0, 0.3, 0.0]])
    out = turn_head(frames, angles, pivot)
    assert out[0].tobytes() == frames[0].tobytes()                  # no turn: the same bits
    np.testing.assert_allclose(out[1:, 0], frames[1:, 0], atol=1e-15)  # the pivot stays
    for f in (1, 2):                                                # distances are kept
        d0 = np.linalg.norm(frames[f][:, None] - frames[f][None], axis=-1)
        d1 = np.linalg.norm(out[f][:, None] - out[f][None], axis=-1)
        np.testing.assert_allclose(d1, d0, atol=1e-12)
    back = np.einsum("ji,nj->ni", head_rotations(angles[2:])[0], out[2] - pivot) + pivot
    np.testing.assert_allclose(back, frames[2], atol=1e-12)         # R^T undoes it
    assert out.dtype == frames.dtype and not np.shares_memory(out, frames)
    with pytest.raises(ValueError, match="angles"):
        turn_head(frames, angles[:2], pivot)


def test_the_neck_fades_out_of_the_turn():
    rest = np.zeros((5, 3))
    rest[:, 1] = [2.0, 1.0, 0.5, 0.0, -1.0]
    np.testing.assert_allclose(neck_weights(rest, 1.0, 1.0), [1.0, 1.0, 0.5, 0.0, 0.0])
    np.testing.assert_array_equal(neck_weights(rest, 1.0, 0.0), np.ones(5))   # no fade
    frames = np.repeat(rest[None] + [0.3, 0.0, 0.2], 2, axis=0)
    angles = np.array([[0.0, 0.0, 0.0], [0.1, 0.2, -0.1]])
    pivot = np.array([0.0, 1.5, 0.0])
    out = turn_head(frames, angles, pivot, neck_weights(rest, 1.0, 1.0))
    whole = turn_head(frames, angles, pivot)
    np.testing.assert_array_equal(out[1, :2], whole[1, :2])     # the head turns rigidly
    assert out[1, 3:].tobytes() == frames[1, 3:].tobytes()      # the neck's base stays
    half = head_rotations(0.5 * angles[1:])[0] @ (frames[1, 2] - pivot) + pivot
    np.testing.assert_allclose(out[1, 2], half, atol=1e-15)     # half-way: half the angles
    assert out[0].tobytes() == frames[0].tobytes()
    with pytest.raises(ValueError, match="weights"):
        turn_head(frames, angles, pivot, np.ones(4))
