"""Skin constraint topology (§8) on synthetic meshes."""

import numpy as np
import pytest

from faceforge.skin.layer import skin_topology
from tests.skin.synthetic import grid, sphere


def _slow_topology(faces):
    """Plain-Python twin: dict of edge -> opposite vertices."""
    opp = {}
    for t in faces:
        for k in range(3):
            a, b, c = int(t[k]), int(t[(k + 1) % 3]), int(t[(k + 2) % 3])
            opp.setdefault((min(a, b), max(a, b)), []).append(c)
    return opp


@pytest.mark.parametrize("mesh", [grid(5, 4), sphere(1.0, 2)], ids=["grid", "sphere"])
def test_counts_are_euler_consistent(mesh):
    v, f = mesh
    topo = skin_topology(f)
    e, m = len(topo.edges), len(f)
    # every face has 3 edge slots: interior edges fill two, boundary edges one
    assert 3 * m == 2 * len(topo.cross_pairs) + len(topo.boundary_edges)
    assert len(topo.nonmanifold_edges) == 0
    assert e == len(topo.cross_pairs) + len(topo.boundary_edges)
    # Euler characteristic V - E + F: 2 for the sphere, 1 for the disc-like grid
    chi = len(v) - e + m
    assert chi == (1 if len(topo.boundary_edges) else 2)


def test_each_interior_edge_gives_one_cross_stretch_and_one_bending():
    v, f = sphere(1.0, 1)
    topo = skin_topology(f)
    slow = _slow_topology(f)
    interior = {k: o for k, o in slow.items() if len(o) == 2}
    assert len(topo.cross_pairs) == len(interior) == len(topo.bending_quads)
    for (a, b, c, d), (p, q) in zip(topo.bending_quads, topo.cross_pairs):
        assert (c, d) == (p, q)
        assert sorted(interior[(a, b)]) == sorted([c, d])
        assert c not in (a, b) and d not in (a, b) and c != d


def test_edges_match_the_plain_python_twin():
    v, f = grid(3, 3)
    topo = skin_topology(f)
    assert sorted(map(tuple, topo.edges.tolist())) == sorted(_slow_topology(f))
    assert np.all(topo.edges[:, 0] < topo.edges[:, 1])


def test_nonmanifold_edge_gets_stretch_but_no_bending():
    f = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]])
    topo = skin_topology(f)
    assert [0, 1] in topo.nonmanifold_edges.tolist()
    assert len(topo.cross_pairs) == 0
    assert [0, 1] in topo.edges.tolist()


def test_bad_shape_is_rejected():
    with pytest.raises(ValueError, match="shape"):
        skin_topology(np.zeros((3, 4), int))
