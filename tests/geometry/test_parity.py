"""Ray parity on a grid (faceforge.geometry.parity): exact on edges and vertices, equal to
trimesh's containment elsewhere."""

import numpy as np
import pytest
import trimesh

from faceforge.geometry.parity import ParityGrid


def points_inside_mesh(points, vertices, faces):
    return ParityGrid(vertices, faces).contains(points)


def _box(lo=0.0, hi=1.0, divisions=1):
    """An axis-aligned cube [lo, hi]^3, each face split into divisions^2 squares of two
    triangles: every (y, z) at a multiple of the step lies on a projected edge or vertex."""
    m = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    if divisions > 1:
        m = m.subdivide_to_size(1.0 / divisions, max_iter=10)
    v = (m.vertices + 0.5) * (hi - lo) + lo
    return v, m.faces


def test_rays_through_shared_edges_and_vertices_count_once():
    for div in (1, 2, 4):
        v, f = _box(divisions=div)
        step = 1.0 / (4 * div)
        g = np.arange(-step, 1.0 + 1.5 * step, step)      # on edges, vertices and diagonals
        y, z = np.meshgrid(g, g, indexing="ij")
        yz = np.column_stack([y.ravel(), z.ravel()])
        on_side = np.any(np.isclose(yz, 0.0) | np.isclose(yz, 1.0), axis=1)
        for x in (-0.5, 0.25, 0.5, 1.5):
            pts = np.column_stack([np.full(len(yz), x), yz])
            if 0.0 < x < 1.0:             # (y, z) on a side face: the point is on the surface
                pts = pts[~on_side]
            expect = (0.0 < x < 1.0) & np.all((pts[:, 1:] > 0) & (pts[:, 1:] < 1), axis=1)
            got = points_inside_mesh(pts, v, f)
            assert np.array_equal(got, expect), (div, x, np.flatnonzero(got != expect)[:5])


def test_orientation_and_winding_do_not_matter():
    v, f = _box(divisions=2)
    rng = np.random.default_rng(1)
    pts = rng.uniform(-0.2, 1.2, (2000, 3))
    ref = points_inside_mesh(pts, v, f)
    assert np.array_equal(points_inside_mesh(pts, v, f[:, ::-1]), ref)          # flipped normals
    assert np.array_equal(points_inside_mesh(pts, v, f[rng.permutation(len(f))]), ref)
    expect = np.all((pts > 0) & (pts < 1), axis=1)
    assert np.array_equal(ref, expect)


@pytest.mark.parametrize("shape", ["sphere", "torus", "capsule_union"])
def test_matches_trimesh_contains_on_curved_and_nonconvex_meshes(shape):
    if shape == "sphere":
        m = trimesh.creation.icosphere(subdivisions=3)
    elif shape == "torus":
        m = trimesh.creation.torus(major_radius=1.0, minor_radius=0.35, major_sections=48, minor_sections=24)
    else:
        a = trimesh.creation.capsule(height=1.5, radius=0.3, count=[16, 16])
        b = a.copy()
        b.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))
        b.apply_translation([0.9, 0.0, 0.0])
        m = trimesh.util.concatenate([a, b])          # two disjoint closed pieces, one mesh
    assert m.is_watertight
    rng = np.random.default_rng(7)
    lo, hi = m.bounds
    pts = rng.uniform(lo - 0.1, hi + 0.1, (5000, 3))
    got = ParityGrid(m.vertices, m.faces).contains(pts)
    ref = m.contains(pts)
    assert 0 < got.sum() < len(pts)
    assert np.array_equal(got, ref)
    # a hair off the surface, at every vertex (rays through vertices and edges): the side it is on
    eps = 1e-7 * float(np.ptp(m.vertices, axis=0).max())
    grid = ParityGrid(m.vertices, m.faces)
    assert grid.contains(m.vertices - eps * m.vertex_normals).all()
    assert not grid.contains(m.vertices + eps * m.vertex_normals).any()


def test_empty_inputs():
    v, f = _box()
    assert ParityGrid(v, f).contains(np.zeros((0, 3))).shape == (0,)
    assert not ParityGrid(v, f[:0]).contains(np.array([[0.5, 0.5, 0.5]])).any()
