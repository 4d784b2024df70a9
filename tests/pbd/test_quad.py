"""The fused stretch + bending sweep (coloured PBD solver) against the separate sweeps."""

from __future__ import annotations

import numpy as np
import pytest

from faceforge.pbd import Solver, SolverSettings
from faceforge.pbd.colouring import colour_order
from faceforge.pbd.constraints._common import BATCH, BATCH_ROWS
from faceforge.pbd.constraints.bending import init_bending, rest_cos_sin
from faceforge.pbd.constraints.distance import init_distance, pbd_coefficients
from faceforge.pbd.constraints.area import init_area
from faceforge.pbd.constraints.quad import (
    _project_quads_batched, area_table, areas_first, match_quad_stretches, match_quad_triangles,
    stretch_table)
from tests.pbd import twins
from tests.pbd.meshes import adjacent_quads, edges, skin_builder, sphere


def test_match_finds_each_stretch_once_in_either_orientation():
    quads = np.array([[0, 1, 2, 3], [1, 4, 0, 5], [6, 7, 8, 9]])
    pairs = np.array([[1, 0], [2, 3], [4, 1], [0, 1], [9, 8], [2, 6]])
    match = match_quad_stretches(pairs, quads)
    # (0, 1) is matched once (first occurrence, stored reversed); its duplicate stays
    np.testing.assert_array_equal(match, [[0, 1], [2, -1], [-1, 4]])
    coef = np.array([[1.0, 0.1, 0.2], [2.0, 0.3, 0.4], [3.0, 0.5, 0.6], [4.0, 0.7, 0.8],
                     [5.0, 0.9, 1.0], [6.0, 0.0, 0.0]])
    table = stretch_table(pairs, quads, match, coef)
    # shares follow the quad's particle order: pair (1, 0) -> share of p0 is its 2nd share
    np.testing.assert_array_equal(table[0], [1.0, 0.2, 0.1, 2.0, 0.3, 0.4])
    np.testing.assert_array_equal(table[1], [3.0, 0.6, 0.5, 1.0, 0.0, 0.0])
    np.testing.assert_array_equal(table[2], [1.0, 0.0, 0.0, 5.0, 1.0, 0.9])


@pytest.mark.parametrize("scale", [0.002, 0.2])  # small: Padé branch; large: atan2 fix-up
def test_fused_sweep_is_stretch_stretch_bending_per_quad(scale):
    v, f = sphere(3)
    q = adjacent_quads(f)
    order, runs = colour_order(q, len(v), np.array([[0, 100], [100, len(q)]]))
    q = q[order]
    rng = np.random.default_rng(8)
    x0 = v + rng.normal(scale=scale, size=v.shape)
    w = rng.uniform(0.0, 2.0, len(v))
    w[::13] = 0.0
    pairs = np.concatenate([edges(f)[::-1], q[:, [3, 2]]])  # mixed orientations
    pairs[::2] = pairs[::2, ::-1]
    rest_d = init_distance(v, pairs) * 1.05
    k_d = rng.uniform(0.1, 1.0, len(pairs))
    coef = pbd_coefficients(pairs, rest_d, k_d, w)
    match = match_quad_stretches(pairs, q)
    assert (match >= 0).all()
    match[::7, 1] = -1  # some quads without a cross stretch
    rest_b = init_bending(v, q)
    k_b = rng.uniform(0.1, 1.0, len(q))
    got = x0.copy()
    _project_quads_batched(got, q, np.ascontiguousarray(w[q].T),
                           np.ascontiguousarray(rest_cos_sin(rest_b).T), k_b,
                           np.ascontiguousarray(stretch_table(pairs, q, match, coef).T),
                           np.zeros((3, len(q))), False, runs, runs[1:],
                           np.zeros(BATCH * BATCH_ROWS), 0, len(q))
    want = x0.copy()
    for j in range(len(q)):  # the plain-Python twins, quad by quad
        for hit in match[j]:
            if hit >= 0:
                want, _ = twins.distance(want, w, pairs[hit:hit + 1], rest_d[hit:hit + 1],
                                         k_d[hit:hit + 1])
        want, _ = twins.bending(want, w, q[j:j + 1], rest_b[j:j + 1], k_b[j:j + 1])
    assert np.abs(got - x0).max() > 1e-4
    np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-12)


