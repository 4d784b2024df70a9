"""Mirror-aware colouring (issue 25): a constraint and its mirror twin share a colour, so a
colour-by-colour sweep of a mirror-symmetric model keeps it symmetric; plain-Python twin of
the numba kernel."""

from __future__ import annotations

import numpy as np
import pytest

from faceforge.geometry.mirror_mesh import mirror_half, vertex_partners
from faceforge.pbd import ModelBuilder, Solver, SolverSettings
from faceforge.pbd.colouring import mirror_colouring, mirror_twins
from tests.pbd.meshes import adjacent_quads, edges, sphere


def _symmetric_sphere():
    v, f = sphere(2)
    turn = np.array([[np.cos(0.4), 0.0, np.sin(0.4)], [0.0, 1.0, 0.0], [-np.sin(0.4), 0.0, np.cos(0.4)]])
    v, f = mirror_half(v @ turn.T, f)   # a triangulation that is its own mirror image
    return v, f, vertex_partners(v)


def mirror_greedy_twin(idx, twin, share):
    """Plain-Python twin of ``colouring._greedy_mirror``."""
    taken, out = {}, [-1] * len(idx)

    def free(rows):
        used = set().union(*(taken.get(int(i), set()) for r in rows for i in idx[r]))
        c = 0
        while c in used:
            c += 1
        return c

    def mark(r, c):
        out[r] = c
        for i in idx[r]:
            taken.setdefault(int(i), set()).add(c)

    for j in range(len(idx)):
        if out[j] >= 0:
            continue
        t = int(twin[j])
        if t >= 0 and t != j and out[t] < 0 and not share[j]:
            c = free([j, t])
            mark(j, c)
            mark(t, c)
            continue
        mark(j, free([j]))
        if t >= 0 and t != j and out[t] < 0:
            mark(t, free([t]))
    return np.array(out)


@pytest.mark.parametrize("kind", ["edges", "quads", "faces"])
def test_twins_share_a_colour(kind):
    v, f, partner = _symmetric_sphere()
    idx = {"edges": edges(f), "quads": adjacent_quads(f), "faces": f}[kind]
    colours = mirror_colouring(idx, len(v), partner)
    twin, share = mirror_twins(idx, partner)
    np.testing.assert_array_equal(colours, mirror_greedy_twin(idx, twin, share))
    assert (twin >= 0).all()   # the constraint set is its own mirror image
    for c in np.unique(colours):
        members = idx[colours == c].ravel()
        assert len(members) == len(np.unique(members)), f"colour {c} shares a particle"
    apart = ~share
    assert apart.mean() > 0.5   # a coarse sphere: a quarter touch the plane
    np.testing.assert_array_equal(colours[apart], colours[twin[apart]])


def _pulled(partner, mirror: bool):
    """The symmetric sphere's stretch network, squeezed symmetrically and let go for a few
    steps (soft stiffness: the sweep's order shows); its final positions."""
    v, f, p = _symmetric_sphere()
    b = ModelBuilder()
    b.add_particles(v, 1.0)
    b.add_distance(edges(f), 0.3)
    b.add_bending(adjacent_quads(f), 0.5)
    model = b.finalize()
    solver = Solver(model, SolverSettings(iterations=3, colouring=True, partitions=1), p if mirror else None)
    state, control = model.state(), model.control()
    state.positions[:] = v * np.array([1.0, 0.6, 1.3]) + 0.3 * np.abs(v[:, :1]) * v   # symmetric squeeze
    state.velocities[:] = 0.0
    for _ in range(5):
        solver.step(state, state, control, 0.04)
    return state.positions, p


def test_a_symmetric_model_stays_more_symmetric():
    """Twins in one colour: the sweep's order is mirrored except for the constraints that
    straddle the plane (a twin sharing a particle takes another colour; a quarter of this
    coarse sphere's), so the asymmetry drops (3x here), not to round-off."""
    x, p = _pulled(None, True)
    x0, _ = _pulled(None, False)   # greedy colours in builder order: the sweep is lopsided
    gap = np.abs(x[p] * [-1.0, 1.0, 1.0] - x).mean()
    gap0 = np.abs(x0[p] * [-1.0, 1.0, 1.0] - x0).mean()
    assert gap < 0.5 * gap0


def test_reversed_colouring_swaps_the_straddling_twins():
    """``reverse``: still a colouring (no shared particle in a colour), twins apart still share
    a colour, and each pair straddling the plane runs in the other order."""
    v, f, partner = _symmetric_sphere()
    idx = edges(f)
    fwd = mirror_colouring(idx, len(v), partner)
    rev = mirror_colouring(idx, len(v), partner, reverse=True)
    twin, share = mirror_twins(idx, partner)
    for c in np.unique(rev):
        members = idx[rev == c].ravel()
        assert len(members) == len(np.unique(members)), f"colour {c} shares a particle"
    np.testing.assert_array_equal(rev[~share], rev[twin[~share]])
    pairs = np.flatnonzero(share & (twin > np.arange(len(idx))))
    assert len(pairs) > 0
    assert (np.sign(fwd[pairs] - fwd[twin[pairs]]) == -np.sign(rev[pairs] - rev[twin[pairs]])).all()


def test_a_small_symmetric_model_stays_symmetric():
    """The straddling twins' order averaged out (Solver steps a small mirror-symmetric model in
    both orders and takes the mean): the squeezed sphere stays its own mirror image to
    round-off. With one order (the code before) it was a third of the lopsided sweep's gap."""
    x, p = _pulled(None, True)
    x0, _ = _pulled(None, False)
    gap = np.abs(x[p] * [-1.0, 1.0, 1.0] - x).mean()
    gap0 = np.abs(x0[p] * [-1.0, 1.0, 1.0] - x0).mean()
    assert gap0 > 1e-4
    assert gap < 1e-9 * max(1.0, np.abs(x).max())


def test_a_symmetric_skin_is_cut_at_its_plane():
    """``partitions: 2`` on a mirror-symmetric model large enough for slabs: the two parts are
    the two sides, the particles on the plane go to the seam (label 2), and the sweep keeps
    the model symmetric (before, the median cut put the plane's particles in one part and
    their constraints half in a part, half in the seam)."""
    from faceforge.pbd.partition import particle_parts

    v, f = sphere(4)
    turn = np.array([[np.cos(0.4), 0.0, np.sin(0.4)], [0.0, 1.0, 0.0], [-np.sin(0.4), 0.0, np.cos(0.4)]])
    v, f = mirror_half(v @ turn.T, f)
    p = vertex_partners(v)
    b = ModelBuilder()
    b.add_particles(v, 1.0)
    b.add_distance(edges(f), 0.3)
    b.add_bending(adjacent_quads(f), 0.5)
    model = b.finalize()
    assert model.constraint_count >= 4000
    part = particle_parts(model, 2, p)
    mid = p == np.arange(len(p))
    assert mid.any() and (part[mid] == 2).all()
    assert set(part[~mid].tolist()) == {0, 1} and (part[~mid] != part[p[~mid]]).all()
    solver = Solver(model, SolverSettings(iterations=3, colouring=True, partitions=2), p)
    state, control = model.state(), model.control()
    state.positions[:] = v * np.array([1.0, 0.6, 1.3]) + 0.3 * np.abs(v[:, :1]) * v
    for _ in range(5):
        solver.step(state, state, control, 0.04)
    x = state.positions
    moved = np.abs(x - v).mean()
    assert np.abs(x[p] * [-1.0, 1.0, 1.0] - x).mean() < 0.02 * moved
