"""The orbicularis oris' lower part (``<sphincter>.lower``): the lower half of the loops raised
toward the upper lip (faceforge.anatomy.muscles.sphincter.lower_raise)."""

import numpy as np
import pytest
import trimesh

from faceforge.anatomy.muscles.sphincter import (LOWER_INWARD, fit_ellipse, lower_control, lower_raise, lower_weights,
                                                 sphincter_displacement)

from tests.anatomy.conftest import icosphere, sphincter_on


@pytest.fixture(scope="module")
def sphere():
    return icosphere(3)


@pytest.fixture(scope="module")
def sphincter(sphere):
    v, f = sphere
    return sphincter_on("oris", v, f, (0.0, -0.3), (0.15, 0.07), (0.32, 0.17))


def test_lower_weights_and_drive():
    w = lower_weights(np.array([1.0, 0.2, 0.0, -0.5, -1.0, -2.0]), 1.0)
    assert w.tolist() == [0.0, 0.0, 0.0, 0.5, 1.0, 1.0]
    assert lower_control("orbicularis_oris") == "orbicularis_oris.lower"
    assert lower_raise(2.0, True, 0.5) == lower_raise(1.0, True, 0.5) > 0.0   # clipped like c
    assert lower_raise(1.0, False, 0.5) == 0.0 and lower_raise(-1.0, True, 0.5) == 0.0


@pytest.mark.parametrize("order", ["corner first", "midline first, reversed"])
@pytest.mark.parametrize("wide", [2.0, 0.6])
def test_lower_part_raises_the_lower_lip_only(order, wide):
    """A planar ring (+Y up): the lower half moves up (+y) by ``low r w_i`` (``r`` its radius
    along y, the fall-off 1 on the ellipse) and in (-z) by LOWER_INWARD times that, the upper
    half stays, whatever sample the loop starts at and whichever way it runs (a symmetric rig
    restarts it at the midline), and whether the ellipse is wider than tall or taller than wide
    (its minor axis then runs across: the MediaPipe mask)."""
    h = 16
    ang = 2 * np.pi * np.arange(h) / h
    outer = np.stack([wide * np.cos(ang), np.sin(ang), np.zeros(h)], 1)
    inner = 0.5 * outer
    idx = np.arange(h) if order == "corner first" else np.roll(np.arange(h)[::-1], 4)
    fwd = np.array([0.0, 0.0, 1.0])
    d = np.empty((h, 3))
    d[idx] = sphincter_displacement(inner[idx], outer[idx], 0.0, 0.0, fwd, 0.3)
    o, da, db, a, b = fit_ellipse(np.concatenate([inner, outer]))
    r = a if abs(da[1]) > abs(db[1]) else b          # the radius along y (axis-aligned ellipse)
    rr = np.sqrt((outer[:, 0] / (b if r == a else a)) ** 2 + (outer[:, 1] / r) ** 2)
    fall = np.cos(0.5 * np.pi * np.clip(1.0 - rr, -1.0, 1.0))
    np.testing.assert_allclose(d[:, 0], 0.0, atol=1e-12)
    np.testing.assert_allclose(d[:, 1], 0.3 * r * np.clip(-outer[:, 1] / r, 0, 1) * fall, atol=1e-9)
    np.testing.assert_allclose(d[:, 2], -LOWER_INWARD * d[:, 1], atol=1e-12)    # and in, toward the teeth
    assert np.all(d[1:8, 1] == 0.0) and d[12, 1] > 0.2
    # with the contraction: the sum of both
    both = sphincter_displacement(inner, outer, 0.4, 0.0, fwd, 0.3)
    np.testing.assert_allclose(both, sphincter_displacement(inner, outer, 0.4) + d, atol=1e-12)


def test_compiled_lower_part_matches_the_numpy_twin(sphincter, sphere):
    v, f = sphere
    rng = np.random.default_rng(7)
    g = sphincter.bound_grid
    scale = float(np.ptp(v, axis=0).max())
    rest = sphincter.targets_from_line_points(0.0, {k: line.positions(v, f) for k, line in sphincter.lines.items()})
    for trial in range(6):
        rot = trimesh.transformations.rotation_matrix(rng.uniform(0, np.pi), rng.normal(size=3))[:3, :3]
        now = v @ rot.T * rng.uniform(0.5, 2.0) + rng.normal(size=3)
        now = now + rng.normal(scale=0.01 * trial, size=v.shape)
        points = {k: line.positions(now, f) for k, line in sphincter.lines.items()}
        for c, low in ((0.0, 0.5), (0.6, 1.0), (0.0, 3.0)):
            fast = sphincter.targets_from_line_points(c, points, 0.0, low)
            twin = sphincter._grid_targets(c, points, 0.0,
                                           lower_raise(low, True, sphincter.max_contraction))[g[:, 0], g[:, 1]]
            assert np.allclose(fast, twin, rtol=0.0, atol=1e-12 * scale)
            assert not np.allclose(fast, sphincter.targets_from_line_points(c, points))
    # on the rest sphere the lower part's targets rise (+y), the upper ones stay
    points = {k: line.positions(v, f) for k, line in sphincter.lines.items()}
    d = sphincter.targets_from_line_points(0.0, points, 0.0, 1.0) - rest
    up = d[:, 1]
    assert up.max() > 0.02 and up.min() > -1e-9


def test_collinear_loops_with_the_lower_part_stay_finite():
    """A degenerate (collinear) loop has no up direction in its plane: the raise is skipped,
    the targets stay finite (compiled and plain)."""
    from faceforge.anatomy.muscles.sphincter import _sphincter_grid

    p = np.stack([np.linspace(0.0, 1.0, 6), np.zeros(6), np.zeros(6)], 1)
    seg, t = np.arange(5), np.full(5, 0.5)
    for low in (0.0, 0.3):
        grid = np.empty((5, 2, 3))
        _sphincter_grid(p, seg, t, p.copy(), seg, t, 0.3, grid, p[:5], p[:5], np.zeros(0), 0.0,
                        np.array([0.0, 0.0, 1.0]), low)
        assert np.all(np.isfinite(grid))
    with np.errstate(all="ignore"):
        d = sphincter_displacement(p[:5], p[:5] * 1.5, 0.0, 0.0, np.array([0.0, 0.0, 1.0]), 0.3)
    assert np.all(np.isfinite(d))