def test_coloured_solver_fuses_skin_stretches_and_keeps_the_others():
    v, f = sphere(2)
    b, _ = skin_builder(v, f)
    model = b.finalize()
    fused = Solver(model, SolverSettings(colouring=True))
    kinds = fused._blocks[:, 0].tolist()
    # the bending block became a fused block with the areas (all triangles of a sphere
    # find a quad, so the area block is gone)
    assert 7 in kinds and 1 not in kinds and 2 not in kinds
    # only the anchors stay distance constraints (every edge is interior on a sphere)
    assert len(fused._arrays["distance"][0]) == len(v)
    assert len(fused._arrays["area"][0]) == 0
    assert Solver(model, SolverSettings(colouring=True, stiffness_mode="xpbd"))._blocks[:, 0] \
        .tolist() == model.blocks[:, 0].tolist()
    assert Solver(model, SolverSettings())._blocks[:, 0].tolist() == model.blocks[:, 0].tolist()
    # the same constraints in another Gauss-Seidel order: the rest state is reached as fast
    rng = np.random.default_rng(2)
    start = model.state()
    free = model.inv_mass > 0
    start.positions[free] += rng.normal(scale=0.02, size=(free.sum(), 3))
    error = {}
    for colouring in (False, True):
        state = start.copy()
        solver = Solver(model, SolverSettings(colouring=colouring))
        for _ in range(100):
            solver.step(state, state, model.control(), 0.04)
        error[colouring] = np.abs(state.positions - model.rest_positions).max()
    initial = np.abs(start.positions - model.rest_positions).max()
    assert error[False] < 0.1 * initial
    assert error[True] < 1.5 * error[False]


def test_match_quad_triangles_gives_each_triangle_to_one_quad_holding_it():
    v, f = sphere(2)
    q = adjacent_quads(f)
    tris = np.concatenate([f, f[:3]])  # three duplicates: no quad left for some of them
    match = match_quad_triangles(tris[:, ::-1], q)  # orientation does not matter
    hit = match[match >= 0]
    assert len(np.unique(hit)) == len(hit)  # a triangle to one quad at most
    assert set(range(len(f))) <= set(hit.tolist())  # the augmenting paths place all
    for j in np.flatnonzero(match >= 0):
        held = {frozenset(q[j, [0, 1, 2]]), frozenset(q[j, [0, 1, 3]])}
        assert frozenset(tris[match[j]]) in held
    table = area_table(tris, q, match, np.arange(len(tris)) + 1.0, np.full(len(tris), 0.5))
    for j in np.flatnonzero(match >= 0)[:20]:
        third = q[j, 2] if table[j, 2] else q[j, 3]
        assert third in tris[match[j]] and table[j, 0] == match[j] + 1.0
    assert (table[match < 0, :2] == 0.0).all()


