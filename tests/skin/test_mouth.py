"""The lip cut on small synthetic faces: shared ring, bridged, open."""

import numpy as np

from faceforge.skin.mouth import cut_mouth, lip_side
from faceforge.skin.layer import skin_topology
from tests.skin.synthetic import mouth_grid


def _boundary(faces):
    return {tuple(e) for e in skin_topology(faces).boundary_edges.tolist()}


def _lip_fdps_of(cut):
    """FDP -> vertex of a cut mesh: upper FDPs on the upper contour, lower on the lower."""
    u, lo = cut.upper, cut.lower
    k = len(u) // 2
    return {"2.4": u[0], "2.5": u[-1], "2.2": u[k], "2.3": lo[k],
            "2.6": u[k // 2], "2.8": lo[k // 2], "2.7": u[(k + len(u)) // 2],
            "2.9": lo[(k + len(u)) // 2]}


def test_shared_ring_is_cut_and_user_vertices_keep_their_order():
    v, f, lips = mouth_grid(8)
    cut = cut_mouth(v, f, lips)
    assert cut.case == "shared_ring"
    n = len(v)
    assert cut.n_user == n
    np.testing.assert_array_equal(cut.vertices[:n], v)  # order and positions preserved
    np.testing.assert_array_equal(cut.vertices[n:], v[cut.source])  # copies coincide
    # the ring interior (corners excluded) is duplicated: 8-grid, corners at columns 1 and 7
    assert len(cut.source) == 5
    assert len(cut.faces) == len(f)
    # the cut creates a boundary along the lip line: both sides of every ring edge
    new_boundary = _boundary(cut.faces) - _boundary(f)
    ring = list(zip(cut.upper[:-1], cut.upper[1:]))
    low = list(zip(cut.lower[:-1], cut.lower[1:]))
    expected = {tuple(sorted(map(int, e))) for e in ring + low}
    assert new_boundary == expected
    # every rewired face lies below the lip line
    rewired = np.flatnonzero((cut.faces != f).any(axis=1))
    assert len(rewired) and np.all(v[f[rewired]].mean(axis=1)[:, 1] < 0.5)
    assert cut.to_user(cut.vertices).shape == v.shape


def test_cutting_twice_finds_the_mouth_open():
    v, f, lips = mouth_grid(8)
    cut = cut_mouth(v, f, lips)
    again = cut_mouth(cut.vertices, cut.faces, _lip_fdps_of(cut))
    assert again.case == "open"
    np.testing.assert_array_equal(again.faces, cut.faces)


def test_bridging_triangles_are_deleted_and_nothing_else():
    v, f, lips = mouth_grid(8)
    cut = cut_mouth(v, f, lips)
    verts = cut.vertices.copy()
    verts[cut.upper[1:-1], 1] += 0.02  # part the lips geometrically
    bridge = []
    for (a, b), (c, d) in zip(zip(cut.upper[:-1], cut.upper[1:]), zip(cut.lower[:-1], cut.lower[1:])):
        if a != c:
            bridge.append([a, c, b] if b == d else [a, c, d])
        if b != d:
            bridge.append([a, d, b])
    faces = np.concatenate([cut.faces, np.asarray(bridge)])
    out = cut_mouth(verts, faces, _lip_fdps_of(cut))
    assert out.case == "bridged"
    np.testing.assert_array_equal(np.sort(out.removed_faces), np.arange(len(cut.faces), len(faces)))
    np.testing.assert_array_equal(out.faces, cut.faces)
    np.testing.assert_array_equal(out.vertices, verts)


def test_missing_lip_landmarks_leave_the_mesh_alone():
    v, f, lips = mouth_grid(6)
    out = cut_mouth(v, f, {"2.2": lips["2.2"]})
    assert out.case == "no_landmarks"
    np.testing.assert_array_equal(out.faces, f)
    assert out.report()["case"] == "no_landmarks"


def test_lip_side_splits_upper_and_lower():
    v, f, lips = mouth_grid(8)
    cut = cut_mouth(v, f, lips)
    side = lip_side(cut)
    assert np.all(side[cut.upper[1:-1]] == 1)
    assert np.all(side[cut.lower[1:-1]] == -1)
    y = cut.vertices[:, 1]
    assert np.all(side[(side != 0) & (y > 0.5 + 1e-9)] == 1)
    assert np.all(side[(side != 0) & (y < 0.5 - 1e-9)] == -1)


def test_lip_side_follows_the_surface_where_the_lips_roll_in():
    """Lower-lip skin lifted above the lip line (a lip rolling inward at the corners, ICT)
    is still lower lip: only a path around a corner joins it to the upper contour. Skin
    beside the mouth, which reaches both contours only around a corner, keeps the height
    rule."""
    v, f, lips = mouth_grid(8)
    cut = cut_mouth(v, f, lips)
    before = lip_side(cut)
    verts = cut.vertices.copy()
    below = np.flatnonzero(np.isclose(verts[:, 1], 0.5 - 1 / 8) & (verts[:, 0] > 0.2) & (verts[:, 0] < 0.8))
    verts[below, 1] = 0.5 + 0.3 / 8            # the row under the lower contour, now above the line
    rolled = cut.__class__(**{**cut.__dict__, "vertices": verts})
    side = lip_side(rolled)
    assert np.all(before[below] == -1)
    assert np.all(side[below] == -1), side[below]
    # beside the mouth (left of corner 2.5, right of corner 2.4) nothing changed
    beside = (verts[:, 0] < 1 / 8 - 1e-9) | (verts[:, 0] > 7 / 8 + 1e-9)
    np.testing.assert_array_equal(side[beside], before[beside])
    # and the old rule alone would have called the lifted skin upper lip
    from faceforge.skin.mouth import side_of_points

    assert np.all(side_of_points(verts[below], rolled) == 1)


def test_muscle_lip_side_tells_the_sphincter_from_the_lips_own_muscles():
    """A ring around the mouth is AROUND_MOUTH even when most of it lies above the line
    (ICT); a sheet below whose end crosses into the upper lip is a lower-lip muscle; one
    above is upper; one far away is neither."""
    from faceforge.skin.mouth import AROUND_MOUTH, muscle_lip_side

    v, f, lips = mouth_grid(8)
    cut = cut_mouth(v, f, lips)                          # lip line y = 0.5, mouth 1/8 .. 7/8
    t = np.linspace(0, 2 * np.pi, 80, endpoint=False)
    ring = np.c_[0.5 + 0.35 * np.cos(t), 0.52 + 0.25 * np.clip(np.sin(t), 0, None)
                 + 0.1 * np.clip(np.sin(t), None, 0), 0 * t]    # its lower half thin, as on ICT
    assert ring[:, 1].mean() > 0.5 and muscle_lip_side(ring, cut) == AROUND_MOUTH   # on average above
    xs, ys = np.meshgrid(np.linspace(0.2, 0.4, 4), np.linspace(0.1, 0.55, 10))
    dep = np.c_[xs.ravel(), ys.ravel(), 0 * xs.ravel()]
    assert (dep[:, 1] > 0.5).any() and muscle_lip_side(dep, cut) == -1
    lev = dep * [1, -1, 1] + [0, 1.05, 0]                # mirrored above the line
    assert muscle_lip_side(lev, cut) == 1
    assert muscle_lip_side(lev + [0, 5.0, 0], cut) == 0


def _ring(h, w, centre, radii, lift):
    """A closed two-sheet muscle ring laid out as hexmesh's (rows around the mouth starting at
    the right corner, counter-clockwise; column 0 inner, w - 1 outer), its lower arc lifted by
    ``lift`` towards the centre line (most of it above the lip line, as ICT's sphincter)."""
    from faceforge.anatomy.muscles.hexmesh import hex_topology

    topo = hex_topology(h, w, closed=True)
    t = 2 * np.pi * np.arange(h) / h
    r = np.linspace(radii[0], radii[1], w)
    x = centre[0] + np.cos(t)[:, None] * r
    y = centre[1] + np.sin(t)[:, None] * r * np.where(np.sin(t) < 0, lift, 1.0)[:, None]
    bottom = np.stack([x, y, np.zeros_like(x)], -1).reshape(-1, 3)
    return np.concatenate([bottom, bottom + [0, 0, 0.02]]), topo.faces


def test_grid_layout_finds_the_muscle_grids_and_nothing_else():
    from faceforge.anatomy.muscles.hexmesh import _faces, grid_layout, hex_topology

    for h, w, closed in ((20, 2, True), (7, 3, True), (5, 4, False), (12, 6, False)):
        assert grid_layout(2 * h * w, hex_topology(h, w, closed).faces, closed) == (h, w)
    flip = np.zeros(2 * 20 - 20, bool)
    flip[::3] = True                                   # cells split along the other diagonal
    assert grid_layout(80, _faces(20, 2, True, flip), True) == (20, 2)
    import trimesh

    ico = trimesh.creation.icosphere(2)                # not a muscle grid
    assert grid_layout(len(ico.vertices), ico.faces) is None
    assert grid_layout(80, hex_topology(20, 2, True).faces[::-1][:-2], True) is None


def test_ring_face_sides_follow_the_rows_not_the_lip_line():
    """A sphincter fitted above the lip line (its lower arc mostly above it too): the faces
    of its lower arc still belong to the lower lip, those of the upper arc to the upper one,
    whichever side of the line they lie on."""
    from faceforge.skin.mouth import MouthCut, ring_face_sides, side_of_points

    v, f, lips = mouth_grid(8)
    cut = cut_mouth(v, f, lips)                          # lip line y = 0.5, corners x = 1/8, 7/8
    h, w = 20, 2
    ring, rf = _ring(h, w, (0.5, 0.5 + 0.02), (0.25, 0.375), lift=0.05)
    sides = ring_face_sides(ring, rf, cut)
    row = (rf % (h * w)) // w                          # rows 0 and h/2 lie at the corners
    top_arc = (row <= h // 2).all(axis=1) & ((row > 0) & (row < h // 2)).any(axis=1)
    bottom_arc = ((row == 0) | (row >= h // 2)).all(axis=1) & (row > h // 2).any(axis=1)
    assert np.all(sides[top_arc] == 1) and np.all(sides[bottom_arc] == -1)
    assert np.count_nonzero(sides == 1) == np.count_nonzero(sides == -1) == len(rf) // 2
    geometric = side_of_points(ring[rf].mean(axis=1), cut)
    assert np.count_nonzero((sides == -1) & (geometric == 1)) > len(rf) // 4   # the old rule's upper
    # the same ring upside down in its numbering: the arcs are found by height, not by index
    flipped = ring.copy()
    flipped[:, 1] = 1.0 - flipped[:, 1]
    assert np.array_equal(ring_face_sides(flipped, rf, cut), -sides)
    # not a muscle grid, or no corners: no labels (the caller keeps the lip-line rule)
    assert ring_face_sides(ring, rf[:-2], cut) is None
    no_corners = MouthCut(cut.case, cut.vertices, cut.faces, cut.n_user, cut.source,
                          cut.removed_faces, cut.upper[:1], cut.lower)
    assert ring_face_sides(ring, rf, no_corners) is None
