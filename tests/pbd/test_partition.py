"""Partitioned steps (faceforge.pbd.partition): how the parts are cut, that the regrouping is
a permutation, and that the threaded step equals the one-thread step to the bit."""

from __future__ import annotations

import numba
import numpy as np
import pytest

from faceforge.pbd import ModelBuilder, Solver, SolverSettings
from faceforge.pbd.partition import (
    constraint_groups, constraint_particles, particle_parts, particle_work, partitioned,
    split_blocks)
from tests.pbd.meshes import adjacent_quads, edges, skin_builder, sphere

DT = 1.0 / 25.0


def bodies_model(sizes=(2, 1, 1, 2, 0, 1)):
    """Separate closed skins (icospheres of these subdivisions), side by side, as the muscles
    of one layer."""
    b = ModelBuilder()
    for i, sub in enumerate(sizes):
        v, f = sphere(sub, radius=0.5)
        first = b.add_particles(v + [2.0 * i, 0.0, 0.0], 1.0)
        q = adjacent_quads(f) + first
        b.add_distance(edges(f) + first, 0.5)
        b.add_bending(q, 0.3)
        b.add_volume(f + first, 1.0)
    return b.finalize()


def skin_model(sub=3):
    v, f = sphere(sub)
    return skin_builder(v, f)[0].finalize()


def test_separate_bodies_stay_whole_and_nothing_joins_the_parts():
    model = bodies_model()
    part = particle_parts(model, 2)
    for j in range(model.volume_count):
        p = model.volume_particles[model.volume_particle_start[j]:model.volume_particle_start[j + 1]]
        assert len(np.unique(part[p])) == 1
    work = np.bincount(part, weights=particle_work(model) + 1.0)
    assert work.max() <= 1.1 * work.sum() / 2
    split = partitioned(model, 2)
    assert set(split.segment.tolist()) == {0, 1}          # no row in the seam (group 2)


@pytest.mark.parametrize("parts", [2, 3, 4])
def test_one_skin_is_cut_into_balanced_slabs_with_a_thin_seam(parts):
    model = skin_model(4)
    part = particle_parts(model, parts)
    assert np.array_equal(part < 0, model.inv_mass == 0)  # the kinematic skull joins no part
    work = np.bincount(part[part >= 0], weights=(particle_work(model) + 1.0)[part >= 0])
    assert len(work) == parts and work.max() <= 1.1 * work.sum() / parts
    total = seam = 0
    for cols in constraint_particles(model).values():
        g = constraint_groups(cols, part, parts)
        total += len(g)
        seam += int(np.count_nonzero(g == parts))
    assert 0 < seam < 0.1 * total


def test_a_small_model_stays_in_one_part():
    """Slabs cost a launch per iteration: below MIN_SLAB_CONSTRAINTS per part they do not pay."""
    from faceforge.pbd.partition import MIN_SLAB_CONSTRAINTS

    model = skin_model(2)
    assert model.constraint_count < 2 * MIN_SLAB_CONSTRAINTS
    assert set(particle_parts(model, 2).tolist()) == {-1, 0}
    solver = Solver(model, SolverSettings(colouring=True, partitions=2))
    assert not solver._threaded and solver._particle_order is None     # nothing to gather
    one = run(Solver(model, SolverSettings(colouring=True)), model)
    assert run(solver, model).positions.tobytes() == one.positions.tobytes()
    big = skin_model(3)
    assert big.constraint_count > 2 * MIN_SLAB_CONSTRAINTS
    assert set(particle_parts(big, 2).tolist()) == {-1, 0, 1}


