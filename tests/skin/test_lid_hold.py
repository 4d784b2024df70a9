"""The upper lid's hold (``skin.lid_hold``, faceforge.skin.brow.lid_hold): the skin of the upper
lids, tied to the bone, stays where the lids put it while the brow above it rises.

On the MakeHuman sample a brow raise dragged the upper lid's skin up with the brow (a quarter
to nearly half of each brow unit's solved field lay 1-2.5 cm under the brow line, where the
expression units are 0; docs/notes/brows11.md)."""

import numpy as np
import pytest

from faceforge.pbd import SolverSettings
from faceforge.skin.binding import Binding, Body, bind_skin
from faceforge.skin.brow import lid_hold
from faceforge.skin.layer import SkinSimulation, SkinStiffness
from tests.skin.synthetic import sphere
from tests.skin.test_brow import EYE_LANDMARKS, LANDMARKS
from tests.skin.test_carry import Bodies


#  upper lid on the bone, upper lid on a muscle, lower lid on the bone, the brow on the bone,
#  the other eye's upper lid on the bone (two anchors: bone and muscle)
_Binding = Binding(body_names=("frontalis_inner_L", "cranium", "mandible"), status=np.zeros(5, np.int8),
                   vertex_ids=np.array([0, 1, 2, 3, 4, 4]), body=np.array([1, 0, 1, 1, 1, 0]),
                   face_ids=np.zeros(6, np.int64), bary=np.zeros((6, 3)), points=np.zeros((6, 3)),
                   distance=np.zeros(6), outward=np.zeros(6, bool), normals=np.zeros((5, 3)))


VERTICES = np.array([[31.5, 4.0, 1.0], [31.0, 3.0, 1.0], [31.5, -4.0, 1.0], [30.0, 24.0, 0.0], [-31.5, 4.0, 1.0]])


def test_lid_hold_picks_the_upper_lids_anchors_on_the_bone():
    tether, held = lid_hold(_Binding, VERTICES, EYE_LANDMARKS, 0.8)
    assert held.tolist() == [True, False, False, False, True, False]
    np.testing.assert_array_equal(tether, [0.8, 0, 0, 0, 0.8, 0])


def test_lid_hold_off_or_without_the_eyes_holds_nothing():
    for stiffness, landmarks in ((0.0, EYE_LANDMARKS), (1.0, LANDMARKS)):
        tether, held = lid_hold(_Binding, VERTICES, landmarks, stiffness)
        assert tether is None and not held.any()


@pytest.fixture(scope="module")
def bound():
    v, f = sphere(1.0, 2)
    bone = Body("cranium", "cranium", *sphere(0.8, 3))
    return v, f, bone, bind_skin(v, f, [bone], max_distance=0.5)


def _drift(bound, hold: bool) -> float:
    """Largest drift of the skin over x < -0.3 when the skin over x > 0.6 is pulled up 0.1 (its
    anchors' targets moved by hand) and the bone stays: held (carried, tethered at 1) or by the
    §8 stretch of the other anchors."""
    v, f, bone, b = bound
    far = v[b.vertex_ids, 0] < -0.3
    carried = far if hold else np.zeros(len(b.vertex_ids), bool)
    sim = SkinSimulation(v, f, b, SkinStiffness(), SolverSettings(iterations=10), carried=carried,
                         tether=np.where(far, 1.0, 0.0) if hold else None)
    body = Bodies(bone.vertices, bone.faces)
    pulled = v[:, 0] > 0.6
    for _ in range(60):
        sim.step(body, 1 / 25)
        sim.state.positions[sim.layer.first + np.flatnonzero(pulled), 1] = v[pulled, 1] + 0.1
    d = np.linalg.norm(sim.simulated() - v, axis=1)
    return float(d[v[:, 0] < -0.3].max())


def test_held_skin_stays_while_its_neighbours_are_pulled(bound):
    assert _drift(bound, True) < 0.5 * _drift(bound, False)


def test_the_default_config_leaves_the_lids_to_the_stretch():
    from faceforge.io.config import ConfigError, load_config

    assert float(load_config().get("skin.lid_hold")) == 0.0
    with pytest.raises(ConfigError):
        load_config(sets=["skin.lid_hold=2"])
