"""The modiolus (anatomy.muscles.modiolus): the sphincter's corners ride on the muscles inserting
there, on the synthetic head of conftest.py with a depressor at each mouth corner."""

import numpy as np
import pytest

from faceforge.anatomy.layers import MusculoskeletalSystem
from faceforge.anatomy.muscles.modiolus import Modiolus, attach_modiolus

from tests.anatomy.conftest import ring_with_pair

CENTRE, OUTER = (0.0, -0.3), (0.32, 0.17)


@pytest.fixture(scope="module")
def parts():
    """Skull, a depressor per side (layer 0, on the bone, inserting at the ring's corner) and the
    ring (layer 1, on the bone only: without the modiolus the depressors cannot move it)."""
    return ring_with_pair("depressor_anguli", [(0.30, -0.75), (0.42, -0.72)], [(0.30, -0.33), (0.36, -0.30)],
                          (0.15, 0.07), CENTRE, OUTER)


def corner_motion(parts, tie: bool, controls: dict, frames: int = 60):
    """Mean displacement of the ring's bottom particles within 0.1 of each corner (x > 0, x < 0)
    after ``frames`` steps, and the system."""
    system = MusculoskeletalSystem.from_parts(*parts)
    if tie:
        assert attach_modiolus(system, muscles=("depressor_anguli", "levator_anguli"), radius=0.3) is not None
    rest = system.rest_positions("orbicularis_oris")
    for _ in range(frames):
        system.step(controls)
    d = system.positions("orbicularis_oris") - rest
    out = []
    for s in (1.0, -1.0):
        near = np.linalg.norm(rest[:, :2] - [s * OUTER[0], CENTRE[1]], axis=1) < 0.1
        out.append(d[near].mean(axis=0))
    return out, system


def test_the_corner_follows_the_depressor_only_with_the_modiolus(parts):
    (left, right), system = corner_motion(parts, True, {"depressor_anguli_L": 1.0})
    ins = system.positions("depressor_anguli_L") - system.rest_positions("depressor_anguli_L")
    t = system.muscles["depressor_anguli_L"].topology
    pull = ins[t.bottom(t.h - 1, np.arange(t.w))].mean(axis=0)
    assert pull[1] < -0.05                       # the insertion moves down
    assert left[1] < 0.5 * pull[1]               # the ring's corner goes with it
    assert abs(right[1]) < 0.2 * abs(left[1])    # the other corner stays
    (free, _), _ = corner_motion(parts, False, {"depressor_anguli_L": 1.0})
    assert abs(free[1]) < 0.2 * abs(left[1])     # untied, the ring lies on the bone alone


def test_rest_is_a_fixed_point_and_the_jaw_alone_is_untouched(parts):
    (left, right), system = corner_motion(parts, True, {}, frames=5)
    assert np.abs(left).max() < 1e-12 and np.abs(right).max() < 1e-12
    (a, b), _ = corner_motion(parts, True, {"orbicularis_oris": 0.5}, frames=20)
    (c, d), _ = corner_motion(parts, False, {"orbicularis_oris": 0.5}, frames=20)
    np.testing.assert_allclose(np.r_[a, b], np.r_[c, d], atol=1e-12)   # no inserting muscle active


def test_both_sides_pull_the_corners_as_mirror_images(parts):
    (left, right), _ = corner_motion(parts, True, {"depressor_anguli_L": 0.7, "depressor_anguli_R": 0.7})
    np.testing.assert_allclose(left * [-1, 1, 1], right, atol=0.02 * np.linalg.norm(left))


def test_the_tie_ramps_in_with_the_summed_contraction():
    rest = {"A3": np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])}
    world = np.zeros((4, 3))
    world[0] = [1.0, 0.0, 0.0]     # side 0's insertion end at the left corner
    world[1] = [-1.0, 0.0, 0.0]
    m = Modiolus(rest, [([0], [[0]]), ([1], [[1]])], world, radius=0.5, ramp=0.1)
    np.testing.assert_allclose(m.weights["A3"], [[1, 0, 0], [0, 0, 1]])
    moved = world.copy()
    moved[0] += [0.0, -0.2, 0.0]
    for c, g in ((0.0, 0.0), (0.05, 0.5), (0.3, 1.0)):
        out = m.apply(rest, moved, np.array([c, 0.0]))
        np.testing.assert_allclose(out["A3"][0], rest["A3"][0] + [0.0, -0.2 * g, 0.0])
        np.testing.assert_allclose(out["A3"][1:], rest["A3"][1:])
