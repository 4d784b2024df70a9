"""The activation solve on stand-in simulations whose answer is known."""

from __future__ import annotations

import numpy as np
import pytest

from faceforge.blendshapes.solve import (ControlSpace, bounded_lsq, control_space, field_agreement, jacobian,
                                         solve_activations)

COLUMNS = ("a", "b", "c")


def _space(names=("a", "b", "c", "jaw.pitch")):
    return control_space(COLUMNS, set(names), {"pitch": (-0.02, 0.4)}, pitch_lever=2.0)


def _linear_sim(B):
    """simulate: skin (k, n, 3) = rest 0 + B @ [c, jaw] (B (3n, 6)); observe: flattened."""

    def simulate(c, jaw):
        x = np.hstack([c, jaw])
        return (x @ B.T).reshape(len(x), -1, 3)

    return simulate, (lambda frames: np.asarray(frames).reshape(len(frames), -1))


def test_control_space_bounds_and_pose():
    s = _space()
    assert s.names == ("a", "b", "c", "jaw.pitch")
    assert np.allclose(s.lower, [0, 0, 0, -0.02]) and np.allclose(s.upper, [1, 1, 1, 0.4])
    c, jaw = s.pose([0.1, 0.2, 0.3, 0.25])
    assert np.allclose(c, [[0.1, 0.2, 0.3]]) and np.allclose(jaw, [[0.25, 0, 0]])
    sub = s.subset(["c", "jaw.pitch"])
    assert sub.names == ("c", "jaw.pitch")
    with pytest.raises(ValueError):
        ControlSpace(("a",), np.zeros(2), np.ones(1), np.ones(1), COLUMNS)


def test_linear_simulation_recovers_the_controls_exactly():
    rng = np.random.default_rng(0)
    B = rng.normal(size=(30, 6))
    simulate, observe = _linear_sim(B)
    s = _space()
    J = jacobian(simulate, observe, s)
    assert np.allclose(J, B[:, [0, 1, 2, 3]])
    truth = np.array([0.3, 0.0, 0.8, 0.2])
    target = observe(simulate(*s.pose(truth)))[0]
    res = solve_activations(target, J, s, simulate, observe, passes=0, ridge=0.0)
    assert np.allclose(res.x, truth, atol=1e-9)
    assert res.residuals[0] < 1e-9
    cos, ratio = field_agreement(res.observed, target)
    assert cos == pytest.approx(1.0) and ratio == pytest.approx(1.0)


def test_bounds_hold_and_an_unreachable_target_is_clipped():
    rng = np.random.default_rng(1)
    B = rng.normal(size=(30, 6))
    simulate, observe = _linear_sim(B)
    s = _space()
    target = observe(simulate(*s.pose(np.array([3.0, 0.0, 0.0, 0.0]))))[0]   # a = 3: beyond its bound
    res = solve_activations(target, jacobian(simulate, observe, s), s, simulate, observe, passes=0, ridge=0.0)
    assert np.all(res.x >= s.lower - 1e-12) and np.all(res.x <= s.upper + 1e-12)
    assert res.x[0] == pytest.approx(1.0, abs=1e-6)
    # a negative target cannot be made by non-negative contractions: nothing contracts
    x = bounded_lsq(np.eye(3), -np.ones(3), np.zeros(3), np.ones(3), ridge=0.0)
    assert np.allclose(x, 0.0)


def test_gauss_newton_passes_correct_a_saturating_simulation():
    """The skin saturates (tanh) as real fibres do: the secant Jacobian from the probe underestimates
    the gain at small contractions, the linear solve misses, the refinement passes close in."""
    rng = np.random.default_rng(2)
    B = rng.normal(size=(30, 6))

    def simulate(c, jaw):
        x = np.hstack([np.tanh(2.0 * c), jaw])
        return (x @ B.T).reshape(len(x), -1, 3)

    observe = lambda frames: np.asarray(frames).reshape(len(frames), -1)  # noqa: E731
    s = _space()
    truth = np.array([0.15, 0.0, 0.3, 0.1])
    target = observe(simulate(*s.pose(truth)))[0]
    J = jacobian(simulate, observe, s)
    res = solve_activations(target, J, s, simulate, observe, passes=4, ridge=0.0)
    assert len(res.residuals) >= 2
    assert res.residuals[-1] < 0.5 * res.residuals[0]
    assert all(b < a for a, b in zip(res.residuals, res.residuals[1:]))   # only improving passes are kept


