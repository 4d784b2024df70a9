"""Every numba kernel against its plain-Python twin (tests/pbd/twins.py)."""

from __future__ import annotations

import numpy as np
import pytest

from faceforge.pbd.constraints import (
    init_area, init_bending, init_distance, init_volume, solve_attachment, solve_position,
    solve_volume)
from faceforge.pbd.constraints.area import _project_area
from faceforge.pbd.constraints.bending import _project_bending, dihedral_angle, rest_cos_sin
from faceforge.pbd.constraints.distance import (
    _project_distance, _project_distance_batched, _project_distance_pbd, move_weights, pbd_coefficients)
from faceforge.pbd.constraints.volume import reference_vertices
from tests.pbd import twins
from tests.pbd.meshes import adjacent_quads, edges, sphere


@pytest.fixture(scope="module")
def mesh():
    v, f = sphere(1)
    rng = np.random.default_rng(7)
    rest = v.copy()
    x = v + rng.normal(scale=0.08, size=v.shape)
    w = rng.uniform(0.2, 2.0, size=len(v))
    w[::9] = 0.0  # some kinematic particles
    return rest, x, w, f


@pytest.mark.parametrize("xpbd", [False, True])
def test_distance_matches_twin(mesh, xpbd):
    rest, x, w, f = mesh
    e = edges(f)
    r = init_distance(rest, e)
    m = len(e)
    rng = np.random.default_rng(1)
    k = rng.uniform(0.1, 1.0, m)
    c = rng.uniform(0.0, 3.0, m) if xpbd else np.zeros(m)
    lam0 = rng.normal(size=m) * 0.01 if xpbd else np.zeros(m)
    want, want_lam = twins.distance(x, w, e, r, k, c, lam0)
    got, lam = x.copy(), lam0.copy()
    _project_distance(got, move_weights(e, w), e, r, k, c, lam, xpbd, 0, m)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-13)
    if xpbd:
        np.testing.assert_allclose(lam, want_lam, rtol=1e-10, atol=1e-13)


def test_pbd_distance_sweep_matches_twin_and_the_general_kernel(mesh):
    """The PBD sweep with precomputed weight shares (used by the solver in the PBD modes)."""
    rest, x, w, f = mesh
    e = edges(f)
    w = w.copy()
    w[e[5]] = 0.0  # one constraint with both ends kinematic
    e = np.concatenate([e, [[3, 3]]])  # and a coincident pair
    r = init_distance(rest, e) * 1.05
    m = len(e)
    k = np.random.default_rng(6).uniform(0.1, 1.0, m)
    want, _ = twins.distance(x, w, e, r, k)
    got = x.copy()
    _project_distance_pbd(got, e, pbd_coefficients(e, r, k, w), 0, m)
    assert np.abs(got - x).max() > 1e-3
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-13)
    general = x.copy()
    _project_distance(general, move_weights(e, w), e, r, k, np.zeros(m), np.zeros(m), False, 0, m)
    np.testing.assert_allclose(got, general, rtol=1e-13, atol=1e-14)


def test_batched_distance_sweep_matches_twin_and_the_sequential_sweep():
    """The vectorised PBD sweep over runs of independent constraints (coloured solver)."""
    from faceforge.pbd.colouring import colour_order
    from faceforge.pbd.constraints._common import BATCH, BATCH_ROWS
    v, f = sphere(3)
    rng = np.random.default_rng(5)
    x = v + rng.normal(scale=0.02, size=v.shape)
    w = rng.uniform(0.0, 2.0, len(v))
    w[::7] = 0.0
    e = np.concatenate([edges(f), [[3, 3]]])  # and a coincident pair
    w[e[5]] = 0.0  # one constraint with both ends kinematic
    order, runs = colour_order(e, len(v), np.array([[0, 200], [200, len(e)]]))
    e = e[order]
    r = init_distance(v, e) * 1.05
    k = rng.uniform(0.1, 1.0, len(e))
    coef = pbd_coefficients(e, r, k, w)
    got = x.copy()
    _project_distance_batched(got, e, np.ascontiguousarray(coef.T), runs,
                              np.zeros(BATCH * BATCH_ROWS), 0, len(e))
    sequential = x.copy()
    _project_distance_pbd(sequential, e, coef, 0, len(e))
    want, _ = twins.distance(x, w, e, r, k)
    assert np.abs(got - x).max() > 1e-3
    np.testing.assert_array_equal(got, sequential)  # the same math, lane by lane
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-13)