def test_split_blocks_permutes_within_blocks_and_orders_rows_part_by_part():
    rng = np.random.default_rng(4)
    blocks = np.array([[0, 0, 50], [1, 0, 30], [0, 50, 80], [3, 0, 4]])
    groups = {0: rng.integers(0, 4, 80), 1: rng.integers(0, 4, 30), 3: rng.integers(0, 4, 4)}
    perm, rows, segment = split_blocks(blocks, groups, 3)
    for kind, start, stop in blocks:
        assert sorted(perm[kind][start:stop]) == list(range(start, stop))
    assert np.all(np.diff(segment) >= 0)                    # part 0, 1, 2, then the seam (3)
    covered = {k: np.zeros(len(g), int) for k, g in groups.items()}
    for (kind, start, stop), s in zip(rows, segment):
        assert np.all(groups[kind][perm[kind][start:stop]] == s)
        covered[kind][start:stop] += 1
    assert all(np.all(c == 1) for c in covered.values())
    source = [next(b for b, (k, a, z) in enumerate(blocks) if k == kind and a <= start < z)
              for kind, start, _ in rows]
    for s in range(4):  # within a part, the blocks keep their order
        assert np.all(np.diff(np.array(source)[segment == s]) > 0)


def test_partitioned_model_is_the_model_renumbered():
    model = skin_model(3)
    split = partitioned(model, 2)
    m, order = split.model, split.particle_order
    assert sorted(order) == list(range(model.particle_count))
    np.testing.assert_array_equal(m.rest_positions, model.rest_positions[order])
    new = np.argsort(order)
    for kind, cols in constraint_particles(model).items():   # the same constraints, renamed
        old = {tuple(sorted(r)) for r in np.stack([new[c] for c in cols], axis=1).tolist()}
        assert old == {tuple(sorted(r)) for r in np.stack(
            constraint_particles(m)[kind], axis=1).tolist()}
    np.testing.assert_array_equal(np.sort(m.volume_particles), np.sort(new[model.volume_particles]))
    assert np.all(np.diff(split.part[split.part >= 0]) >= 0)   # each part's particles contiguous
    np.testing.assert_array_equal(m.position_rest_target,
                                  model.position_rest_target[split.position_order])


def run(solver, model, steps=12):
    """Perturbed start, then the kinematic shell turning and the position target moving."""
    state = model.state()
    free = model.inv_mass > 0
    state.positions[free] += np.random.default_rng(1).normal(scale=0.03, size=(free.sum(), 3))
    control = model.control()
    kin = model.kinematic_indices
    for t in range(steps):
        a = 0.02 * t
        rot = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
        control.kinematic_positions = model.rest_positions[kin] @ rot.T
        control.position_targets = model.position_rest_target + 0.01 * t
        solver.step(state, state, control, DT)
    return state


def solver_for(model, parts, threaded):
    solver = Solver(model, SolverSettings(colouring=True, partitions=parts))
    solver._threaded = threaded      # what pbd.threads decides from the machine
    return solver


@pytest.mark.parametrize("parts", [2, 3])
@pytest.mark.parametrize("bodies", [False, True])
def test_threaded_step_equals_the_one_thread_step_to_the_bit(parts, bodies):
    model = bodies_model() if bodies else skin_model(3)
    if not bodies:   # the skin's volume ends the seam: its update is left to the next launch
        s = solver_for(model, parts, True)
        assert s._blocks[s._seg[-2]:s._seg[-1]][-1, 0] == 3
    one = run(solver_for(model, parts, False), model)
    threaded = run(solver_for(model, parts, True), model)
    assert np.abs(one.positions - model.rest_positions).max() > 0.01   # it did move
    assert threaded.positions.tobytes() == one.positions.tobytes()
    assert threaded.velocities.tobytes() == one.velocities.tobytes()
    old = numba.get_num_threads()
    try:                                  # and however many threads numba gives it
        numba.set_num_threads(1)
        single = run(solver_for(model, parts, True), model)
    finally:
        numba.set_num_threads(old)
    assert single.positions.tobytes() == one.positions.tobytes()


