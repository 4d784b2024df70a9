"""Greedy colouring: validity, its plain-Python twin, and the coloured solver's invariants."""

from __future__ import annotations

import numpy as np
import pytest

from faceforge.pbd import Solver, SolverSettings, max_abs_residuals
from faceforge.pbd.colouring import colour_order, greedy_colouring
from tests.pbd.meshes import adjacent_quads, edges, skin_builder, sphere


def greedy_twin(indices):
    taken = {}
    out = []
    for row in indices:
        used = set().union(*(taken.get(int(i), set()) for i in row))
        c = 0
        while c in used:
            c += 1
        out.append(c)
        for i in row:
            taken.setdefault(int(i), set()).add(c)
    return np.array(out)


@pytest.mark.parametrize("kind", ["edges", "quads", "faces", "star"])
def test_colours_are_valid_and_match_twin(kind):
    v, f = sphere(2)
    idx = {"edges": edges(f), "quads": adjacent_quads(f), "faces": f,
           # 130 constraints on one particle: more than 64 colours
           "star": np.c_[np.zeros(130, dtype=np.int64), np.arange(1, 131)]}[kind]
    colours = greedy_colouring(idx, len(v))
    np.testing.assert_array_equal(colours, greedy_twin(idx))
    for c in np.unique(colours):
        members = idx[colours == c].ravel()
        assert len(members) == len(np.unique(members)), f"colour {c} shares a particle"
    if kind == "star":
        assert colours.max() == 129


def test_colour_order_keeps_blocks_in_place():
    v, f = sphere(1)
    e = edges(f)
    blocks = np.array([[0, 40], [40, len(e)]])
    order, runs = colour_order(e, len(v), blocks)
    assert sorted(order[:40]) == list(range(40))
    assert sorted(order[40:]) == list(range(40, len(e)))
    assert runs[0] == 0 and runs[-1] == len(e) and 40 in runs
    permuted = e[order]
    for a, b in zip(runs[:-1], runs[1:]):  # every run is a set of independent constraints
        members = permuted[a:b].ravel()
        assert len(members) == len(np.unique(members))


@pytest.mark.parametrize("scale", [0.002, 0.2])
def test_batched_area_matches_the_sequential_sweep(scale):
    from faceforge.pbd.constraints._common import BATCH, BATCH_ROWS
    from faceforge.pbd.constraints.area import _project_area, _project_area_batched, init_area
    from tests.pbd import twins
    v, f = sphere(3)
    f = np.concatenate([f, [[0, 1, 1]]])  # a degenerate triangle too
    order, runs = colour_order(f, len(v), np.array([[0, 300], [300, len(f)]]))
    f = f[order]
    rng = np.random.default_rng(8)
    x0 = v + rng.normal(scale=scale, size=v.shape)
    w = rng.uniform(0.0, 2.0, len(v))
    rest = init_area(v, f) * 1.1
    k = rng.uniform(0.1, 1.0, len(f))
    got = x0.copy()
    _project_area_batched(got, f, np.ascontiguousarray(w[f].T), rest, k, runs,
                          np.zeros(BATCH * BATCH_ROWS), 0, len(f))
    scalar = x0.copy()
    zeros = np.zeros(len(f))
    _project_area(scalar, w, f, rest, k, zeros, zeros, False, 0, len(f))
    want, _ = twins.area(x0, w, f, rest, k)
    assert np.abs(got - x0).max() > 1e-4
    np.testing.assert_allclose(got, scalar, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(got, want, rtol=1e-11, atol=1e-13)


@pytest.mark.parametrize("scale", [0.002, 0.2])  # small: Padé branch; large: atan2 fix-up
def test_batched_bending_matches_the_sequential_sweep(scale):
    from faceforge.pbd.constraints._common import BATCH, BATCH_ROWS
    from faceforge.pbd.constraints.bending import (
        _project_bending, _project_bending_batched, init_bending,
        rest_cos_sin)
    from tests.pbd import twins
    v, f = sphere(3)
    q = adjacent_quads(f)
    order, runs = colour_order(q, len(v), np.array([[0, 100], [100, len(q)]]))
    q = q[order]
    rng = np.random.default_rng(8)
    x0 = v + rng.normal(scale=scale, size=v.shape)
    w = rng.uniform(0.0, 2.0, len(v))
    rest = init_bending(v, q)
    k = rng.uniform(0.1, 1.0, len(q))
    got = x0.copy()
    _project_bending_batched(got, q, np.ascontiguousarray(w[q].T),
                             np.ascontiguousarray(rest_cos_sin(rest).T), k, runs,
                             np.zeros(BATCH * BATCH_ROWS), 0, len(q))
    scalar = x0.copy()
    zeros = np.zeros(len(q))
    _project_bending(scalar, w, q, rest_cos_sin(rest), k, zeros, zeros, False, 0, len(q))
    want, _ = twins.bending(x0, w, q, rest, k)
    assert np.abs(got - x0).max() > 1e-4
    np.testing.assert_allclose(got, scalar, rtol=1e-11, atol=1e-13)
    np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("mode", ["paper", "xpbd"])  # batched sweeps / scalar coloured sweeps
def test_coloured_solver_rest_fixed_point_momentum_and_convergence(mode):
    v, f = sphere(2)
    b, _ = skin_builder(v, f)
    model = b.finalize()
    solver = Solver(model, SolverSettings(colouring=True, stiffness_mode=mode))
    state = model.state()
    for _ in range(200):
        solver.step(state, state, model.control(), 0.04)
    assert np.abs(state.positions - model.rest_positions).max() < 1e-12
    # internal constraints only: momentum is conserved, residuals shrink
    b, _ = skin_builder(v, f, anchors=False, extras=False)
    model = b.finalize()
    state = model.state()
    rng = np.random.default_rng(4)
    state.positions += rng.normal(scale=0.05, size=state.positions.shape)
    state.velocities[:] = rng.normal(size=state.positions.shape)
    p0 = state.velocities.sum(axis=0)
    before = max_abs_residuals(model, state.positions)
    solver = Solver(model, SolverSettings(colouring=True, damping=0.0, stiffness_mode=mode))
    out = model.state()
    solver.step(state, out, model.control(), 0.04)
    np.testing.assert_allclose(out.velocities.sum(axis=0), p0, atol=1e-9 * len(v))
    for _ in range(50):
        solver.step(out, out, model.control(), 0.04)
    after = max_abs_residuals(model, out.positions)
    assert after["distance"] < 0.2 * before["distance"]


@pytest.mark.parametrize("mode", ["paper", "xpbd"])
def test_stepping_in_place_equals_stepping_into_another_state(mode):
    """``_step`` skips copying the state onto itself when ``state_out`` is ``state_in``: the
    same bits as stepping into a separate state (which copies), and the input is kept then."""
    v, f = sphere(2)
    b, _ = skin_builder(v, f)
    model = b.finalize()
    solver = Solver(model, SolverSettings(colouring=True, stiffness_mode=mode))
    rng = np.random.default_rng(7)
    a = model.state()
    a.positions += rng.normal(scale=0.05, size=a.positions.shape)
    a.velocities[:] = rng.normal(size=a.positions.shape)
    x0, v0 = a.positions.copy(), a.velocities.copy()
    out = model.state()
    solver.step(a, out, model.control(), 0.04)
    assert np.array_equal(a.positions, x0) and np.array_equal(a.velocities, v0)
    solver.step(a, a, model.control(), 0.04)
    assert np.array_equal(a.positions, out.positions) and np.array_equal(a.velocities, out.velocities)
