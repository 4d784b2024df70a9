"""RayCaster: first hit and all hits on a sphere, embree and pure-Python engines agree."""

import numpy as np
import pytest
import trimesh

from faceforge.geometry.rays import RayCaster, first_hit, has_embree


@pytest.fixture(scope="module")
def sphere():
    m = trimesh.creation.icosphere(3)
    return np.asarray(m.vertices), np.asarray(m.faces, np.int64)


@pytest.mark.parametrize("embree", [False, True])
def test_first_hit_from_outside_and_miss(sphere, embree):
    if embree and not has_embree():
        pytest.skip("embree not installed")
    v, f = sphere
    rc = RayCaster(v, f, use_embree=embree)
    rng = np.random.default_rng(0)
    d = rng.normal(size=(50, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    origins = 3 * d
    face, pts, dist = rc.first_hit(origins, -d)
    assert np.all(face >= 0)
    # the polyhedron lies within the unit sphere, its faces farther than the inradius
    r = np.linalg.norm(pts, axis=1)
    assert np.all(r <= 1 + 1e-6) and np.all(r > 0.98)
    np.testing.assert_allclose(dist, 3 - r, atol=1e-5)
    # each hit lies on the face reported
    n = rc.mesh.face_normals[face]
    np.testing.assert_allclose(np.einsum("ij,ij->i", pts - v[f[face, 0]], n), 0, atol=1e-5)
    # pointing away: miss; max_distance cuts hits
    face2, pts2, dist2 = rc.first_hit(origins, d)
    assert np.all(face2 == -1) and np.all(np.isinf(dist2)) and np.isnan(pts2).all()
    face3, _, _ = rc.first_hit(origins, -d, max_distance=1.5)
    assert np.all(face3 == -1)


def test_all_hits_enter_and_leave(sphere):
    v, f = sphere
    rc = RayCaster(v, f)
    ray, face, pts, dist = rc.all_hits([[0.0, 0.01, -5.0]], [[0.0, 0.0, 1.0]])
    assert len(ray) == 2 and np.all(np.diff(dist) > 0)
    np.testing.assert_allclose(pts[:, 2], [-1, 1], atol=0.02)


def test_one_shot_twin_matches(sphere):
    v, f = sphere
    o, d = np.array([[0.0, 0.0, 4.0]]), np.array([[0.0, 0.0, -1.0]])
    a = RayCaster(v, f).first_hit(o, d)
    b = first_hit(v, f, o, d)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_allclose(a[2], b[2])