@pytest.mark.parametrize("scale", [0.002, 0.2])  # small: Padé branch; large: atan2 fix-up
def test_fused_sweep_with_areas_is_stretch_stretch_bending_area_per_quad(scale):
    v, f = sphere(3)
    q = adjacent_quads(f)
    order, runs = colour_order(q, len(v), np.array([[0, len(q)]]))
    q = q[order]
    rng = np.random.default_rng(9)
    x0 = v + rng.normal(scale=scale, size=v.shape)
    w = rng.uniform(0.0, 2.0, len(v))
    w[::11] = 0.0
    pairs = np.concatenate([q[:, [1, 0]], q[:, 2:]])
    rest_d = init_distance(v, pairs) * 0.97
    k_d = rng.uniform(0.1, 1.0, len(pairs))
    match = match_quad_stretches(pairs, q)
    rest_b = init_bending(v, q)
    k_b = rng.uniform(0.1, 1.0, len(q))
    tris = f[rng.permutation(len(f))]
    rest_a = init_area(v, tris) * 1.1
    k_a = rng.uniform(0.1, 1.0, len(tris))
    tri_of = match_quad_triangles(tris, q)
    assert (tri_of >= 0).sum() == len(f)
    got = x0.copy()
    _project_quads_batched(
        got, q, np.ascontiguousarray(w[q].T), np.ascontiguousarray(rest_cos_sin(rest_b).T), k_b,
        np.ascontiguousarray(
            stretch_table(pairs, q, match, pbd_coefficients(pairs, rest_d, k_d, w)).T),
        np.ascontiguousarray(area_table(tris, q, tri_of, rest_a, k_a).T), True, runs, runs[1:],
        np.zeros(BATCH * BATCH_ROWS), 0, len(q))
    want = x0.copy()
    for j in range(len(q)):  # the plain-Python twins, quad by quad
        for hit in match[j]:
            want, _ = twins.distance(want, w, pairs[hit:hit + 1], rest_d[hit:hit + 1],
                                     k_d[hit:hit + 1])
        want, _ = twins.bending(want, w, q[j:j + 1], rest_b[j:j + 1], k_b[j:j + 1])
        t = tri_of[j]
        if t >= 0:
            want, _ = twins.area(want, w, tris[t:t + 1], rest_a[t:t + 1], k_a[t:t + 1])
    assert np.abs(got - x0).max() > 1e-4
    np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("scale", [0.002, 0.2])
def test_quads_with_areas_first_in_each_run_give_the_same_bits(scale):
    """The solver moves the quads with a fused area to the front of each colour run and the
    sweep skips the area rows of the others: the quads of a run are independent, so this is
    the same sweep, bit for bit, as every area row projected in the colour order."""
    v, f = sphere(3)
    q = adjacent_quads(f)
    order, runs = colour_order(q, len(v), np.array([[0, 150], [150, len(q)]]))
    q = q[order]
    rng = np.random.default_rng(10)
    x0 = v + rng.normal(scale=scale, size=v.shape)
    w = rng.uniform(0.0, 2.0, len(v))
    pairs = np.concatenate([q[:, [1, 0]], q[:, 2:]])
    stretch = stretch_table(pairs, q, match_quad_stretches(pairs, q),
                            pbd_coefficients(pairs, init_distance(v, pairs) * 0.97,
                                             rng.uniform(0.1, 1.0, len(pairs)), w)).T
    rest_cs = rest_cos_sin(init_bending(v, q)).T
    k_b = rng.uniform(0.1, 1.0, len(q))
    tris = f[rng.permutation(len(f))][: len(f) * 2 // 3]   # a third of the quads lose theirs too
    tri_of = match_quad_triangles(tris, q)
    area = area_table(tris, q, tri_of, init_area(v, tris) * 1.1, rng.uniform(0.1, 1.0, len(tris))).T

    def sweep(p, stop):
        x = x0.copy()
        for _ in range(3):
            _project_quads_batched(x, q[p], np.ascontiguousarray(w[q[p]].T),
                                   np.ascontiguousarray(rest_cs[:, p]), k_b[p],
                                   np.ascontiguousarray(stretch[:, p]),
                                   np.ascontiguousarray(area[:, p]), True, runs, stop,
                                   np.zeros(BATCH * BATCH_ROWS), 0, len(q))
        return x

    first, stop = areas_first(tri_of, runs)
    assert sorted(first.tolist()) == list(range(len(q)))
    for a, b, s in zip(runs[:-1], runs[1:], stop):  # moved within their run, areas first
        assert sorted(first[a:b].tolist()) == list(range(a, b))
        assert (tri_of[first[a:s]] >= 0).all() and (tri_of[first[s:b]] < 0).all()
    assert (stop < runs[1:]).any() and (stop > runs[:-1]).any()
    want = sweep(np.arange(len(q)), runs[1:])
    assert np.abs(want - x0).max() > 1e-4
    assert sweep(first, stop).tobytes() == want.tobytes()
