"""Closest points on meshes (geometry.closest.TriangleGrid, SurfaceProjector.closest) against
trimesh's r-tree search, which they replace."""

from pathlib import Path

import numpy as np
import pytest
import trimesh

from faceforge.geometry.closest import TriangleGrid
from faceforge.geometry.surface_points import SurfaceProjector

ROOT = Path(__file__).resolve().parents[2]


def _check(vertices, faces, pts, got, dist, face):
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    want, want_dist, _ = trimesh.proximity.closest_point(mesh, pts)
    scale = float(np.linalg.norm(np.ptp(vertices, axis=0)))
    np.testing.assert_allclose(dist, want_dist, rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(dist, np.linalg.norm(got - pts, axis=1), rtol=0, atol=1e-12 * scale)
    # the triangle reported holds the closest point
    tri = vertices[faces[face]]
    _, on_face, _ = trimesh.proximity.closest_point(trimesh.Trimesh(
        tri.reshape(-1, 3), np.arange(3 * len(face)).reshape(-1, 3), process=False), pts)
    np.testing.assert_allclose(on_face, dist, rtol=0, atol=1e-12 * scale)
    return want


def test_tree_matches_trimesh_on_a_sphere():
    """Points inside, outside and on a sphere."""
    sphere = trimesh.creation.icosphere(3)
    rng = np.random.default_rng(2)
    pts = rng.normal(size=(400, 3)) * rng.uniform(0.2, 1.8, (400, 1))
    pts[:20] = sphere.vertices[:20]                      # on it (at a vertex: ties)
    got, face = TriangleGrid(sphere.triangles).closest(pts)
    want = _check(sphere.vertices, sphere.faces, pts, got, np.linalg.norm(got - pts, axis=1), face)
    np.testing.assert_allclose(got[20:], want[20:], atol=1e-9)


@pytest.mark.parametrize("bone", ["cranium", "mandible"])
def test_projector_matches_trimesh_on_the_template_skull(bone):
    """Real data: the template bones (thin walls, triangles of very different sizes), with
    points from inside the bone to a head's width away."""
    mesh = trimesh.load(ROOT / "templates" / "skull" / f"{bone}.obj", process=False)
    v, f = np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64)
    rng = np.random.default_rng(7)
    scale = float(np.linalg.norm(np.ptp(v, axis=0)))
    base = v[rng.integers(0, len(v), 500)]
    pts = base + rng.normal(size=(500, 3)) * rng.uniform(0.0, 0.3, (500, 1)) * scale
    got, dist, face = SurfaceProjector(v, f).closest(pts)
    assert dist.max() > 0.05 * scale and dist.min() < 1e-3 * scale   # far and near points
    _check(v, f, pts, got, dist, face)


def test_tree_far_points_ties_and_bad_input():
    """Points far outside the grid (the search walks out to the triangles), a single
    triangle, the lowest index among equally near triangles, and non-finite input."""
    sphere = trimesh.creation.icosphere(2)
    tree = TriangleGrid(sphere.triangles)
    rng = np.random.default_rng(5)
    far = rng.normal(size=(50, 3)) * 10.0
    got, face = tree.closest(far)
    _check(sphere.vertices, sphere.faces, far, got, np.linalg.norm(got - far, axis=1), face)
    # at a vertex every triangle around it is at distance 0: the lowest index is reported
    got, face = tree.closest(sphere.vertices)
    for v in range(len(sphere.vertices)):
        assert face[v] == np.flatnonzero((sphere.faces == v).any(axis=1)).min()
    np.testing.assert_array_equal(got, sphere.vertices)
    one = np.array([[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]])
    q, face = TriangleGrid(one).closest(np.array([[0.2, 0.2, 5.0], [-3.0, -3.0, 0.0]]))
    np.testing.assert_allclose(q, [[0.2, 0.2, 0.0], [0.0, 0.0, 0.0]], atol=1e-15)
    assert face.tolist() == [0, 0]
    with pytest.raises(ValueError, match="finite"):
        tree.closest(np.array([[0.0, np.nan, 0.0]]))
    with pytest.raises(ValueError, match="at least one triangle"):
        TriangleGrid(np.zeros((0, 3, 3)))


def test_tree_near_ties_do_not_depend_on_rounding():
    """A point on the mirror plane of mirror-image triangles is equally near both: which one
    is reported must not flip with the last bits of its coordinates (it did, and a skin
    vertex on the MakeHuman head's midline pushed the left or the right side of the skull
    depending on numpy's BLAS kernel, moving the fitted skull by up to 6 %)."""
    right = np.array([[0.1, 0.0, 0.0], [0.5, 0.0, 1.0], [0.5, 1.0, 0.0]])
    left = right * [-1.0, 1.0, 1.0]
    tree = TriangleGrid(np.stack([right, left, right + [0.0, 0.0, 3.0]]))
    for dx in (-1e-13, 0.0, 1e-13):
        q, face = tree.closest(np.array([[dx, 0.3, 0.3]]))
        assert face.tolist() == [0]
        assert q[0, 0] > 0.0   # the lowest index's point, not its mirror
    q, face = tree.closest(np.array([[-1e-3, 0.3, 0.3]]))       # a real difference still wins
    assert face.tolist() == [1]
