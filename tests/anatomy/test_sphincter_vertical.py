"""The sphincter's closure in the up frame (``muscle.sphincter.closure_vertical``,
``muscle.sphincter.eversion_up``): with the lips pushed out, a closure that narrows the ring without
lowering the upper lip, and an eversion that turns the lips up and down, not the corners out, on a
mouth whose fitted ellipse is taller than wide (faceforge.anatomy.muscles.sphincter)."""

import numpy as np
import pytest

from faceforge.anatomy.muscles.sphincter import (VERTICAL_RAMP, fit_ellipse, sphincter_displacement,
                                                 vertical_share)

from tests.anatomy.conftest import chin_mouth_on, icosphere, jostled, planar_mouth

FWD = np.array([0.0, 0.0, 1.0])


def test_closure_vertical_narrows_the_ring_and_keeps_its_height():
    inner, outer = planar_mouth()
    c, top, corner = 0.5, 6, 0                      # sin = 1: the upper lip's midline; cos = 1: a corner
    paper = sphincter_displacement(inner, outer, c)
    flat = sphincter_displacement(inner, outer, c, vertical=0.0)
    assert paper[top, 1] < -0.3 * c                 # the paper's closure pulls the upper lip down
    np.testing.assert_allclose(flat[:, 1], 0.0, atol=1e-12)      # up is +Y here: no vertical pull
    np.testing.assert_allclose(flat[:, 0], paper[:, 0], atol=1e-12)   # the corners come in as before
    assert flat[corner, 0] < -0.1
    np.testing.assert_allclose(sphincter_displacement(inner, outer, c, vertical=0.5), 0.5 * (paper + flat),
                               atol=1e-12)
    # the protrusion and the lower part are not touched by it
    np.testing.assert_allclose(sphincter_displacement(inner, outer, 0.0, 0.3, FWD, 0.2, vertical=0.0),
                               sphincter_displacement(inner, outer, 0.0, 0.3, FWD, 0.2), atol=1e-12)


def test_eversion_up_turns_the_lips_out_not_the_corners():
    inner, outer = planar_mouth(tall=2.5)                  # the fitted ellipse is taller than wide
    o, da, db, a, b = fit_ellipse(np.concatenate([inner, outer]))
    assert abs(db[0]) > 0.99                        # its minor axis runs across the mouth
    top, corner = 6, 0
    old = sphincter_displacement(inner, outer, 0.0, 0.3, FWD)
    new = sphincter_displacement(inner, outer, 0.0, 0.3, FWD, eversion_up=True)
    assert old[corner, 0] > 0.05                    # along dir_b the eversion spreads the corners
    assert abs(new[corner, 0]) < 1e-12 and new[top, 1] > 0.05     # along up: the upper lip goes up
    np.testing.assert_allclose(new[:, 2], old[:, 2], atol=1e-12)  # the same forward push
    # a mouth whose minor axis is vertical: the same eversion either way
    wide_in, wide_out = planar_mouth()
    np.testing.assert_allclose(sphincter_displacement(wide_in, wide_out, 0.0, 0.3, FWD, eversion_up=True),
                               sphincter_displacement(wide_in, wide_out, 0.0, 0.3, FWD), atol=1e-12)


@pytest.fixture(scope="module")
def sphere():
    return icosphere(3)


def _mouth_on(v, f, **kw):
    return chin_mouth_on(v, f, protrusion=0.5, **kw)


def test_compiled_up_frame_matches_the_numpy_twin(sphere):
    v, f = sphere
    base = _mouth_on(v, f)
    scale = float(np.ptp(v, axis=0).max())
    rng = np.random.default_rng(5)
    for kw in ({"closure_vertical": 0.0}, {"closure_vertical": 0.3, "eversion_up": True}):
        sph = _mouth_on(v, f, **kw)
        g = sph.bound_grid
        for trial in range(4):
            now = jostled(v, rng, trial)
            points = {k: line.positions(now, f) for k, line in sph.lines.items()}
            for c, lift in ((0.3, 0.1), (1.0, 0.4)):
                fast = sph.targets_from_line_points(c, points, lift)
                vert = vertical_share(sph.closure_vertical, lift, True)
                twin = sph._grid_targets(c, points, sph._lift(lift), 0.0, vert)[g[:, 0], g[:, 1]]
                assert np.allclose(fast, twin, rtol=0.0, atol=1e-12 * scale)
                assert not np.allclose(fast, base.targets_from_line_points(c, points, lift), rtol=0.0,
                                       atol=1e-6 * scale)


def test_closure_vertical_is_checked(sphere):
    v, f = sphere
    with pytest.raises(ValueError, match="closure_vertical"):
        _mouth_on(v, f, closure_vertical=-0.1)


def test_the_closure_alone_keeps_the_papers_shape(sphere):
    """The share follows the protrusion drive: the closure alone (lips pressed, the upper lip
    lowered: FAP 4/51, anger) is the paper's; with the lips pushed out the ring keeps its height."""
    assert vertical_share(0.0, 0.0, True) == 1.0 and vertical_share(0.0, VERTICAL_RAMP, True) == 0.0
    assert vertical_share(0.2, 0.5 * VERTICAL_RAMP, True) == pytest.approx(0.6) and vertical_share(0.0, 1.0, False) == 1.0
    assert vertical_share(0.0, 2.0, True) == 0.0 and vertical_share(0.0, -1.0, True) == 1.0
    v, f = sphere
    base, flat = _mouth_on(v, f), _mouth_on(v, f, closure_vertical=0.0)
    points = {k: line.positions(v, f) for k, line in flat.lines.items()}
    np.testing.assert_allclose(flat.targets_from_line_points(0.8, points), base.targets_from_line_points(0.8, points),
                               atol=1e-12)
    moved = flat.targets_from_line_points(0.8, points, 1.0) - base.targets_from_line_points(0.8, points, 1.0)
    assert np.abs(moved).max() > 1e-3
