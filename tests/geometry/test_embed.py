"""A dense mesh's vertices carried on a coarser proxy (faceforge.geometry.embed, .decimate)."""

import numpy as np
import pytest

from faceforge.fit.proxy import border_vertices
from faceforge.geometry.decimate import decimate_pieces
from faceforge.geometry.embed import area_vertex_normals, carry, embed_points
from faceforge.geometry.triangles import vertex_components, vertex_normals


def grid(n, size=1.0):
    """A flat n x n vertex grid in z = 0 (triangles), ``size`` wide."""
    x, y = np.meshgrid(np.linspace(0, size, n), np.linspace(0, size, n))
    v = np.stack([x.ravel(), y.ravel(), np.zeros(n * n)], axis=1)
    i = np.arange(n * n).reshape(n, n)
    a, b, c, d = i[:-1, :-1].ravel(), i[:-1, 1:].ravel(), i[1:, :-1].ravel(), i[1:, 1:].ravel()
    return v, np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])


def sphere(subdivisions):
    """A unit icosphere."""
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=subdivisions)
    return np.asarray(m.vertices, float), np.asarray(m.faces, np.int64)


def rigid(seed=3):
    rng = np.random.default_rng(seed)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return q * np.sign(np.linalg.det(q)), rng.normal(size=3)


def test_points_on_a_plane_ride_any_affine_map_of_it_exactly():
    coarse_v, coarse_f = grid(4)
    rng = np.random.default_rng(0)
    points = np.column_stack([rng.uniform(0, 1, (200, 2)), np.zeros(200)])
    e = embed_points(points, coarse_v, coarse_f)
    np.testing.assert_allclose(carry(coarse_v, coarse_f, e), points, atol=1e-12)
    a = np.array([[1.3, 0.2, 0.0], [-0.1, 0.8, 0.4], [0.3, 0.1, 1.1]])
    t = np.array([0.5, -2.0, 1.0])
    np.testing.assert_allclose(carry(coarse_v @ a.T + t, coarse_f, e), points @ a.T + t, atol=1e-12)


def test_a_dense_sphere_rides_its_coarse_copy_exactly_at_rest_and_under_rigid_motion():
    dense_v, _ = sphere(4)
    v, f = sphere(2)
    e = embed_points(dense_v, v, f)
    np.testing.assert_allclose(carry(v, f, e), dense_v, atol=1e-12)
    r, t = rigid()
    frames = np.stack([v, v @ r.T + t])
    out = carry(frames, f, e)
    np.testing.assert_allclose(out[1], dense_v @ r.T + t, atol=1e-12)
    # the foot slides along the interpolated normal: what is left over is small next to the offset
    assert np.abs(e.residual).max() < 0.2 * np.abs(e.offset).max()


def test_vertex_normals_of_a_stack_of_frames_are_the_area_weighted_ones():
    v, f = sphere(1)
    r, t = rigid(5)
    stack = np.stack([v, v @ r.T + t])
    n = area_vertex_normals(stack, f)
    np.testing.assert_allclose(n[0], vertex_normals(v, f), atol=1e-12)
    np.testing.assert_allclose(n[1], vertex_normals(stack[1], f), atol=1e-12)


def test_a_point_stays_on_its_own_piece():
    a_v, a_f = grid(6)
    b_v = a_v + [0.0, 0.0, 0.05]   # a second sheet 0.05 above: nearer to some points than their own
    v = np.concatenate([a_v, b_v])
    f = np.concatenate([a_f, a_f + len(a_v)])
    pieces = vertex_components(len(v), f)
    points = np.array([[0.5, 0.5, 0.04]])
    e = embed_points(points, v, f, point_piece=[pieces[0]], face_piece=pieces[f[:, 0]])
    assert e.face[0] < len(a_f)   # on sheet a, 0.04 below the point, not sheet b 0.01 above it
    np.testing.assert_allclose(carry(v, f, e), points, atol=1e-12)


