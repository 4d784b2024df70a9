"""The sphincter's bulge (``muscle.sphincter.bulge``): as the ring closes, its lips also move forward
by ``bulge`` times the length of their own closure (the orbicularis, shortening round the teeth,
pushes the lips forward off them); faceforge.anatomy.muscles.sphincter."""

import numpy as np
import pytest

from faceforge.anatomy.muscles.sphincter import VERTICAL_RAMP, bulge_share, sphincter_displacement, vertical_share

from tests.anatomy.conftest import chin_mouth_on, icosphere, jostled, planar_mouth

FWD = np.array([0.0, 0.0, 1.0])


def test_bulge_moves_the_lips_forward_by_their_closure():
    inner, outer = planar_mouth()
    c, top, corner = 0.4, 6, 0
    for kw in ({}, {"vertical": 0.0}, {"lift": 0.3, "low": 0.2}):
        lift, low = kw.pop("lift", 0.0), kw.pop("low", 0.0)
        flat = sphincter_displacement(inner, outer, c, lift, FWD, low, **kw)
        bulged = sphincter_displacement(inner, outer, c, lift, FWD, low, bulge=1.5, **kw)
        closure = sphincter_displacement(inner, outer, c, 0.0, FWD, **kw)    # the in-plane part alone
        extra = bulged - flat
        np.testing.assert_allclose(extra[:, :2], 0.0, atol=1e-12)       # only along the plane's normal
        np.testing.assert_allclose(extra[:, 2], 1.5 * np.linalg.norm(closure, axis=1), atol=1e-12)
        assert extra[corner, 2] > extra[top, 2] > 0.0                   # the corners close, and bulge, most
    back = sphincter_displacement(inner, outer, c, 0.0, -FWD, bulge=1.0) - sphincter_displacement(inner, outer, c)
    assert np.all(back[:, 2] <= 1e-12) and back[corner, 2] < -0.05     # toward `forward`, whichever side
    # a relaxed ring does not bulge, nor does a ring that only protrudes
    assert np.array_equal(sphincter_displacement(inner, outer, 0.0, bulge=1.0), np.zeros((len(inner), 3)))
    np.testing.assert_allclose(sphincter_displacement(inner, outer, 0.0, 0.3, FWD, bulge=1.0),
                               sphincter_displacement(inner, outer, 0.0, 0.3, FWD), atol=0.0)


@pytest.fixture(scope="module")
def sphere():
    return icosphere(3)


def test_compiled_bulge_matches_the_numpy_twin(sphere):
    v, f = sphere
    scale = float(np.ptp(v, axis=0).max())
    base = chin_mouth_on(v, f, protrusion=0.5, closure_vertical=0.0, eversion_up=True)
    sph = chin_mouth_on(v, f, protrusion=0.5, closure_vertical=0.0, eversion_up=True, bulge=1.0)
    assert sph.bulge == 1.0 and base.bulge == 0.0
    g = sph.bound_grid
    rng = np.random.default_rng(9)
    for trial in range(4):
        now = jostled(v, rng, trial)
        points = {k: line.positions(now, f) for k, line in sph.lines.items()}
        for c, lift in ((0.3, 0.1), (1.0, 0.4)):
            fast = sph.targets_from_line_points(c, points, lift)
            vert, bul = vertical_share(sph.closure_vertical, lift, True), bulge_share(sph.bulge, lift, True)
            twin = sph._grid_targets(c, points, sph._lift(lift), 0.0, vert, bul)[g[:, 0], g[:, 1]]
            assert np.allclose(fast, twin, rtol=0.0, atol=1e-12 * scale)
            assert not np.allclose(fast, base.targets_from_line_points(c, points, lift), rtol=0.0,
                                   atol=1e-6 * scale)
        # relaxed, or closing without pushing the lips out (a lip press): no bulge
        np.testing.assert_allclose(sph.targets_from_line_points(0.0, points, 0.3),
                                   base.targets_from_line_points(0.0, points, 0.3), rtol=0.0, atol=0.0)
        np.testing.assert_allclose(sph.targets_from_line_points(0.8, points, 0.0),
                                   base.targets_from_line_points(0.8, points, 0.0), rtol=0.0, atol=0.0)


def test_the_bulge_follows_the_protrusion_drive():
    """As the closure's vertical share: the closure alone (lips pressed) is the paper's, a ring that
    pushes its lips out bulges them in full from a drive of VERTICAL_RAMP on."""
    assert bulge_share(1.5, 0.0, True) == 0.0 and bulge_share(1.5, VERTICAL_RAMP, True) == 1.5
    assert bulge_share(1.5, 0.5 * VERTICAL_RAMP, True) == pytest.approx(0.75) and bulge_share(1.5, 1.0, False) == 0.0
    assert bulge_share(0.0, 1.0, True) == 0.0 and bulge_share(1.0, 2.0, True) == 1.0


def test_bulge_is_checked(sphere):
    v, f = sphere
    for bad in (-0.1, np.inf):
        with pytest.raises(ValueError, match="bulge"):
            chin_mouth_on(v, f, bulge=bad)
