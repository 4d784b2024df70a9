"""Cameras, quarter turns, lifting through holes (the z-buffer itself: tests/geometry/test_raster.py),
the mirror plane: no face detector needed."""

from __future__ import annotations

import numpy as np
import pytest

from faceforge.landmarks.lift import lift
from faceforge.landmarks.raster import Render, View, rasterise
from faceforge.landmarks.symmetry import mirror_plane, symmetric
from faceforge.landmarks.views import _unrotate


def _front(size=24, scale=10.0):
    return View(np.array([0.0, 0.0, -1.0]), np.array([0.0, 1.0, 0.0]), np.zeros(3), scale, size)


@pytest.mark.parametrize("quarter", [0, 1, 2, 3])
def test_quarter_turns_map_points_back(quarter):
    size = 16
    img = np.zeros((size, size))
    img[3, 11] = 1.0       # row 3, column 11: centre (11.5, 3.5)
    turned = np.rot90(img, k=quarter)
    r, c = np.argwhere(turned == 1.0)[0]
    assert np.allclose(_unrotate(np.array([[c + 0.5, r + 0.5]]), quarter, size), [[11.5, 3.5]])


def test_a_point_in_a_hole_lands_on_the_rim():
    # a front square (z = 0) with a square hole, and a far wall behind it (z = -5)
    outer = np.array([[-2, -2], [2, -2], [2, 2], [-2, 2]], float)
    inner = np.array([[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]], float)
    v = np.vstack([np.column_stack([outer, np.zeros(4)]), np.column_stack([inner, np.zeros(4)]),
                   [[-3, -3, -5], [3, -3, -5], [3, 3, -5], [-3, 3, -5]]])
    f = []
    for i in range(4):
        j = (i + 1) % 4
        f += [[i, j, 4 + j], [i, 4 + j, 4 + i]]
    f += [[8, 9, 10], [8, 10, 11]]
    f = np.array(f)
    view = View(np.array([0.0, 0, -1]), np.array([0.0, 1, 0]), np.zeros(3), 20.0, 120)
    depth, fid, bary = rasterise(v, f, view)
    r = Render(view, np.zeros((120, 120), np.uint8), depth, fid, bary)
    inside = view.project(np.array([[0.3, 0.0, 0.0]]))[:, :2]       # in the hole, near its right edge
    solid = view.project(np.array([[1.2, 0.4, 0.0]]))[:, :2]
    pts, snapped = lift(r, v, f, np.vstack([inside, solid]), diagonal=10.0, radius_px=30)
    assert snapped.tolist() == [True, False]
    assert abs(pts[0, 2]) < 1e-9 and 0.5 <= pts[0, 0] <= 0.56 and abs(pts[0, 1]) < 0.06   # on the rim, not the wall
    assert np.allclose(pts[1], [1.2, 0.4, 0.0], atol=0.03)


def test_mirror_plane_of_a_symmetric_mesh_and_of_a_lopsided_one():
    rng = np.random.default_rng(1)
    half = rng.uniform(0.1, 1, (200, 3))
    v = np.vstack([half, half * [-1, 1, 1]])
    tilt = np.radians(10)
    rot = np.array([[np.cos(tilt), -np.sin(tilt), 0], [np.sin(tilt), np.cos(tilt), 0], [0, 0, 1]])
    v = v @ rot.T + [0.2, 0, 0]
    diag = float(np.linalg.norm(np.ptp(v, axis=0)))
    left, right = v[:5], v[200:205]            # rough pairs: the start of the search
    plane = mirror_plane(v, left + 0.02, right, diag)
    assert symmetric(plane)
    assert abs(abs(plane.mirror.normal @ (rot @ [1, 0, 0])) - 1) < 1e-9
    assert np.allclose(plane.mirror(v[:200]), v[200:])
    assert np.array_equal(plane.partner[:200], np.arange(200, 400))
    lopsided = v.copy()
    lopsided[200:] += rng.normal(scale=0.05, size=(200, 3))
    assert not symmetric(mirror_plane(lopsided, left, right, diag))


def test_a_piece_on_one_side_only_does_not_tilt_the_mirror_plane():
    """A symmetric mesh plus a small lopsided piece (a lash card on one lid, an earring): the
    plane stays the mesh's own (it tilted when every vertex refined it)."""
    rng = np.random.default_rng(2)
    half = rng.uniform(0.1, 1, (400, 3))
    v = np.vstack([half, half * [-1, 1, 1]])
    card = rng.uniform(0, 0.1, (8, 3)) + [0.5, 0.6, 1.4]   # in front, on the +x side only
    mesh = np.vstack([v, card])
    diag = float(np.linalg.norm(np.ptp(mesh, axis=0)))
    plane = mirror_plane(mesh, v[:5] + 0.01, v[400:405], diag)
    assert abs(abs(plane.mirror.normal[0]) - 1) < 1e-9 and abs(plane.mirror.point @ plane.mirror.normal) < 1e-9
    assert symmetric(plane)


def test_a_required_fdp_that_lands_nowhere_is_named():
    from faceforge.exceptions import LandmarkError
    from faceforge.landmarks.detect import _placeable, fdp_table

    table = fdp_table()
    agreed = np.zeros((478, 3))
    agreed[table["9.3"]] = np.nan          # the nose tip fell off the mesh in every view
    agreed[table["5.1"]] = np.nan          # an optional one is simply left out
    with pytest.raises(LandmarkError, match=r"FDP 9\.3 could not be placed"):
        _placeable(table, agreed, "head.obj")
    agreed[table["9.3"]] = 0.0
    ids = _placeable(table, agreed, "head.obj")
    assert "5.1" not in ids and len(ids) == len(table) - 1


def test_plane_cut_matches_trimesh_and_takes_an_in_plane_edge_once():
    import trimesh

    from faceforge.landmarks.rules import plane_cut

    s = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
    normal = np.array([0.3, 0.9, 0.1]) / np.linalg.norm([0.3, 0.9, 0.1])
    pts, fid = plane_cut(s.vertices, s.faces, np.array([0.05, 0.1, 0.0]), normal)
    segs, fids = trimesh.intersections.mesh_plane(s, normal, [0.05, 0.1, 0.0], return_faces=True)
    order = np.argsort(fid)
    assert np.array_equal(fid[order], np.sort(fids))
    assert np.allclose(pts[order], segs.mean(axis=1)[np.argsort(fids)])
    # two triangles sharing an edge in the plane x = 0: the edge counted once (the negative side's)
    v = np.array([[0.0, 0, 0], [0, 1, 0], [-1, 0.5, 0], [1, 0.5, 0]])
    pts, fid = plane_cut(v, np.array([[0, 1, 2], [0, 3, 1]]), np.zeros(3), np.array([1.0, 0, 0]))
    assert fid.tolist() == [0] and np.allclose(pts, [[0, 0.5, 0]])
