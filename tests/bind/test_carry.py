"""Carried anchors (``skin.carry``): the skin goes where the tissue under it goes.

The paper's anchor (§8) is a stretch of rest length |p - q|; it passes on only the part of
the anchor's motion along p - q. A carried anchor holds q (and so p) at the skin vertex's
rest offset from its surface point, turned with the anchor triangle's frame.
"""

import numpy as np
import pytest

from faceforge.anatomy.binding import Body, bind_skin
from faceforge.anatomy.skin import SkinSimulation, SkinStiffness
from faceforge.pbd import SolverSettings
from tests.bind.synthetic import sphere


class Bodies:
    """The part of MusculoskeletalSystem a SkinSimulation reads: one body, moved by hand."""

    def __init__(self, v, f):
        self.rest, self.v, self.f = v.copy(), v.copy(), f

    def world(self, rest=False):
        return (self.rest if rest else self.v).copy(), self.f

    def world_view(self):
        return self.v

    def face_range(self, name):
        return slice(0, len(self.f))


@pytest.fixture(scope="module")
def bound():
    v, f = sphere(1.0, 2)
    muscle = Body("muscle", "muscle", *sphere(0.8, 3))
    return v, f, muscle, bind_skin(v, f, [muscle], max_distance=0.5)


def _sim(bound, carry: bool):
    v, f, _, b = bound
    return SkinSimulation(v, f, b, SkinStiffness(), SolverSettings(iterations=10),
                          carried=np.full(len(b.vertex_ids), carry))


def _rotation(axis, angle):
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def test_carried_targets_follow_a_rigid_motion_of_the_body_exactly(bound):
    v, f, muscle, b = bound
    sim = _sim(bound, True)
    body = Bodies(muscle.vertices, muscle.faces)
    r, t = _rotation([0.3, 1.0, -0.2], 0.4), np.array([0.05, -0.1, 0.2])
    body.v = body.rest @ r.T + t
    got = sim.carry_targets(body, sim.anchor_targets(body))
    np.testing.assert_allclose(got, v[b.vertex_ids] @ r.T + t, rtol=0, atol=1e-12)


def test_the_rest_state_with_carried_anchors_is_a_fixed_point(bound):
    """The carried targets at rest are the skin's rest positions to the bit; the skin's own
    constraints (as with the paper's anchors) stay within round-off over 1,000 frames."""
    v, f, muscle, b = bound
    sim = _sim(bound, True)
    body = Bodies(muscle.vertices, muscle.faces)
    assert np.array_equal(sim.carry_targets(body, sim.anchor_targets(body)), v[b.vertex_ids])
    for _ in range(1000):
        sim.step(body, 1 / 25)
    assert np.abs(sim.simulated() - v).max() < 1e-12 * np.linalg.norm(np.ptp(v, axis=0))


def test_carried_skin_turns_with_a_body_turning_under_it(bound):
    """The body turns 0.1 rad about the vertical axis (its surface slides sideways under the
    skin): the settled skin is the rest skin turned, to 5 % of the motion."""
    v, f, muscle, _ = bound
    r = _rotation([0.0, 1.0, 0.0], 0.1)
    sim = _sim(bound, True)
    body = Bodies(muscle.vertices, muscle.faces)
    body.v = body.rest @ r.T
    for _ in range(150):
        sim.step(body, 1 / 25)
    err = np.linalg.norm(sim.simulated() - v @ r.T, axis=1).max()
    assert err < 0.05 * np.linalg.norm(v @ r.T - v, axis=1).max()