def test_ridge_is_scale_free():
    """A control that moves the skin 1000x less is pulled towards rest no more than a large one."""
    J = np.diag([1000.0, 1.0])
    x = bounded_lsq(J, np.array([500.0, 0.5]), np.zeros(2), np.ones(2), ridge=1e-2)
    assert x[0] == pytest.approx(x[1], rel=1e-9)


def test_field_agreement():
    a = np.array([[1.0, 0, 0], [0, 1.0, 0]])
    assert field_agreement(2 * a, a) == pytest.approx((1.0, 2.0))
    assert field_agreement(-a, a)[0] == pytest.approx(-1.0)
    with pytest.raises(ValueError):
        field_agreement(a, 0 * a)


def test_magnitude_step_brings_a_short_field_to_its_target_size():
    """A skin that responds at half the secant's gain beyond the probe (it saturates): the passes
    are skipped, the linear solve leaves the field short; the magnitude step scales the pose until
    the field's size matches its projection on the target, and never leaves the bounds."""
    rng = np.random.default_rng(3)
    B = rng.normal(size=(30, 6))

    def simulate(c, jaw):
        x = np.hstack([np.where(c < 0.5, c, 0.5 + 0.5 * (c - 0.5)), jaw])   # gain halves above 0.5
        return (x @ B.T).reshape(len(x), -1, 3)

    observe = lambda frames: np.asarray(frames).reshape(len(frames), -1)  # noqa: E731
    s = _space()
    J = jacobian(simulate, observe, s)
    target = observe(simulate(*s.pose(np.array([0.9, 0.0, 0.0, 0.0]))))[0]
    plain = solve_activations(target, J, s, simulate, observe, passes=0, ridge=0.0)
    _, short = field_agreement(plain.observed, target)
    res = solve_activations(target, J, s, simulate, observe, passes=0, ridge=0.0, rescale=3)
    cos, ratio = field_agreement(res.observed, target)
    assert short < 0.9 and ratio > short and ratio == pytest.approx(cos, abs=0.05)
    assert res.residuals[-1] < plain.residuals[-1]
    assert np.all(res.x <= s.upper + 1e-12) and np.all(res.x >= s.lower - 1e-12)


def test_local_step_fixes_controls_that_do_not_add_up():
    """Two controls whose effects multiply (a shared insertion): the secants from rest predict
    their sum wrongly and the chord passes stall; a Jacobian taken at the solution closes in."""
    rng = np.random.default_rng(4)
    B = rng.normal(size=(30, 6))

    def simulate(c, jaw):
        x = np.hstack([c, jaw]).copy()
        x[:, 2] = x[:, 2] + 3.0 * c[:, 0] * c[:, 1]        # a and b together move c's field
        return (x @ B.T).reshape(len(x), -1, 3)

    observe = lambda frames: np.asarray(frames).reshape(len(frames), -1)  # noqa: E731
    s = _space()
    J = jacobian(simulate, observe, s)
    target = observe(simulate(*s.pose(np.array([0.6, 0.5, 0.1, 0.0]))))[0]
    plain = solve_activations(target, J, s, simulate, observe, passes=2, ridge=0.0)
    res = solve_activations(target, J, s, simulate, observe, passes=2, ridge=0.0, local=3)
    assert res.residuals[-1] < 0.5 * plain.residuals[-1], (plain.residuals, res.residuals)
    assert np.all(res.x <= s.upper + 1e-12) and np.all(res.x >= s.lower - 1e-12)
