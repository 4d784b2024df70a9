"""The sphincter's closure centre (``muscle.sphincter.closure_centre``): the closure pulls the inner
loop toward the mouth opening (the inner loop's mean) instead of the mean of both loops, which lies
below the mouth when the outer loop reaches down to the chin (faceforge.anatomy.muscles.sphincter)."""

import numpy as np
import pytest

from faceforge.anatomy.muscles.sphincter import fit_ellipse, sphincter_displacement

from tests.anatomy.conftest import chin_mouth_on, icosphere, jostled, planar_mouth


def test_closure_centre_moves_the_pull_to_the_mouth_opening():
    inner, outer = planar_mouth()
    o, da, db, a, b = fit_ellipse(np.concatenate([inner, outer]))
    assert o[1] < -0.1                                  # the paper's centre lies below the mouth
    c = 0.5
    paper = sphincter_displacement(inner, outer, c)
    moved = sphincter_displacement(inner, outer, c, centre=1.0)
    top = 6                                             # the upper lip's midline (sin = 1)
    assert paper[top, 1] < -0.3 * c                     # the paper pulls the upper lip down past the opening
    x, y = (outer - o) @ da, (outer - o) @ db
    fall = np.cos(0.5 * np.pi * np.clip(1.0 - np.sqrt(x * x * b * b + y * y * a * a) / (a * b), -1, 1))
    to = inner.mean(axis=0) - inner
    want = c * (np.outer(to @ da, da) + np.outer(to @ db, db)) * fall[:, None]
    np.testing.assert_allclose(moved, want, atol=1e-12)
    assert -0.3 * c <= moved[top, 1] < 0.0              # toward the opening, not past it
    # half way: half of each, and a ring whose loops share their centre is not changed
    np.testing.assert_allclose(sphincter_displacement(inner, outer, c, centre=0.5), 0.5 * (paper + moved),
                               atol=1e-12)
    same = np.stack([2.0 * inner[:, 0], 4.0 * inner[:, 1], inner[:, 2]], 1)
    np.testing.assert_allclose(sphincter_displacement(inner, same, c, centre=1.0),
                               sphincter_displacement(inner, same, c), atol=1e-12)


@pytest.fixture(scope="module")
def sphere():
    return icosphere(3)


def _mouth_on(v, f, **kw):
    return chin_mouth_on(v, f, **kw)


def test_compiled_closure_centre_matches_the_numpy_twin(sphere):
    v, f = sphere
    base = _mouth_on(v, f)
    sph = _mouth_on(v, f, closure_centre=1.0)
    g = sph.bound_grid
    scale = float(np.ptp(v, axis=0).max())
    rng = np.random.default_rng(3)
    for trial in range(4):
        now = jostled(v, rng, trial, turn=np.pi)
        points = {k: line.positions(now, f) for k, line in sph.lines.items()}
        for c in (0.3, 1.0):
            fast = sph.targets_from_line_points(c, points)
            twin = sph._grid_targets(c, points, 0.0, 0.0)[g[:, 0], g[:, 1]]
            assert np.allclose(fast, twin, rtol=0.0, atol=1e-12 * scale)
            assert not np.allclose(fast, base.targets_from_line_points(c, points), rtol=0.0, atol=1e-6 * scale)


def test_closure_centre_is_checked(sphere):
    v, f = sphere
    with pytest.raises(ValueError, match="closure_centre"):
        _mouth_on(v, f, closure_centre=1.5)