def test_a_piece_with_no_more_triangles_than_its_share_is_kept_whole():
    # a tetrahedron over keep_below with a budget of 8 triangles: the library refused the target
    # ("target_count must be less than the number of faces") and the fit ended in a traceback
    pytest.importorskip("fast_simplification")
    v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    f = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    pv, pf, piece, merged = decimate_pieces(v, f, 2, keep_below=1)
    np.testing.assert_array_equal(pv, v)
    np.testing.assert_array_equal(pf, f)
    np.testing.assert_array_equal(merged, np.arange(4))


def test_the_decimator_keeps_pieces_apart_and_open_borders_whole():
    pytest.importorskip("fast_simplification")
    big_v, big_f = grid(40)
    big_v[:, 2] = 0.1 * np.sin(3 * big_v[:, 0]) * np.cos(2 * big_v[:, 1])
    small_v, small_f = sphere(1)
    small_v = 0.05 * small_v + [0.5, 0.5, 1.0]
    v = np.concatenate([big_v, small_v])
    f = np.concatenate([big_f, small_f + len(big_v)])
    pv, pf, piece, merged = decimate_pieces(v, f, 600, keep_below=100)
    assert 400 < len(pv) < 800
    assert set(np.unique(piece)) == {0, 1}
    # the small piece (42 vertices) is copied whole; the two pieces share no triangle
    np.testing.assert_array_equal(pv[piece == 1], small_v)
    assert np.all(piece[pf[:, 0]] == piece[pf[:, 1]]) and np.all(piece[pf[:, 1]] == piece[pf[:, 2]])
    # every border vertex of the grid is still there, at its place
    border = big_v[border_vertices(big_f)]
    kept = pv[piece == 0]
    gap = np.min(np.linalg.norm(border[:, None] - kept[None], axis=2), axis=1)
    assert gap.max() < 1e-6   # (the replay rounds through float32)
    assert len(border_vertices(pf)) == len(border)
    # each input vertex was merged into a proxy vertex of its own piece; the small piece's into itself
    assert np.all(piece[merged] == np.r_[np.zeros(len(big_v), int), np.ones(len(small_v), int)])
    np.testing.assert_array_equal(pv[merged[len(big_v):]], small_v)


def test_a_lip_vertex_rides_its_own_lip_where_the_other_touches_it():
    # two sheets, the lower one's top row under the upper one's bottom row, 1e-3 apart (touching
    # lips); the point on the lower sheet is nearer to the upper one's triangles in space
    from faceforge.geometry.embed import ring_choice

    up_v, up_f = grid(4)
    low_v = up_v.copy()
    low_v[:, 1] -= 1.0 - 1e-3
    low_v[:, 2] = 0.0
    v = np.concatenate([up_v, low_v])
    f = np.concatenate([up_f, up_f + len(up_v)])
    point = low_v[np.argmax(low_v[:, 1])][None] + [0.1, 2e-3, 0.0]   # just above the lower lip's top row
    mine = len(up_v) + int(np.argmax(low_v[:, 1]))
    nearest = embed_points(point, v, f).face[0]
    assert nearest < len(up_f)   # the nearest triangle in space: the upper lip's
    ring = ring_choice(point, v, f, [mine])[0]
    assert ring >= len(up_f)    # the collapse's vertex: the lower lip's
    e = embed_points(point, v, f, point_vertex=[mine])
    assert e.face[0] >= len(up_f)
    np.testing.assert_allclose(carry(v, f, e), point, atol=1e-12)


def test_the_compiled_carry_is_its_numpy_twin():
    from faceforge.geometry.embed import carry_plain

    dense_v, _ = sphere(3)
    v, f = sphere(1)
    e = embed_points(dense_v * 1.02, v, f)
    rng = np.random.default_rng(1)
    frames = v[None] + 0.05 * rng.normal(size=(3,) + v.shape)
    np.testing.assert_allclose(carry(frames, f, e), carry_plain(frames, f, e), atol=1e-12)
    np.testing.assert_allclose(carry(frames[0], f, e), carry_plain(frames[0], f, e), atol=1e-12)


