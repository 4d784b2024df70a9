"""Head mesh validation and repair on small broken meshes."""

from __future__ import annotations

import numpy as np
import pytest

from faceforge.exceptions import MeshError
from faceforge.io.mesh_check import boundary_loops, check_mesh, merge_duplicate_vertices

from tests.fit.heads import ellipsoid_head


def unwelded(v, f):
    """Every face gets its own three vertices (what some OBJ/STL exporters write)."""
    return v[f.ravel()].copy(), np.arange(3 * len(f)).reshape(-1, 3)


def test_clean_closed_mesh_passes_unchanged(ellipsoid):
    v, f = ellipsoid
    c = check_mesh(v, f, "head.obj")
    np.testing.assert_array_equal(c.vertices, v)
    np.testing.assert_array_equal(c.faces, f)
    assert c.report.boundary_loops == [] and c.report.components == [len(f)] and c.report.warnings == []


def test_duplicate_vertices_merge_with_a_map_back(ellipsoid):
    v, f = ellipsoid
    uv, uf = unwelded(v, f)
    c = check_mesh(uv, uf, "soup.obj")
    assert len(c.vertices) == len(v) and c.report.merged_vertices == len(uv) - len(v)
    # round trip: internal data mapped back reproduces the user's vertices exactly
    np.testing.assert_array_equal(c.to_user(c.vertices), uv)
    np.testing.assert_array_equal(c.user_to_internal[c.internal_to_user], np.arange(len(c.vertices)))
    assert c.report.boundary_loops == [] and len(c.report.components) == 1
    assert any("merged" in w for w in c.report.warnings)


def test_merge_is_transitive_and_ordered():
    v = np.array([[0, 0, 0], [5, 0, 0], [0.4, 0, 0], [0.8, 0, 0], [5, 0, 0.1]], float)
    u2i, i2u = merge_duplicate_vertices(v, 0.5)
    np.testing.assert_array_equal(u2i, [0, 1, 0, 0, 1])
    np.testing.assert_array_equal(i2u, [0, 1])


def test_degenerate_and_duplicate_triangles_dropped(ellipsoid):
    v, f = ellipsoid
    v2 = np.vstack([v, (v[0] + v[1]) / 2])          # collinear with vertices 0 and 1
    bad = np.array([[0, 1, len(v)], [3, 3, 4]])
    f2 = np.vstack([f, bad, f[:2][:, [1, 2, 0]]])    # zero-area, repeated index, two duplicates
    c = check_mesh(v2, f2, "bad.obj")
    assert c.report.degenerate_faces == 2 and c.report.duplicate_faces == 2
    assert len(c.faces) == len(f) and c.report.boundary_loops == []


def test_holes_are_reported_as_loops(ellipsoid):
    v, f = ellipsoid
    top = np.any(f == 0, axis=1)                       # remove the cap fan around the pole
    c = check_mesh(v, f[~top], "open.obj")
    assert c.report.boundary_loops == [int(top.sum())]
    loop = boundary_loops(f[~top])[0]
    assert set(loop.tolist()) == set(np.unique(f[top]).tolist()) - {0}


def test_components_kept_and_reported(ellipsoid):
    v, f = ellipsoid
    v2 = np.vstack([v, v * 0.1 + [0, 0, 0.5]])
    c = check_mesh(v2, np.vstack([f, f + len(v)]), "two.obj")
    assert c.report.components == [len(f), len(f)] and len(c.faces) == 2 * len(f)


def test_non_manifold_edge_rejected(ellipsoid):
    v, f = ellipsoid
    v2 = np.vstack([v, [[3.0, 3.0, 3.0]]])
    fin = np.array([[f[0, 0], f[0, 1], len(v)]])         # a third face on an existing edge
    with pytest.raises(MeshError, match=r"fin\.obj: 1 non-manifold edges"):
        check_mesh(v2, np.vstack([f, fin]), "fin.obj")


@pytest.mark.parametrize("verts,faces,msg", [
    (np.zeros((0, 3)), np.zeros((0, 3), int), "at least 3 vertices"),
    (np.eye(3), np.zeros((0, 3), int), "needs triangles"),
    (np.array([[0, 0, 0], [1, 0, 0], [np.nan, 1, 0]]), np.array([[0, 1, 2]]), "NaN"),
    (np.eye(3), np.array([[0, 1, 5]]), "out of range"),
    (np.zeros((3, 3)), np.array([[0, 1, 2]]), "zero extent"),
    (np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0]], float), np.array([[0, 1, 2]]), "degenerate"),
])
def test_unusable_meshes_rejected_in_one_line(verts, faces, msg):
    with pytest.raises(MeshError, match=msg) as e:
        check_mesh(verts, faces, "x.obj")
    assert str(e.value).startswith("x.obj: ") and "\n" not in str(e.value)


def test_ellipsoid_helper_is_watertight():
    import trimesh

    v, f = ellipsoid_head(8, 12)
    m = trimesh.Trimesh(v, f, process=False)
    assert m.is_watertight and m.volume > 0


def test_inconsistent_winding_is_repaired(ellipsoid):
    import trimesh

    v, f = ellipsoid
    bad = f.copy()
    idx = np.random.default_rng(0).choice(len(f), 40, replace=False)
    bad[idx] = bad[idx][:, ::-1]
    c = check_mesh(v, bad, "w.obj")
    assert any("winding" in w for w in c.report.warnings)
    mesh = trimesh.Trimesh(c.vertices, c.faces, process=False)
    assert mesh.is_winding_consistent and abs(mesh.volume) > 0
    # the same triangles, only turned: each face keeps its vertex set
    np.testing.assert_array_equal(np.sort(c.faces, axis=1), np.sort(f, axis=1))


def test_two_heads_side_by_side_rejected(ellipsoid):
    """Two heads in one file with no landmarks: the detector fitted one of them and bound the other
    as skin; it is one error when the landmarks are to be found (``one_head``). With a landmark file
    the user chose the head, and the other is a kept piece (tests/reliability/test_scenarios.py)."""
    v, f = ellipsoid
    width = np.ptp(v[:, 0])
    with pytest.raises(MeshError, match="2 separate head-sized pieces"):
        check_mesh(np.vstack([v, v + [1.2 * width, 0, 0]]), np.vstack([f, f + len(v)]), "two.obj", one_head=True)
    assert len(check_mesh(np.vstack([v, v + [1.2 * width, 0, 0]]), np.vstack([f, f + len(v)])).report.components) == 2
    # a smaller head-sized piece beside it (a child's head) too; a small prop beside it is kept
    with pytest.raises(MeshError, match="separate head-sized"):
        check_mesh(np.vstack([v, 0.6 * v + [1.2 * width, 0, 0]]), np.vstack([f, f + len(v)]), "two.obj", one_head=True)
    c = check_mesh(np.vstack([v, 0.2 * v + [1.2 * width, 0, 0]]), np.vstack([f, f + len(v)]), "prop.obj", one_head=True)
    assert len(c.report.components) == 2


def test_pieces_in_or_on_the_head_are_not_a_second_head(ellipsoid):
    """A hair cap as large as the head but overlapping it stays a piece of the head."""
    v, f = ellipsoid
    cap = v * 1.05 + [0, 0.3 * np.ptp(v[:, 1]), 0]
    c = check_mesh(np.vstack([v, cap]), np.vstack([f, f + len(v)]), "hair.obj", one_head=True)
    assert len(c.report.components) == 2
