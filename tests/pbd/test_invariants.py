"""Physical and numerical invariants of the solver (no snapshots)."""

from __future__ import annotations

import numpy as np
import pytest

from faceforge.pbd import ModelBuilder, Solver, SolverSettings, max_abs_residuals
from tests.pbd.meshes import edges, skin_builder, sphere

DT = 1.0 / 25.0


def internal_model(v, f, inv_mass, open_surface=False):
    """All internal kinds (no kinematic particles, no external pulls)."""
    if open_surface:
        f = f[:-20]
    b, _ = skin_builder(v, f, inv_mass=inv_mass, anchors=False, extras=False)
    return b.finalize()


@pytest.mark.parametrize("masses", ["equal", "unequal"])
@pytest.mark.parametrize("open_surface", [False, True])
def test_internal_constraints_conserve_linear_momentum(masses, open_surface):
    v, f = sphere(2)
    rng = np.random.default_rng(11)
    w = np.ones(len(v)) if masses == "equal" else rng.uniform(0.1, 5.0, len(v))
    model = internal_model(v, f, w, open_surface)
    state = model.state()
    state.positions += rng.normal(scale=0.1, size=state.positions.shape)
    state.velocities[:] = rng.normal(scale=0.5, size=state.positions.shape)
    mass = 1.0 / model.inv_mass
    p0 = (mass[:, None] * state.velocities).sum(axis=0)
    c0 = (mass[:, None] * state.positions).sum(axis=0) / mass.sum()
    out = model.state()
    Solver(model, SolverSettings(damping=0.0)).step(state, out, model.control(), DT)
    assert np.abs(out.positions - state.positions).max() > 1e-3  # the constraints did act
    p1 = (mass[:, None] * out.velocities).sum(axis=0)
    c1 = (mass[:, None] * out.positions).sum(axis=0) / mass.sum()
    np.testing.assert_allclose(p1, p0, atol=1e-9 * mass.sum())
    # the centre of mass moves on a straight line at the initial velocity
    np.testing.assert_allclose(c1, c0 + DT * p0 / mass.sum(), atol=1e-12)


@pytest.mark.parametrize("mode", ["paper", "iteration_independent", "xpbd"])
def test_rest_state_is_a_fixed_point(mode):
    v, f = sphere(2)
    b, info = skin_builder(v, f)
    model = b.finalize()
    kinds = {k: getattr(model, f"{k}_count") for k in
             ("distance", "bending", "area", "volume", "position", "attachment")}
    assert all(kinds.values()) and len(model.kinematic_indices) > 0
    state, out = model.state(), model.state()
    control = model.control()
    solver = Solver(model, SolverSettings(stiffness_mode=mode))
    for _ in range(500):
        solver.step(state, out, control, DT)
        solver.step(out, state, control, DT)
    drift = np.abs(state.positions - model.rest_positions).max()
    assert drift < 1e-12
    assert np.abs(state.velocities).max() < 1e-9


def test_residual_shrinks_with_iterations():
    v, f = sphere(2)
    b, _ = skin_builder(v, f, anchors=False, extras=False,
                        stiff={"stretch": 1.0, "bending": 0.0, "area": 1.0})
    model = b.finalize()
    rng = np.random.default_rng(3)
    start = model.state()
    start.positions += rng.normal(scale=0.03, size=start.positions.shape)
    previous = np.inf
    for iterations in (1, 2, 4, 8, 16, 32):
        out = model.state()
        Solver(model, SolverSettings(iterations=iterations, damping=0.0)).step(
            start, out, model.control(), DT)
        r = max_abs_residuals(model, out.positions)
        total = r["distance"] + r["area"]
        assert total < previous
        previous = total
    r0 = max_abs_residuals(model, start.positions)
    assert previous < 0.05 * (r0["distance"] + r0["area"])


