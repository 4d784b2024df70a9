"""Distance constraints with their own end weights (``ModelBuilder.add_distance(weight=)``).

A *tether* ties a particle to a kinematic one held on a target, weighing the kinematic end
as a particle of some inverse mass. It must move the free end exactly as the model it
replaces: a dynamic particle of that inverse mass, put on the target by a stiffness-1
position constraint before the distance constraint, every iteration.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from faceforge.pbd import ModelBuilder, Solver, SolverSettings
from faceforge.pbd.constraints.distance import (
    _project_distance, _project_distance_pbd, move_weights, pbd_coefficients)
from tests.pbd import twins
from tests.pbd.meshes import edges, sphere


def _anchored(kinematic: bool, seed=0):
    """A sphere (2562 vertices: big enough to be cut in two parts) every third of whose
    vertices is tied to an anchor particle q: held
    by a stiffness-1 position constraint (``kinematic=False``, the reference) or kinematic
    with a tether weighing it as mass 1 (``kinematic=True``). Returns the model, the grid's
    vertex count."""
    v, f = sphere(4)
    rng = np.random.default_rng(seed)
    anchored = np.arange(0, len(v), 3)
    q_rest = v[anchored] + rng.normal(scale=0.05, size=(len(anchored), 3))
    b = ModelBuilder()
    first = b.add_particles(v, 1.0)
    q = b.add_particles(q_rest, 0.0 if kinematic else 1.0)
    q = q + np.arange(len(anchored))
    if not kinematic:
        b.add_position(q, 1.0)
    b.add_distance(np.stack([first + anchored, q], axis=1), 0.2,
                   weight=(1.0, 1.0) if kinematic else None)
    b.add_distance(first + edges(f), 0.5)
    b.add_area(first + f, 0.9)
    return b.finalize(), len(v)


def _play(model, n_skin, kinematic, settings, frames=4):
    solver = Solver(model, settings)
    state, control = model.state(), model.control()
    rng = np.random.default_rng(3)
    for _ in range(frames):
        goal = model.rest_positions[n_skin:] + rng.normal(scale=0.03, size=(len(model.rest_positions) - n_skin, 3))
        if kinematic:
            control.kinematic_positions[:] = goal
        else:
            control.position_targets[:] = goal
        solver.step(state, state, control, 1.0 / 25.0)
    return state.positions[:n_skin]


@pytest.mark.parametrize("mode", ["paper", "iteration_independent", "xpbd"])
def test_tether_moves_the_skin_as_a_held_anchor_particle(mode):
    settings = SolverSettings(iterations=6, stiffness_mode=mode, partitions=1)
    ref_model, n = _anchored(False)
    teth_model, _ = _anchored(True)
    ref = _play(ref_model, n, False, settings)
    got = _play(teth_model, n, True, settings)
    assert np.abs(ref - ref_model.rest_positions[:n]).max() > 1e-3   # the skin moved
    # paper: q = x + 1.0 (t - x) is t up to one rounding and the shares are the same floats
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-14 if mode == "paper" else 1e-12)


def test_tethers_stay_inside_the_parts():
    """A kinematic end belongs to no part: a tether goes to its free end's part, never to the
    seam, and the cut model steps the same bytes on threads as on one."""
    model, n = _anchored(True)
    settings = SolverSettings(iterations=6, partitions=2)
    solver = Solver(model, settings)
    assert solver._segment.max() == settings.partitions          # cut, with a seam
    idx = solver._arrays["distance"][0]
    seam = [(start, stop) for (kind, start, stop), g in zip(solver._blocks, solver._segment)
            if kind == 0 and g == settings.partitions]
    assert seam and all((solver._w[idx[a:b]] > 0).all() for a, b in seam)
    assert (solver._w == 0).sum() == len(model.kinematic_indices)
    runs = []
    for threaded in (True, False):
        solver = Solver(model, settings)
        solver._threaded = threaded and solver._threaded
        state, control = model.state(), model.control()
        control.kinematic_positions += [0.02, -0.01, 0.03]
        for _ in range(3):
            solver.step(state, state, control, 1.0 / 25.0)
        runs.append(state.positions)
    np.testing.assert_array_equal(runs[0], runs[1])


@pytest.mark.parametrize("xpbd", [False, True])
def test_weighted_sweeps_match_the_twin(xpbd):
    rng = np.random.default_rng(5)
    x = rng.normal(size=(12, 3))
    w = rng.uniform(0.5, 2.0, 12)
    w[[2, 7]] = 0.0                                    # kinematic ends
    pairs = np.array([[0, 1], [1, 2], [3, 7], [4, 5], [2, 7], [6, 8], [9, 10]])
    weight = rng.uniform(0.2, 1.5, size=(len(pairs), 2))
    weight[4] = 0.0                                    # both weights 0: not projected
    rest = rng.uniform(0.5, 1.5, len(pairs))
    k = rng.uniform(0.1, 1.0, len(pairs))
    c = rng.uniform(0.0, 2.0, len(pairs)) if xpbd else np.zeros(len(pairs))
    lam = np.zeros(len(pairs))
    want, want_lam = twins.distance(x, w, pairs, rest, k, c, lam, weight=weight)
    got = x.copy()
    _project_distance(got, move_weights(pairs, w, weight), pairs, rest, k, c, lam, xpbd, 0, len(pairs))
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-14)
    np.testing.assert_array_equal(got[[2, 7]], x[[2, 7]])   # kinematic ends never move
    assert np.abs(got - x).max() > 1e-2
    if xpbd:
        np.testing.assert_allclose(lam, want_lam, rtol=1e-12, atol=1e-14)
    else:
        pbd = x.copy()
        _project_distance_pbd(pbd, pairs, pbd_coefficients(pairs, rest, k, w, weight), 0, len(pairs))
        np.testing.assert_allclose(pbd, want, rtol=1e-12, atol=1e-14)


def test_default_weights_are_the_inverse_masses():
    b = ModelBuilder()
    b.add_particles(np.eye(3), [1.0, 0.5, 0.0])
    b.add_distance([[0, 1], [1, 2]], 0.5)
    m = b.finalize()
    np.testing.assert_array_equal(m.distance_weight, [[1.0, 0.5], [0.5, 0.0]])
    # and a Model made without them gets the same default
    m2 = dataclasses.replace(m, distance_weight=None)
    np.testing.assert_array_equal(m2.distance_weight, m.distance_weight)


@pytest.mark.parametrize("weight, match", [
    ((1.0, 2.0, 3.0), "shape"), ([[1.0, -1.0]], ">= 0"), ([[0.0, 0.0]], "not 0 at both"),
    ([[np.nan, 1.0]], "finite")])
def test_bad_weights_are_refused(weight, match):
    b = ModelBuilder()
    b.add_particles(np.eye(3), 1.0)
    with pytest.raises(ValueError, match=match):
        b.add_distance([[0, 1]], 0.5, weight=weight)