@pytest.mark.parametrize("xpbd", [False, True])
def test_bending_matches_twin(mesh, xpbd):
    rest, x, w, f = mesh
    q = adjacent_quads(f)
    r = init_bending(rest, q)
    m = len(q)
    rng = np.random.default_rng(2)
    k = rng.uniform(0.1, 1.0, m)
    c = rng.uniform(0.0, 3.0, m) if xpbd else np.zeros(m)
    lam0 = rng.normal(size=m) * 0.01 if xpbd else np.zeros(m)
    want, want_lam = twins.bending(x, w, q, r, k, c, lam0)
    got, lam = x.copy(), lam0.copy()
    _project_bending(got, w, q, rest_cos_sin(r), k, c, lam, xpbd, 0, m)
    np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-12)
    if xpbd:
        np.testing.assert_allclose(lam, want_lam, rtol=1e-8, atol=1e-12)


def test_deviation_is_atan2_of_the_rotated_pair():
    from faceforge.pbd.constraints.bending import _deviation
    rng = np.random.default_rng(9)
    for theta in np.concatenate([rng.uniform(-np.pi, np.pi, 200), [0.0, 1e-12, -0.24, 0.25]]):
        y, x = np.sin(theta) * 3.0, np.cos(theta) * 3.0
        got = _deviation(y, x)
        assert got == twins.deviation(y, x, 0.0)
        assert abs(got - theta) <= 1.3e-9 * abs(theta) + 1e-15  # Padé branch is this close
        assert np.sign(got) == np.sign(theta)
    assert _deviation(0.0, 1.0) == 0.0


def test_bending_gradient_is_the_derivative_of_the_angle():
    rng = np.random.default_rng(3)
    h = 1e-6
    for _ in range(20):
        p = rng.normal(size=(4, 3))
        q = np.array([[0, 1, 2, 3]])
        grad = np.array(twins.bending_gradient(*p))
        fd = np.zeros((4, 3))
        for i in range(4):
            for d in range(3):
                pp, pm = p.copy(), p.copy()
                pp[i, d] += h
                pm[i, d] -= h
                fd[i, d] = (dihedral_angle(pp, q)[0] - dihedral_angle(pm, q)[0]) / (2 * h)
        np.testing.assert_allclose(grad, fd, atol=1e-6 * max(1.0, np.abs(fd).max()))


@pytest.mark.parametrize("xpbd", [False, True])
def test_area_matches_twin(mesh, xpbd):
    rest, x, w, f = mesh
    r = init_area(rest, f)
    m = len(f)
    rng = np.random.default_rng(4)
    k = rng.uniform(0.1, 1.0, m)
    c = rng.uniform(0.0, 3.0, m) if xpbd else np.zeros(m)
    lam0 = rng.normal(size=m) * 0.01 if xpbd else np.zeros(m)
    want, want_lam = twins.area(x, w, f, r, k, c, lam0)
    got, lam = x.copy(), lam0.copy()
    _project_area(got, w, f, r, k, c, lam, xpbd, 0, m)
    np.testing.assert_allclose(got, want, rtol=1e-11, atol=1e-13)
    if xpbd:
        np.testing.assert_allclose(lam, want_lam, rtol=1e-9, atol=1e-13)


@pytest.mark.parametrize("open_surface", [False, True])
def test_volume_matches_twin(mesh, open_surface):
    rest, x, w, f = mesh
    f = f[:-12] if open_surface else f
    v0 = init_volume(rest, f) * 1.1
    ref = reference_vertices(f)
    assert (len(ref) < len(np.unique(f))) == open_surface
    want = twins.volume(x, w, f, v0, 0.7, ref)
    got = solve_volume(x, w, f, v0, 0.7)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-13)
    # the solver's kernel leaves its gradient scratch all zero (it relies on that)
    from faceforge.pbd.constraints.volume import _project_volume, localize, pair_triangles
    particles, _, local_ref = localize(f)
    rows = pair_triangles(f)
    assert (rows[:, 3] >= 0).any() and (rows[:, 3] < 0).any()  # pairs and singles
    g = np.zeros_like(x)
    again = x.copy()
    one = np.ones(1)
    _project_volume(again, w, np.array([0, len(particles)]), particles, np.array([[0, len(particles)]]),
                    np.array([[0, len(rows)]]),
                    rows, np.array([0, len(local_ref)]), particles[local_ref], np.array([v0]),
                    one * 0.7, one * 0.0, one * 0.0, g, False, 0, 1)
    np.testing.assert_array_equal(again, got)
    assert not g.any()