@pytest.mark.parametrize("parts", [2, 4])
def test_partitioned_rest_state_is_a_fixed_point(parts):
    model = skin_model(3)
    solver = Solver(model, SolverSettings(colouring=True, partitions=parts))
    state, control = model.state(), model.control()
    for _ in range(300):
        solver.step(state, state, control, DT)
    assert np.abs(state.positions - model.rest_positions).max() < 1e-12
    assert np.abs(state.velocities).max() < 1e-9


def test_partitioned_step_converges_to_the_sequential_solution():
    """Another Gauss-Seidel order: the same equilibrium under a held load."""
    model = skin_model(3)
    control = model.control()
    control.position_targets = model.position_rest_target + [0.05, -0.03, 0.02]
    out = {}
    for parts in (1, 2):
        solver = Solver(model, SolverSettings(colouring=True, partitions=parts))
        state = model.state()
        for _ in range(600):
            solver.step(state, state, control, DT)
        out[parts] = state.positions
    moved = np.abs(out[1] - model.rest_positions).max()
    assert moved > 0.02
    assert np.abs(out[2] - out[1]).max() < 1e-3 * moved


def test_position_slots_keep_their_meaning():
    """Targets are given in the model's slot order; the partitioned solver regroups the
    position constraints and must pull each particle to its own slot's target."""
    v, f = sphere(3)
    b, info = skin_builder(v, f)
    ends = np.concatenate([np.eye(3), -np.eye(3)])[[0, 3, 1, 4, 2, 5, 3, 0, 4, 1, 5, 2]]
    pulled = b.add_particles(1.2 * ends, 1.0)    # +x, -x, ... then -x, +x, ...: whatever
    slots = b.add_position(np.arange(pulled, pulled + 12), 1.0)   # the cut, some out of order
    model = b.finalize()
    control = model.control()
    goal = 1.2 * ends + np.arange(12)[:, None] * [0.01, 0.02, -0.01]
    control.position_targets[slots] = goal
    solver = Solver(model, SolverSettings(colouring=True, partitions=2))
    assert solver._position_order is not None     # the slots were regrouped
    state = model.state()
    for _ in range(30):
        solver.step(state, state, control, DT)
    np.testing.assert_allclose(state.positions[pulled:pulled + 12], goal, atol=1e-9)
    del info


def test_volume_summed_by_parts_equals_the_sequential_sum_to_the_bit():
    from faceforge.pbd.constraints.volume import (
        _project_volume, _solve_volume_parts, _volume_apply, localize, pair_triangles)
    from faceforge.pbd.partition import row_cuts

    v, f = sphere(3)
    rows = pair_triangles(f)
    part = (v[:, 0] > 0).astype(np.int64)
    order, cuts = row_cuts(rows, part, 2)
    rows = rows[order]
    assert 0 < cuts[1] < cuts[2] < cuts[3]                 # both parts and a seam
    particles, _, ref = localize(f)
    ref_ids = particles[ref]
    rng = np.random.default_rng(2)
    x0 = v * 1.05 + rng.normal(scale=0.01, size=v.shape)
    w = rng.uniform(0.5, 1.5, len(v))
    rest = 4.0
    serial = x0.copy()
    g = np.zeros_like(x0)
    label = part[particles]        # the body's particles grouped by part, as the solver does
    particles = particles[np.argsort(label, kind="stable")]
    pcuts = np.searchsorted(np.sort(label), np.arange(4))
    assert 0 < pcuts[1] < pcuts[2] == pcuts[3] == len(particles)
    _project_volume(serial, w, np.array([0, len(particles)]), particles, pcuts[None], cuts[None], rows,
                    np.array([0, len(ref)]), ref_ids, np.array([rest]), np.ones(1),
                    np.zeros(1), np.zeros(1), g, False, 0, 1)
    parts = x0.copy()
    _solve_volume_parts(parts, w, particles, pcuts, rows, cuts, ref_ids, rest, 1.0, 0.0, 0.0,
                        g, False, np.zeros((2, 8)), False)
    assert np.abs(serial - x0).max() > 1e-3
    assert parts.tobytes() == serial.tobytes()
    assert not g.any()
    # the update left to the caller, part by part (as the solver's next launch applies it)
    later = x0.copy()
    _, f6, moved = _solve_volume_parts(later, w, particles, pcuts, rows, cuts, ref_ids, rest, 1.0,
                                       0.0, 0.0, g, False, np.zeros((2, 8)), True)
    assert moved and g.any() and later.tobytes() == x0.tobytes()
    for p in (1, 0, 2):
        _volume_apply(later, w, particles[pcuts[p]:pcuts[p + 1]], g, f6, moved)
    assert later.tobytes() == serial.tobytes()
    assert not g.any()


