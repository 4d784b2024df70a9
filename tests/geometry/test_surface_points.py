"""Surface points follow their mesh (Fig. 2); projection lands exactly on the surface."""

import numpy as np
import trimesh

from faceforge.geometry.surface_points import SurfacePoints, project_to_surface
from faceforge.geometry.triangles import points_from_barycentric


def rotation(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def test_surface_points_follow_rotating_icosahedron_exactly():
    """Fig. 2: when the icosahedron rotates (and translates), surface points and their normals
    are the rigidly transformed originals."""
    m = trimesh.creation.icosahedron()
    v, f = np.asarray(m.vertices), np.asarray(m.faces, np.int64)
    rng = np.random.default_rng(2)
    sp = SurfacePoints(rng.integers(0, len(f), 50), rng.dirichlet(np.ones(3), 50))
    p0, n0 = sp.positions(v, f), sp.normals(v, f)
    for angle in np.linspace(0.1, 2 * np.pi, 7):
        R = rotation([1, 2, 0.5], angle)
        t = np.array([0.3, -1.0, 2.0])
        vr = v @ R.T + t
        np.testing.assert_allclose(sp.positions(vr, f), p0 @ R.T + t, atol=1e-12)
        np.testing.assert_allclose(sp.normals(vr, f), n0 @ R.T, atol=1e-12)


def test_normals_are_blend_of_vertex_normals_and_unit():
    m = trimesh.creation.icosphere(2)
    v, f = np.asarray(m.vertices), np.asarray(m.faces, np.int64)
    sp = SurfacePoints([0, 1, 2], [[1, 0, 0], [0.2, 0.3, 0.5], [1 / 3, 1 / 3, 1 / 3]])
    n = sp.normals(v, f)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0)
    # at a vertex the normal is that vertex's normal (radial on the sphere)
    np.testing.assert_allclose(n[0], v[f[0, 0]] / np.linalg.norm(v[f[0, 0]]), atol=0.02)


def test_project_to_surface_is_closest_point_and_on_surface():
    m = trimesh.creation.icosphere(3)
    v, f = np.asarray(m.vertices), np.asarray(m.faces, np.int64)
    rng = np.random.default_rng(3)
    q = rng.normal(size=(100, 3))
    sp = project_to_surface(q, v, f)
    p = sp.positions(v, f)
    assert np.all(sp.bary >= 0) and np.allclose(sp.bary.sum(axis=1), 1)
    closest, dist, _ = trimesh.proximity.closest_point(m, q)
    np.testing.assert_allclose(p, closest, atol=1e-9)
    # points already on the surface project onto themselves
    again = project_to_surface(p, v, f).positions(v, f)
    np.testing.assert_allclose(again, p, atol=1e-9)
    np.testing.assert_allclose(points_from_barycentric(v, f, sp.face_ids, sp.bary), p)


def test_projector_cache_follows_content():
    from faceforge.geometry.surface_points import SurfaceProjector, projector

    m = trimesh.creation.icosphere(2)
    v, f = np.asarray(m.vertices).copy(), np.asarray(m.faces, np.int64)
    a = projector(v, f)
    assert projector(v.copy(), f.copy()) is a  # same content, same trees
    v2 = v * 2.0
    b = projector(v2, f)
    assert b is not a
    q = np.array([[0.0, 0.0, 5.0]])
    np.testing.assert_allclose(b.closest(q)[0], SurfaceProjector(v2, f).closest(q)[0])
    np.testing.assert_allclose(np.linalg.norm(project_to_surface(q, v2, f).positions(v2, f)), 2.0, atol=0.05)


def test_projector_keeps_what_every_line_on_a_mesh_asks_again():
    """The action lines of one layer ask the projector's mesh for its vertex normals, face
    normals, centre and mean edge length: computed once (the muscles' build did it per line,
    66 times on MakeHuman) and the same values as computed afresh."""
    from faceforge.anatomy.muscles.action_line import ActionLine, mean_edge_length, project_outermost
    from faceforge.geometry.surface_points import projector
    from faceforge.geometry.triangles import vertex_normals

    m = trimesh.creation.icosphere(2)
    v, f = np.asarray(m.vertices).copy(), np.asarray(m.faces, np.int64)
    calls = []
    p = projector(v, f)
    for _ in range(3):
        got = p.derived("count", lambda v, f: calls.append(1) or vertex_normals(v, f))
    assert len(calls) == 1
    np.testing.assert_array_equal(got, vertex_normals(v, f))
    assert not got.flags.writeable                      # shared: nobody edits it in place
    pts = np.array([[0.2, 0.3, 1.2], [0.5, 0.1, 1.1], [0.8, -0.1, 0.9]])
    first = project_outermost(pts, v, f)
    again = project_outermost(pts, v.copy(), f.copy())  # the kept values, by content
    np.testing.assert_array_equal(first.face_ids, again.face_ids)
    np.testing.assert_array_equal(first.bary, again.bary)
    assert "vertex_normals" in p._derived and "face_normals" in p._derived and "centre" in p._derived
    ActionLine.from_points(pts, v, f)
    assert p._derived["mean_edge_length"] == mean_edge_length(v, f)
