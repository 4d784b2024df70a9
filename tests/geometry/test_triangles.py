"""triangles: normals, areas, barycentric round trip, mesh concatenation."""

import numpy as np
import pytest
import trimesh

from faceforge.geometry.triangles import (
    barycentric, check_mesh, concatenate_meshes, face_areas, face_normals, points_from_barycentric,
    smooth_vertex_normals, vertex_normals)


def ico(sub=2):
    m = trimesh.creation.icosphere(sub)
    return np.asarray(m.vertices), np.asarray(m.faces, np.int64)


def twin_vertex_normals(v, f):
    """Plain-Python twin: loop over each vertex's star."""
    out = np.zeros_like(v)
    for i in range(len(v)):
        acc = np.zeros(3)
        for tri in f:
            if i in tri:
                a, b, c = v[tri]
                n = np.cross(b - a, c - a)
                acc += n  # |n| = 2 area: area weighting
        if np.linalg.norm(acc) > 0:
            out[i] = acc / np.linalg.norm(acc)
    return out


def test_face_normals_and_areas_match_trimesh():
    v, f = ico(2)
    m = trimesh.Trimesh(v, f, process=False)
    np.testing.assert_allclose(face_normals(v, f), m.face_normals, atol=1e-12)
    np.testing.assert_allclose(face_areas(v, f), m.area_faces, rtol=1e-12)
    assert face_areas(v, f).sum() == pytest.approx(m.area)


def test_vertex_normals_area_weighted_twin_and_sphere():
    rng = np.random.default_rng(0)
    v, f = ico(1)
    v = v * rng.uniform(0.8, 1.2, (len(v), 1))  # irregular areas
    np.testing.assert_allclose(vertex_normals(v, f), twin_vertex_normals(v, f), atol=1e-12)
    vs, fs = ico(3)
    # on a fine sphere the vertex normal is the radial direction
    assert np.min(np.einsum("ij,ij->i", vertex_normals(vs, fs), vs)) > 0.999


def test_smoothed_normals_of_a_noisy_sphere_point_out_again():
    """A fine sphere with radial noise of 30 % of its edge length: its raw vertex normals tilt; three
    rounds of neighbour averaging bring them back within a few degrees of the radial direction;
    0 rounds are the raw normals bit for bit; a clean sphere's normals barely move."""
    vs, fs = ico(4)
    edge = np.linalg.norm(vs[fs[:, 0]] - vs[fs[:, 1]], axis=1).mean()
    noisy = vs * (1.0 + np.random.default_rng(1).normal(0.0, 0.3 * edge, (len(vs), 1)))

    def tilt(n):   # degrees off the radial direction, 90th percentile
        return np.percentile(np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", n, vs), -1, 1))), 90)

    raw, smooth = vertex_normals(noisy, fs), smooth_vertex_normals(noisy, fs, 3)
    assert np.array_equal(smooth_vertex_normals(noisy, fs, 0), raw)
    assert tilt(raw) > 15.0 and tilt(smooth) < 0.5 * tilt(raw)
    np.testing.assert_allclose(np.linalg.norm(smooth, axis=1), 1.0, atol=1e-12)
    assert tilt(smooth_vertex_normals(vs, fs, 3)) < 0.5


def test_unreferenced_vertex_gets_zero_normal():
    v, f = ico(1)
    v2 = np.vstack([v, [[5.0, 5.0, 5.0]]])
    n = vertex_normals(v2, f)
    assert np.all(n[-1] == 0) and np.allclose(np.linalg.norm(n[:-1], axis=1), 1)


def test_barycentric_round_trip():
    rng = np.random.default_rng(1)
    v, f = ico(2)
    ids = rng.integers(0, len(f), 200)
    w = rng.dirichlet(np.ones(3), 200)
    p = points_from_barycentric(v, f, ids, w)
    np.testing.assert_allclose(barycentric(p, v, f, ids), w, atol=1e-10)
    # and the other way: a point -> coordinates -> the same point (when in the plane)
    np.testing.assert_allclose(points_from_barycentric(v, f, ids, barycentric(p, v, f, ids)), p, atol=1e-12)


def test_barycentric_projects_off_plane_points_to_their_foot():
    v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    f = np.array([[0, 1, 2]])
    w = barycentric([[0.25, 0.25, 3.0]], v, f, [0])
    np.testing.assert_allclose(w, [[0.5, 0.25, 0.25]])


def test_concatenate_meshes_offsets():
    a, b = ico(0), ico(1)
    v, f, off = concatenate_meshes([a, b])
    assert list(off) == [0, len(a[0]), len(a[0]) + len(b[0])]
    np.testing.assert_array_equal(v[f[len(a[1]):]], b[0][b[1]])


def test_check_mesh_rejects_bad_shapes():
    with pytest.raises(ValueError, match=r"\(n, 3\)"):
        check_mesh(np.zeros((3, 2)), [[0, 1, 2]])
    with pytest.raises(ValueError, match="outside"):
        check_mesh(np.zeros((3, 3)), [[0, 1, 3]])