def test_large_mesh_recovers_from_random_perturbation():
    m_v, m_f = sphere(4)  # 2562 vertices; two skins give 5124 particles
    v = np.concatenate([m_v, m_v * 0.5 + 3.0])
    f = np.concatenate([m_f, m_f + len(m_v)])
    b, _ = skin_builder(v, f)
    model = b.finalize()
    assert model.particle_count > 5000
    size = np.ptp(model.rest_positions, axis=0).max()
    rng = np.random.default_rng(0)
    state = model.state()
    free = model.inv_mass > 0
    state.positions[free] += rng.uniform(-0.3, 0.3, size=(free.sum(), 3)) * size
    solver = Solver(model, SolverSettings())
    control = model.control()
    before = max_abs_residuals(model, state.positions)
    for _ in range(100):
        solver.step(state, state, control, DT)
    assert np.all(np.isfinite(state.positions)) and np.all(np.isfinite(state.velocities))
    assert np.abs(state.positions - model.rest_positions).max() < 2.0 * size  # no blow-up
    after = max_abs_residuals(model, state.positions)
    assert after["distance"] < 0.5 * before["distance"]
    assert after["area"] < 0.5 * before["area"]


def test_degenerate_input_stays_finite():
    # zero-length edge, zero-area (collinear) triangle, flat and folded dihedrals
    pts = np.array([[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, -1, 0],   # flat quad
                    [2, 0, 0], [2, 0, 0],                              # coincident pair
                    [3, 0, 0], [4, 0, 0], [5, 0, 0],                   # collinear triangle
                    [0, 0, 5], [1, 0, 5], [0.5, 1, 5], [0.5, 1, 5]],   # folded quad
                   dtype=float)
    b = ModelBuilder()
    b.add_particles(pts, 1.0)
    b.add_distance([[4, 5], [0, 1]], 1.0)
    b.add_distance([[4, 5]], 1.0, rest_length=[0.0])
    b.add_area([[6, 7, 8], [0, 1, 2]], 1.0)
    b.add_area([[6, 7, 8]], 1.0, rest_area=[0.3])
    b.add_bending([[0, 1, 2, 3], [9, 10, 11, 12], [6, 7, 8, 4]], 1.0)
    b.add_bending([[0, 1, 2, 3], [9, 10, 11, 12]], 1.0, rest_angle=[np.pi, -np.pi])
    b.add_volume([[0, 1, 2], [6, 7, 8], [4, 5, 6]], 1.0)
    model = b.finalize()
    state = model.state()
    solver = Solver(model)
    for _ in range(50):
        solver.step(state, state, model.control(), DT)
    assert np.all(np.isfinite(state.positions)) and np.all(np.isfinite(state.velocities))
    r = max_abs_residuals(model, state.positions)
    assert all(np.isfinite(list(r.values())))


@pytest.mark.parametrize("rest_angle", [np.pi - 1e-9, -2.0, 2.0])
def test_flat_quad_folds_toward_its_rest_angle(rest_angle):
    b = ModelBuilder()
    b.add_particles(np.array([[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, -1, 0]], float), 1.0)
    b.add_bending([[0, 1, 2, 3]], 1.0, rest_angle=[rest_angle])
    model = b.finalize()
    state = model.state()
    before = abs(max_abs_residuals(model, state.positions)["bending"])
    solver = Solver(model)
    for _ in range(20):
        solver.step(state, state, model.control(), DT)
    after = max_abs_residuals(model, state.positions)["bending"]
    assert np.all(np.isfinite(state.positions))
    assert after < 0.1 * before


def run(model, steps=30, seed=0):
    state = model.state()
    state.positions[model.inv_mass > 0] += np.random.default_rng(seed).normal(
        scale=0.05, size=((model.inv_mass > 0).sum(), 3))
    solver = Solver(model, SolverSettings(substeps=2))
    control = model.control()
    for _ in range(steps):
        solver.step(state, state, control, DT)
    return state


def test_determinism_same_bytes():
    v, f = sphere(2)
    a = run(skin_builder(v, f)[0].finalize())
    b = run(skin_builder(v, f)[0].finalize())
    assert a.positions.tobytes() == b.positions.tobytes()
    assert a.velocities.tobytes() == b.velocities.tobytes()