def test_partitions_setting_is_checked():
    from faceforge.exceptions import ConfigError

    with pytest.raises(ValueError, match="partitions"):
        SolverSettings(partitions=0)
    with pytest.raises(ConfigError, match="solver.partitions"):
        SolverSettings.from_config({"partitions": 1.5})
    assert SolverSettings.from_config({"partitions": 3}).partitions == 3


@pytest.mark.parametrize("env", [{"NUMBA_NUM_THREADS": "1"}, {"NUMBA_THREADING_LAYER": "workqueue"},
                                 {}])
def test_threads_are_used_only_where_numba_runs_them_well(env):
    """One numba thread, or numba's own workqueue (a launch costs more than a part), runs the
    parts on the calling thread; TBB (installed with faceforge on x86-64) or OpenMP threads."""
    import os
    import platform
    import subprocess
    import sys

    code = ("from faceforge.pbd.threads import threaded, threads_used, load_tbb; import numba; "
            "print(threaded(), load_tbb(), numba.config.NUMBA_NUM_THREADS, threads_used(2), "
            "threads_used(1))")
    run_env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_")} | env
    out = subprocess.run([sys.executable, "-c", code], env=run_env, capture_output=True,
                         text=True, check=True).stdout.split()
    threads = int(out[2])
    assert out[4] == "1" and out[3] == ("2" if out[0] == "True" else "1")
    if env or threads < 2:
        assert out[0] == "False"
    elif platform.machine() in ("x86_64", "AMD64"):   # pip's tbb wheel, found by load_tbb
        assert out[0] == out[1] == "True"


def test_bodies_sharing_a_kinematic_particle_are_projected_in_the_seam():
    """A volume projection sums a gradient for every particle of its body, kinematic ones
    too: two bodies in two parts sharing one would add into the same row at once."""
    from faceforge.pbd.partition import body_groups

    b = ModelBuilder()
    v, f = sphere(3, radius=0.5)
    pin = b.add_particles(v[:1], 0.0)                    # one kinematic particle, shared
    for i in range(2):
        first = b.add_particles(v + [1.5 * i, 0.0, 0.0], 1.0)
        tri = f + first
        tri[f == 0] = pin
        b.add_distance(edges(f) + first, 0.5)
        b.add_bending(adjacent_quads(f) + first, 0.3)
        b.add_volume(tri, 1.0)
    model = b.finalize()
    part = particle_parts(model, 2)
    assert len(np.unique(part[part >= 0])) == 2
    assert body_groups(model, part, 2).tolist() == [2, 2]
    one = run(solver_for(model, 2, False), model)
    threaded = run(solver_for(model, 2, True), model)
    assert threaded.positions.tobytes() == one.positions.tobytes()


def test_solver_reports_the_threads_its_step_runs_on():
    from faceforge.pbd.threads import threads_used

    settings = SolverSettings(colouring=True, partitions=2)
    assert Solver(skin_model(3), settings).threads == threads_used(2)
    assert Solver(skin_model(2), settings).threads == 1          # too small to cut
    assert Solver(skin_model(3), SolverSettings(colouring=True)).threads == 1
