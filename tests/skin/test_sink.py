"""The one-sided hold (``skin.lid_hold_sink``, faceforge.skin.sink): held skin follows its
neighbours down and toward the nose, not up nor away.

``skin.lid_hold`` held the upper lid's skin against a raised brow (the MakeHuman brow units
+0.07 in cosine) and against a lowered one alike, so the played lowered brows stopped short
(docs/notes/brows15.md); with the sink a lowered brow may carry the lid's skin down."""

import numpy as np
import pytest

from faceforge.pbd import SolverSettings
from faceforge.skin.binding import Body, bind_skin
from faceforge.skin.layer import SkinSimulation, SkinStiffness
from faceforge.skin.sink import sink, sink_args, sink_plain
from tests.skin.synthetic import sphere
from tests.skin.test_carry import Bodies


def test_compiled_twin_follows_only_the_sinking_and_the_draw_toward_the_nose():
    rng = np.random.default_rng(5)
    rest = rng.normal(size=(6, 3))
    ids = np.array([0, 1, 1, 2, 4, 5])
    medial = np.array([[-1.0, 0.3, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    rows, vid, p0, up, m = sink_args(rest, ids, [0, 2, 4, 5], up=(0.0, 2.0, 0.0), medial=medial)
    np.testing.assert_allclose(up, [0, 1, 0])
    np.testing.assert_allclose(m, [[-1, 0, 0], [1, 0, 0], [1, 0, 0], [0, 0, 0]])   # unit, across up
    pos = rest + rng.normal(size=rest.shape)
    t = rng.normal(size=(len(ids), 3))
    a = sink_plain(t.copy(), rows, vid, p0, up, m, pos, 0.7)
    b = t.copy()
    sink(b, rows, vid, p0, up, m, pos, 0.7)
    np.testing.assert_allclose(a, b, atol=1e-12)
    d = pos[vid] - rest[vid]
    h, g = np.minimum(d[:, 1], 0), np.maximum((d * m).sum(axis=1), 0)
    np.testing.assert_allclose(a[rows] - t[rows], 0.7 * (np.c_[0 * h, h, 0 * h] + g[:, None] * m), atol=1e-12)
    untouched = np.setdiff1d(np.arange(len(ids)), rows)
    np.testing.assert_array_equal(a[untouched], t[untouched])
    still = t.copy()
    sink(still, rows, vid, p0, up, m, rest, 1.0)       # at rest nothing moves
    np.testing.assert_array_equal(still, t)
    none = sink_args(rest, ids, [0, 2], medial=None)[4]
    np.testing.assert_array_equal(none, np.zeros((2, 3)))


def test_toward_nose_points_from_each_eyes_outer_corner_to_its_inner_one():
    from faceforge.skin.brow import toward_nose
    from tests.skin.test_brow import EYE_LANDMARKS, LANDMARKS

    pts = np.array([[31.5, 4.0, 1.0], [-31.5, 4.0, 1.0], [2.0, 6.0, 0.0]])
    np.testing.assert_allclose(toward_nose(pts, EYE_LANDMARKS), [[-1, 0, 0], [1, 0, 0], [-1, 0, 0]])
    mpeg = {**EYE_LANDMARKS, "3.12": (-44.0, 0.0, 0.0), "3.8": (-19.0, 0.0, 0.0)}   # MPEG-4's naming
    np.testing.assert_allclose(toward_nose(pts, mpeg), [[-1, 0, 0], [1, 0, 0], [-1, 0, 0]])
    assert not toward_nose(pts, LANDMARKS).any()


@pytest.fixture(scope="module")
def bound():
    v, f = sphere(1.0, 2)
    bone = Body("cranium", "cranium", *sphere(0.8, 3))
    return v, f, bone, bind_skin(v, f, [bone], max_distance=0.5)


def _drift(bound, share: float, pull) -> np.ndarray:
    """(n_held, 3) motion of the held skin (x < -0.3, carried, tethered at 0.5, toward the nose
    +x) when the skin over x > -0.1 is moved by ``pull`` (3,) by hand and the bone stays;
    ``share`` the sink (None: off)."""
    v, f, bone, b = bound
    far = v[b.vertex_ids, 0] < -0.3
    rows = np.flatnonzero(far)
    sim = SkinSimulation(v, f, b, SkinStiffness(), SolverSettings(iterations=10), carried=far,
                         tether=np.where(far, 0.5, 0.0),
                         sink=None if share is None else (rows, share, (0.0, 1.0, 0.0),
                                                          np.tile([1.0, 0.0, 0.0], (len(rows), 1))))
    body = Bodies(bone.vertices, bone.faces)
    pulled = v[:, 0] > -0.1
    for _ in range(80):
        sim.step(body, 1 / 25)
        sim.state.positions[sim.layer.first + np.flatnonzero(pulled)] = v[pulled] + np.asarray(pull)
    held = np.unique(b.vertex_ids[far])
    return sim.simulated()[held] - v[held]


def test_held_skin_sinks_with_its_neighbours_but_does_not_rise(bound):
    down, up = (0.0, -0.2, 0.0), (0.0, 0.2, 0.0)
    two_down, one_down = _drift(bound, None, down)[:, 1].min(), _drift(bound, 1.0, down)[:, 1].min()
    two_up, one_up = _drift(bound, None, up)[:, 1].max(), _drift(bound, 1.0, up)[:, 1].max()
    assert one_down < 1.5 * two_down < 0.0          # follows a lowered neighbour further down
    assert 0.0 < one_up <= 1.05 * two_up            # a raise is held as before
    np.testing.assert_allclose(_drift(bound, 0.0, down), _drift(bound, None, down), atol=1e-12)   # 0: two-sided


def test_held_skin_follows_a_pull_toward_the_nose_not_away(bound):
    nose, away = (0.2, 0.0, 0.0), (-0.2, 0.0, 0.0)
    assert _drift(bound, 1.0, nose)[:, 0].mean() > 1.5 * _drift(bound, None, nose)[:, 0].mean() > 0.0
    assert 0.0 > _drift(bound, 1.0, away)[:, 0].mean() >= 1.1 * _drift(bound, None, away)[:, 0].mean()


def test_the_default_config_keeps_the_two_sided_hold():
    from faceforge.io.config import ConfigError, load_config

    assert float(load_config().get("skin.lid_hold_sink")) == 0.0
    with pytest.raises(ConfigError):
        load_config(sets=["skin.lid_hold_sink=1.5"])
