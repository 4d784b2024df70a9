"""The skin layer in the PBD engine: rest is a fixed point, anchors drag the skin."""

import numpy as np
import pytest

from faceforge.skin.binding import Body, bind_skin
from faceforge.skin.layer import SkinStiffness, add_skin, skin_topology
from faceforge.pbd import ModelBuilder, Solver, SolverSettings
from tests.skin.synthetic import grid, sphere


def _model(v, f, b, stiffness=SkinStiffness()):
    builder = ModelBuilder()
    layer = add_skin(builder, v, f, stiffness, b.vertex_ids, b.points)
    model = builder.finalize()
    return model, layer


@pytest.fixture(scope="module")
def bound_sphere():
    v, f = sphere(1.0, 2)
    upper = Body("cranium", "cranium", *sphere(0.8, 3))
    b = bind_skin(v, f, [upper], max_distance=0.5)
    return v, f, upper, b


@pytest.mark.parametrize("position", [1.0, 0.9])
def test_constraint_counts(bound_sphere, position):
    v, f, _, b = bound_sphere
    model, layer = _model(v, f, b, SkinStiffness(position=position))
    topo = skin_topology(f)
    k = len(b.vertex_ids)
    assert model.particle_count == len(v) + k
    assert model.distance_count == k + len(topo.edges) + len(topo.cross_pairs)
    assert model.bending_count == len(topo.bending_quads)
    assert model.area_count == len(f) and model.volume_count == 1
    np.testing.assert_array_equal(layer.anchor_particles, len(v) + np.arange(k))
    # held exactly (1): the anchors are kinematic, tethered; softer: position constraints
    kinematic = position == 1.0
    assert layer.kinematic_anchors == kinematic
    assert model.position_count == (0 if kinematic else k)
    np.testing.assert_array_equal(model.kinematic_indices, layer.anchor_particles if kinematic else [])
    assert layer.anchor_targets(model.control()).shape == (k, 3)


def test_rest_state_is_a_fixed_point_over_1000_frames(bound_sphere):
    v, f, upper, b = bound_sphere
    model, layer = _model(v, f, b)
    solver = Solver(model, SolverSettings(iterations=10, substeps=1, damping=0.1))
    state = model.state()
    control = model.control()
    layer.anchor_targets(control)[layer.anchor_slots] = b.targets([(upper.vertices, upper.faces)])
    for _ in range(1000):
        solver.step(state, state, control, 1 / 25)
    drift = np.abs(layer.skin_positions(state.positions) - v).max()
    assert drift < 1e-4 * np.linalg.norm(np.ptp(v, axis=0))


def test_moving_anchors_drag_the_bound_skin():
    v, f = grid(6, 6)
    v[:, 2] = 0.2
    plate = grid(6, 6)
    lower = Body("mandible", "mandible", plate[0] * 1.2 - 0.1, plate[1])
    b = bind_skin(v, f, [lower], max_distance=0.5, normals=np.tile([0, 0, 1.0], (len(v), 1)))
    inner = (v[:, 0] > 0.1) & (v[:, 0] < 0.9) & (v[:, 1] > 0.1) & (v[:, 1] < 0.9)
    assert np.all(b.status[inner] != 0)
    model, layer = _model(v, f, b)
    solver = Solver(model, SolverSettings(iterations=10))
    state, control = model.state(), model.control()
    # along the anchor rays: a distance constraint keeps |p - q|, so a sideways
    # translation of parallel anchors is a free (pendulum) mode; a normal one is not
    shift = np.array([0.0, 0.0, -0.05])
    layer.anchor_targets(control)[layer.anchor_slots] = b.targets([(lower.vertices + shift, lower.faces)])
    for _ in range(200):
        solver.step(state, state, control, 1 / 25)
    moved = layer.skin_positions(state.positions) - v
    np.testing.assert_allclose(moved[b.vertex_ids], np.broadcast_to(shift, moved[b.vertex_ids].shape), atol=2e-3)