def test_pair_triangles_keeps_every_triangle_once_with_its_orientation():
    from faceforge.pbd.constraints.volume import pair_triangles
    v, f = sphere(2)
    f = np.concatenate([f[:-7], f[-7:-5, ::-1], [[0, 1, 1]]])  # two flipped, a degenerate
    rows = pair_triangles(f)
    got = []
    for a, b, c, d in rows.tolist():
        got.append((a, b, c))
        if d >= 0:
            got.append((b, a, d))
    canon = {tuple(np.roll(t, -int(np.argmin(t)))) for t in f.tolist()}
    assert len(got) == len(f) and {tuple(np.roll(t, -int(np.argmin(t)))) for t in got} == canon
    assert (rows[:, 3] >= 0).sum() > 0.45 * len(f)  # most triangles found a partner
    singles = rows[rows[:, 3] < 0]
    assert [0, 1, 1, -1] in singles.tolist()


def test_position_and_attachment_match_twins(mesh):
    rest, x, w, f = mesh
    rng = np.random.default_rng(5)
    particles = np.array([1, 4, 9, 20])  # 9 is kinematic
    targets = rng.normal(size=(4, 3))
    k = np.array([0.2, 1.0, 0.5, 0.7])
    np.testing.assert_allclose(solve_position(x, w, particles, targets, k),
                               twins.position(x, w, particles, targets, k), rtol=1e-13)
    tris = f[[3, 5, 30, 31]]
    bary = rng.dirichlet(np.ones(3), size=4)
    np.testing.assert_allclose(solve_attachment(x, w, particles, tris, bary, k),
                               twins.attachment(x, w, particles, tris, bary, k), rtol=1e-13)


def test_solver_step_matches_the_plain_python_step():
    """The compiled step (predict, kinematic, blocks in order, velocities) against its twin."""
    from faceforge.pbd import Solver, SolverSettings
    from tests.pbd.meshes import skin_builder

    v, f = sphere(1)
    b, info = skin_builder(v, f)
    model = b.finalize()
    rng = np.random.default_rng(12)
    state = model.state()
    free = model.inv_mass > 0
    state.positions[free] += rng.normal(scale=0.05, size=(free.sum(), 3))
    state.velocities[free] = rng.normal(scale=0.2, size=(free.sum(), 3))
    control = model.control()
    control.kinematic_positions += 0.01
    control.position_targets += 0.1
    settings = SolverSettings(iterations=3, substeps=2, damping=0.2, gravity=1.5)
    out = model.state()
    Solver(model, settings).step(state, out, control, 0.04)
    x, vel = twins.step(model, state.positions, state.velocities, control, 0.04,
                        iterations=3, substeps=2, damping=0.2, gravity=1.5)
    np.testing.assert_allclose(out.positions, x, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(out.velocities, vel, rtol=1e-8, atol=1e-9)


def test_a_pbd_bending_projection_turns_a_folded_quad_at_most_max_step_angle():
    """A hinge folded 2.6 rad away from its flat rest: one PBD projection (k = 1) turns it
    by MAX_STEP_ANGLE (a linearised step from 2.6 rad overshoots; the orbicularis ring
    diverged so); repeated projections still reach the rest angle. XPBD is not clamped."""
    from faceforge.pbd.constraints.bending import MAX_STEP_ANGLE, _wrap

    rest = np.array([[0.0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, -1, 0]])
    q = np.array([[0, 1, 2, 3]])
    r = init_bending(rest, q)
    fold = 2.6
    x = rest.copy()
    x[3] = [0.5, -np.cos(fold), np.sin(fold)]      # the second wing turned about the hinge
    w = np.ones(4)
    before = float(_wrap(dihedral_angle(x, q) - r)[0])
    assert abs(abs(before) - fold) < 1e-9
    once = x.copy()
    _project_bending(once, w, q, rest_cos_sin(r), np.ones(1), np.zeros(1), np.zeros(1), False, 0, 1)
    turned = abs(before) - abs(float(_wrap(dihedral_angle(once, q) - r)[0]))
    assert 0.5 * MAX_STEP_ANGLE < turned < 1.5 * MAX_STEP_ANGLE
    np.testing.assert_allclose(once, twins.bending(x, w, q, r, np.ones(1))[0], rtol=1e-10, atol=1e-12)
    for _ in range(40):
        _project_bending(once, w, q, rest_cos_sin(r), np.ones(1), np.zeros(1), np.zeros(1), False, 0, 1)
    assert abs(float(_wrap(dihedral_angle(once, q) - r)[0])) < 1e-6
