"""Heat-method geodesics: close to great-circle distance; components and unreferenced vertices."""

import numpy as np
import pytest
import trimesh

from faceforge.geometry.geodesic import GeodesicSolver, geodesic_distance


def test_sphere_great_circle():
    m = trimesh.creation.icosphere(4)
    v, f = np.asarray(m.vertices), np.asarray(m.faces, np.int64)
    d = geodesic_distance(v, f, [0])
    exact = np.arccos(np.clip(v @ v[0] / np.linalg.norm(v, axis=1) / np.linalg.norm(v[0]), -1, 1))
    assert d[0] == pytest.approx(0, abs=1e-3)
    # heat method error on a 2562-vertex sphere: a few percent of pi
    assert np.max(np.abs(d - exact)) < 0.05 * np.pi


def test_two_components_and_unreferenced_vertices():
    a = trimesh.creation.icosphere(2)
    b = trimesh.creation.icosphere(2)
    va, fa = np.asarray(a.vertices), np.asarray(a.faces, np.int64)
    vb = np.asarray(b.vertices) + [5.0, 0, 0]
    fb = np.asarray(b.faces, np.int64) + len(va) + 1
    v = np.vstack([va, [[100.0, 100, 100]], vb])  # one unreferenced vertex between them
    f = np.vstack([fa, fb])
    d = geodesic_distance(v, f, [0])
    assert np.all(np.isfinite(d[: len(va)])) and np.all(np.isinf(d[len(va):]))
    # the same as solving the first component alone
    np.testing.assert_allclose(d[: len(va)], geodesic_distance(va, fa, [0]), atol=1e-9)
    both = GeodesicSolver(v, f).distance([0, len(va) + 1])
    assert np.all(np.isfinite(both[fa.ravel()])) and np.all(np.isfinite(both[fb.ravel()]))
    assert np.isinf(both[len(va)])
    with pytest.raises(ValueError, match="no face"):
        geodesic_distance(v, f, [len(va)])