def test_points_on_a_triangle_bind_removed_ride_a_kept_one_around_their_vertex():
    from faceforge.geometry.embed import embed_off

    v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [0.5, 2, 0]])
    f = np.array([[0, 1, 2], [1, 3, 2], [2, 3, 4]])
    points = np.array([[0.7, 0.6, 0.0], [0.2, 0.2, 0.0]])
    e = embed_points(points, v, f)
    assert e.face[0] == 1 and e.face[1] == 0
    out = embed_off(e, v, f, [1], anchor=[3, 0])   # triangle 1 removed (a bridge): point 0 around vertex 3
    assert out.face[0] == 2 and out.face[1] == 0
    np.testing.assert_allclose(carry(v, f, out), points, atol=1e-12)
    assert embed_off(e, v, f, [], anchor=[3, 0]) is e


def test_locked_vertices_survive_the_decimation_in_place():
    pytest.importorskip("fast_simplification")
    v, f = grid(30)
    v[:, 2] = 0.05 * np.sin(4 * v[:, 0])
    locked = np.zeros(len(v), bool)
    locked[np.flatnonzero(np.isclose(v[:, 1], v[15 * 30, 1]))] = True   # one interior row: a lip line
    pv, pf, piece, merged = decimate_pieces(v, f, 300, keep_below=10, keep_borders=False, locked=locked)
    assert len(pv) < 450
    np.testing.assert_allclose(pv[merged[locked]], v[locked], atol=1e-6)
    assert len(np.unique(merged[locked])) == locked.sum()   # none merged into another
    assert not np.isin(np.arange(len(pv)), pf).sum() < len(pv)   # no loose flag vertex left


def test_a_point_of_one_side_leaves_a_triangle_with_a_corner_on_the_other():
    from faceforge.geometry.embed import embed_apart

    # a strip of rows y = 1, 0 (side +1: the upper lip) and y = -1, -2 (side -1: the lower lip)
    x = np.arange(4.0)
    v = np.array([[a, b, 0.0] for b in (1.0, 0.0, -1.0, -2.0) for a in x])
    i = np.arange(16).reshape(4, 4)
    a, b, c, d = i[:-1, :-1].ravel(), i[:-1, 1:].ravel(), i[1:, :-1].ravel(), i[1:, 1:].ravel()
    f = np.concatenate([np.stack([a, d, b], 1), np.stack([a, c, d], 1)])
    side = np.repeat([1, 1, -1, -1], 4)
    points = np.array([[1.5, -0.2, 0.01], [1.5, -0.8, 0.0], [1.5, 0.5, 0.0]])
    point_side = np.array([1, -1, 1])
    e = embed_points(points, v, f)
    assert (side[f[e.face[:2]]] == 1).any(axis=1).all() and (side[f[e.face[:2]]] == -1).any(axis=1).all()
    out, moved = embed_apart(e, points, v, f, point_side, side)
    assert moved == 2
    assert not (side[f[out.face]] == -point_side[:, None]).any()
    np.testing.assert_allclose(carry(v, f, out), points, atol=1e-12)
    parted = v + np.where(side[:, None] < 0, [0.0, -1.0, 0.0], 0.0)   # the lower lip drops 1
    np.testing.assert_allclose(carry(parted, f, out)[[0, 2]], points[[0, 2]], atol=1e-12)   # the upper's stay
    np.testing.assert_allclose(carry(parted, f, out)[1], points[1] + [0, -1, 0], atol=1e-12)
    assert abs(carry(parted, f, e)[0, 1] - points[0, 1]) > 0.1   # without: dragged half down
    assert embed_apart(out, points, v, f, point_side, side) == (out, 0)
