"""ModelBuilder validation and layout, SolverSettings and its config helper."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from faceforge.exceptions import ConfigError, FaceforgeError
from faceforge.pbd import ModelBuilder, Solver, SolverSettings, effective_stiffness
from faceforge.pbd.model import AREA, DISTANCE, POSITION

ROOT = Path(__file__).resolve().parents[2]


def small_builder():
    b = ModelBuilder()
    b.add_particles(np.eye(3), 1.0)
    return b


def test_blocks_follow_call_order_and_merge_neighbours():
    b = small_builder()
    b.add_distance([[0, 1]], 0.5)
    b.add_distance([[1, 2]], 0.5)
    b.add_area([[0, 1, 2]], 1.0)
    slots = b.add_position([2], 0.2)
    b.add_distance([[0, 2]], 0.5)
    m = b.finalize()
    assert m.blocks.tolist() == [[DISTANCE, 0, 2], [AREA, 0, 1], [POSITION, 0, 1],
                                 [DISTANCE, 2, 3]]
    assert slots.tolist() == [0]
    np.testing.assert_allclose(m.distance_rest_length, np.sqrt(2.0))


def test_model_is_read_only_and_state_control_are_copies():
    b = small_builder()
    b.add_position([1], 0.2)
    m = b.finalize()
    with pytest.raises(ValueError):
        m.rest_positions[0, 0] = 5.0
    s, c = m.state(), m.control()
    s.positions[0, 0] = 5.0
    c.position_targets[0, 0] = 5.0
    assert m.rest_positions[0, 0] == 1.0 and m.position_rest_target[0, 0] == 0.0


@pytest.mark.parametrize("call", [
    lambda b: b.add_distance([[0, 3]], 0.5),           # index out of range
    lambda b: b.add_distance([[0, 1, 2]], 0.5),        # wrong width
    lambda b: b.add_distance([[0, 1]], 1.5),           # stiffness outside [0, 1]
    lambda b: b.add_area([[0, 1, 2]], [0.5, 0.5]),     # stiffness length
    lambda b: b.add_bending([[0.0, 1, 2, 0]], 0.5),    # float indices
    lambda b: b.add_attachment([0], [[0, 1, 2]], [[1, 0, 0]], 0.5),  # attached to itself
    lambda b: b.add_attachment([0], [[1, 2, 1]], [[1, 0]], 0.5),     # bary shape
    lambda b: b.add_particles(np.zeros((2, 2))),       # positions shape
    lambda b: b.add_particles(np.zeros((2, 3)), -1.0),  # negative inverse mass
])
def test_builder_rejects_bad_input(call):
    with pytest.raises(ValueError):
        call(small_builder())


def test_solver_rejects_bad_state_shapes():
    m = small_builder().finalize()
    s = m.state()
    bad = m.state()
    bad.positions = np.zeros((2, 3))
    with pytest.raises(ValueError, match="state_out.positions"):
        Solver(m).step(s, bad, m.control(), 0.04)


def test_from_config_reads_default_yaml():
    cfg = yaml.safe_load((ROOT / "configs" / "default.yaml").read_text())
    s = SolverSettings.from_config(cfg)
    assert s == SolverSettings.from_config(cfg["solver"])
    assert (s.iterations, s.substeps, s.damping, s.stiffness_mode) == (10, 1, 0.1, "paper")


@pytest.mark.parametrize("section, key", [
    ({"iterations": 0}, "solver.iterations"),
    ({"iterations": 2.5}, "solver.iterations"),
    ({"damping": 1.0}, "solver.damping"),
    ({"stiffness_mode": "stiff"}, "solver.stiffness_mode"),
    ({"gravity": "down"}, "solver.gravity"),
    ({"iteration": 10}, "solver.iteration"),
])
def test_from_config_errors_name_the_key_and_file(section, key):
    with pytest.raises(ConfigError) as err:
        SolverSettings.from_config(section, path="my.yaml")
    assert isinstance(err.value, FaceforgeError)
    message = str(err.value)
    assert message.startswith(f"my.yaml: {key}:") and "\n" not in message


def test_effective_stiffness_modes():
    k = np.array([0.0, 0.2, 0.95, 1.0])
    paper, c = effective_stiffness(k, SolverSettings(stiffness_mode="paper"))
    np.testing.assert_array_equal(paper, k)
    assert not c.any()
    ind, _ = effective_stiffness(k, SolverSettings(iterations=7,
                                                   stiffness_mode="iteration_independent"))
    np.testing.assert_allclose(1.0 - (1.0 - ind) ** 7, k)  # n projections remove the fraction k
    kx, cx = effective_stiffness(k, SolverSettings(stiffness_mode="xpbd"))
    np.testing.assert_array_equal(kx, [0.0, 1.0, 1.0, 1.0])
    np.testing.assert_allclose(cx, [0.0, 4.0, 0.05 / 0.95, 0.0])


def test_solver_rejects_a_model_with_ids_out_of_range():
    import dataclasses

    from faceforge.pbd.constraints import solve_distance
    b = ModelBuilder()
    b.add_particles(np.eye(3), 1.0)
    b.add_distance([[0, 1]], 0.5)
    model = b.finalize()
    bad = dataclasses.replace(model, distance_indices=np.array([[0, -1]]))
    with pytest.raises(ValueError, match="distance_indices"):
        Solver(bad)
    with pytest.raises(ValueError, match="outside"):
        solve_distance(np.eye(3), np.ones(3), [[0, 3]], [1.0], 0.5)
