"""The cheek's tether (``skin.cheek_tether``): skin anchored on the cheek raiser follows it.

A patch of tissue rising under a skin held all around (the cheek under the lower lid, AU6)
drags its skin only part of the way when each skin vertex shares a §8 stretch of 0.2 with
its anchor particle; tethered (the whole correction on the skin vertex), the skin goes most
of the way. On the MakeHuman sample the raiser at c = 1 lifted FDP 5.3 94 ENS untethered and
199 tethered (MediaPipe 46 and 155; the Xface files ask 150).
"""

import numpy as np
import pytest

from faceforge.pbd import SolverSettings
from faceforge.skin.binding import Body, bind_skin
from faceforge.skin.cheek import cheek_tether
from faceforge.skin.layer import SkinSimulation, SkinStiffness, _anchor_stiffness
from tests.skin.synthetic import sphere
from tests.skin.test_carry import Bodies


@pytest.fixture(scope="module")
def bound():
    v, f = sphere(1.0, 2)
    muscle = Body("muscle", "muscle", *sphere(0.8, 3))
    return v, f, muscle, bind_skin(v, f, [muscle], max_distance=0.5)


def _rise(bound, tether):
    """Mean rise of the skin over a cap of the body (the skin's x > 0.9; the body's x > 0.6) that moves up 0.1 while the
    rest of the body stays, after 100 frames of 10 iterations; carried anchors."""
    v, f, muscle, b = bound
    sim = SkinSimulation(v, f, b, SkinStiffness(), SolverSettings(iterations=10),
                         carried=np.ones(len(b.vertex_ids), bool), tether=tether)
    body = Bodies(muscle.vertices, muscle.faces)
    body.v = body.rest + 0.1 * (body.rest[:, 0] > 0.6)[:, None] * [0.0, 1.0, 0.0]
    for _ in range(100):
        sim.step(body, 1 / 25)
    d = sim.simulated()[:, 1] - v[:, 1]
    return float(d[v[:, 0] > 0.9].mean()), sim


def test_a_tethered_cheek_follows_its_rising_muscle(bound):
    """Untethered, the skin over the rising cap lags behind it (63 % of the way here); tethered
    it follows 90 %."""
    b = bound[3]
    loose, _ = _rise(bound, None)
    tight, _ = _rise(bound, np.ones(len(b.vertex_ids)))
    assert loose < 0.07, loose
    assert tight > 0.085, tight


def test_a_tethered_rest_is_a_fixed_point(bound):
    v, f, muscle, b = bound
    sim = SkinSimulation(v, f, b, SkinStiffness(), SolverSettings(iterations=10),
                         carried=np.ones(len(b.vertex_ids), bool), tether=np.ones(len(b.vertex_ids)))
    body = Bodies(muscle.vertices, muscle.faces)
    for _ in range(200):
        sim.step(body, 1 / 25)
    assert np.abs(sim.simulated() - v).max() < 1e-12 * np.linalg.norm(np.ptp(v, axis=0))


def test_cheek_tether_picks_the_cheek_muscles_anchors():
    class B:
        body_names = ("zygomaticus_major_L", "orbicularis_oculi_lower_L", "orbicularis_oculi_lower_R",
                      "orbicularis_oculi_L", "cranium")
        body = np.array([0, 1, 2, 3, 4, 1])

    got = cheek_tether(B, ["orbicularis_oculi_lower"], 0.7)
    np.testing.assert_array_equal(got, [0, 0.7, 0.7, 0, 0, 0.7])
    assert cheek_tether(B, ["orbicularis_oculi_lower"], 0.0) is None
    assert cheek_tether(B, ["buccinator"], 1.0) is None


def test_anchor_stiffness_checks_the_tether():
    k, tied = _anchor_stiffness(0.2, [0.0, 1.0, 0.5], 3)
    np.testing.assert_array_equal(k, [0.2, 1.0, 0.5])
    np.testing.assert_array_equal(tied, [False, True, True])
    with pytest.raises(ValueError):
        _anchor_stiffness(0.2, [0.0, 1.5], 2)


def test_the_default_config_tethers_the_cheek():
    from faceforge.io.config import load_config

    cfg = load_config()
    assert float(cfg.get("skin.cheek_tether")) > 0.2
    assert "orbicularis_oculi_lower" in cfg.get("bind.cheek_muscles")