def test_kinematic_particles_follow_control_exactly():
    v, f = sphere(2)
    b, info = skin_builder(v, f)
    model = b.finalize()
    solver = Solver(model, SolverSettings(substeps=3))
    state = model.state()
    control = model.control()
    kin = model.kinematic_indices
    for t in range(10):
        angle = 0.05 * (t + 1)
        rot = np.array([[np.cos(angle), 0, np.sin(angle)], [0, 1, 0],
                        [-np.sin(angle), 0, np.cos(angle)]])
        control.kinematic_positions = model.rest_positions[kin] @ rot.T + [0.0, 0.01 * t, 0.0]
        solver.step(state, state, control, DT)
        assert np.array_equal(state.positions[kin], control.kinematic_positions)
    # the skin was dragged along by its anchors
    skin = np.arange(info["skin"], info["skin"] + len(v))
    assert np.abs(state.positions[skin] - model.rest_positions[skin]).max() > 0.05


def test_one_way_attachment_never_moves_the_triangle():
    v, f = sphere(1)
    b = ModelBuilder()
    base = b.add_particles(v, 1.0)
    b.add_distance(edges(f) + base, 1.0)
    rider = b.add_particles(v[:3] + 0.5, 1.0)
    tris = f[:3] + base
    bary = np.full((3, 3), 1.0 / 3.0)
    b.add_attachment(np.arange(rider, rider + 3), tris, bary, 1.0)
    model = b.finalize()
    state = model.state()
    solver = Solver(model)
    for _ in range(5):
        solver.step(state, state, model.control(), DT)
    # the base mesh is at rest and satisfied: attachments must not have moved it
    assert np.array_equal(state.positions[:len(v)], model.rest_positions[:len(v)])
    targets = np.einsum("mk,mkd->md", bary, state.positions[tris])
    assert np.abs(state.positions[rider:rider + 3] - targets).max() < 1e-12


def test_position_constraint_pulls_by_k_per_iteration():
    b = ModelBuilder()
    b.add_particles(np.zeros((1, 3)), 1.0)
    slots = b.add_position([0], 0.2)
    model = b.finalize()
    control = model.control()
    control.position_targets[slots] = [1.0, 0.0, 0.0]
    state = model.state()
    Solver(model, SolverSettings(iterations=10, damping=0.0)).step(state, state, control, DT)
    np.testing.assert_allclose(state.positions[0, 0], 1.0 - 0.8 ** 10, rtol=1e-13)
    out = model.state()
    Solver(model, SolverSettings(iterations=10, damping=0.0,
                                 stiffness_mode="iteration_independent")).step(
        model.state(), out, control, DT)
    np.testing.assert_allclose(out.positions[0, 0], 0.2, rtol=1e-12)


def test_xpbd_result_does_not_depend_on_iteration_count():
    # two soft constraints pulling one particle to different targets: XPBD converges to
    # the minimiser of the implicit-Euler energy 1/2 |x - x_pred|^2 / w + sum C_j^2 / (2 a_j)
    # (a_j = (1 - k_j) / k_j * w, here w = 1), whatever the iteration count
    b = ModelBuilder()
    b.add_particles(np.zeros((1, 3)), 1.0)
    b.add_position([0, 0], [0.5, 0.25])
    model = b.finalize()
    control = model.control()
    control.position_targets[:] = [[1.0, 0, 0], [-1.0, 0, 0]]
    a1, a2 = 1.0, 3.0  # (1 - k) / k for k = 0.5, 0.25
    expected = (1.0 / a1 - 1.0 / a2) / (1.0 + 1.0 / a1 + 1.0 / a2)
    for n, tol in ((30, 1e-6), (200, 1e-12)):
        out = model.state()
        Solver(model, SolverSettings(iterations=n, stiffness_mode="xpbd", damping=0.0)).step(
            model.state(), out, control, DT)
        np.testing.assert_allclose(out.positions[0, 0], expected, atol=tol)
