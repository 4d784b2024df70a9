"""fit_clearance: bone that swallowed skin gives way locally, and only locally."""

import numpy as np
import trimesh

from faceforge.fit.clearance import BumpField, clearance_fields, swallowed, wendland_c2


def test_wendland_is_one_at_the_centre_zero_at_the_radius_and_monotone():
    r = np.linspace(0.0, 1.2, 121)
    phi = wendland_c2(r)
    assert phi[0] == 1.0 and np.all(phi[r >= 1.0] == 0.0)
    assert np.all(np.diff(phi) <= 0.0)


def test_a_single_bump_moves_its_centre_by_delta_and_nothing_beyond_the_radius():
    centre, delta = np.array([[0.0, 0.0, 0.0]]), np.array([[0.0, 0.0, -0.3]])
    field = BumpField(centre, delta, radius=1.0)
    pts = np.array([[0.0, 0.0, 0.0], [0.5, 0.0, 0.0], [1.0, 0.0, 0.0], [3.0, 2.0, 1.0]])
    out = field(pts)
    assert np.allclose(out[0], centre[0] + delta[0])
    assert 0.0 < -(out[1, 2]) < 0.3                       # partial inside the radius
    assert np.array_equal(out[2:], pts[2:])               # untouched at and beyond it


def test_overlapping_bumps_never_exceed_the_largest_push():
    centres = np.array([[0.0, 0.0, 0.0], [0.05, 0.0, 0.0], [0.1, 0.0, 0.0]])
    deltas = np.tile([[0.0, 0.0, -0.2]], (3, 1))
    out = BumpField(centres, deltas, radius=1.0)(np.array([[0.05, 0.0, 0.0]]))
    assert -out[0, 2] <= 0.2 + 1e-12


def test_swallowed_skin_ends_outside_and_far_bone_stays():
    bone = trimesh.creation.icosphere(subdivisions=4, radius=1.0)
    skin = np.array([[0.0, 0.0, 0.95], [0.02, 0.0, 0.96], [0.0, 0.0, 1.5]])  # two inside, one outside
    assert swallowed([(bone.vertices, bone.faces)], skin).tolist() == [True, True, False]
    fields = clearance_fields([(bone.vertices, bone.faces)], skin, clearance=0.01, radius=0.3)
    v = bone.vertices
    for g in fields:
        v = g(v)
    assert not swallowed([(v, bone.faces)], skin).any()
    moved = trimesh.Trimesh(v, bone.faces, process=False)
    _, dist, _ = trimesh.proximity.closest_point(moved, skin[:2])
    assert np.all(dist > 1e-3)     # clearly outside (overlapping bumps average their pushes)
    far = bone.vertices[:, 2] < 0.5
    assert np.array_equal(v[far], bone.vertices[far])     # the back of the bone does not move


def test_a_face_larger_than_the_radius_still_gives_way():
    """The bone moves by its vertices: a swallowed point in the middle of a face whose corners
    all lie beyond the bump radius is cleared all the same (MakeHuman's cheek, 18 mm faces)."""
    bone = trimesh.creation.box(extents=(4.0, 4.0, 4.0))        # 12 faces, corners 2.8 from a face centre
    skin = np.array([[0.3, 0.2, 1.97]])                         # 0.03 beneath the top face
    fields = clearance_fields([(bone.vertices, bone.faces)], skin, clearance=0.05, radius=0.5)
    v = bone.vertices
    for g in fields:
        v = g(v)
    assert not swallowed([(v, bone.faces)], skin).any()
    # the corners of the closest triangle went 0.03 + 0.05 down, the rest stayed
    moved = np.linalg.norm(v - bone.vertices, axis=1) > 0
    assert moved.sum() == 3 and np.allclose(v[moved, 2], 2.0 - 0.08)


def test_skin_on_the_seam_of_two_touching_bones_ends_outside_both():
    """Two bones meeting face to face (upper and lower molars in occlusion): skin on the seam
    is pushed out through their common outer surface, not from one bone into the other."""
    upper = trimesh.creation.box(extents=(2.0, 2.0, 1.0))
    upper.apply_translation([0.0, 0.0, 0.5])
    lower = trimesh.creation.box(extents=(2.0, 2.0, 1.0))
    lower.apply_translation([0.0, 0.0, -0.5])
    skin = np.array([[0.97, 0.1, 0.005], [0.97, -0.1, -0.005]])     # near the side wall, on the seam
    bones = [(upper.vertices, upper.faces), (lower.vertices, lower.faces)]
    assert swallowed(bones, skin).all()
    fields = clearance_fields(bones, skin, clearance=0.02, radius=1.0)
    for g in fields:
        bones = [(g(v), f) for v, f in bones]
    assert not swallowed(bones, skin).any()
    assert len(fields) <= 2


def test_a_symmetric_field_keeps_a_symmetric_bone_symmetric_and_clears_midline_skin():
    """With the head's mirror plane, each field carries its bumps' mirror images (pushes of
    midline skin turned into the plane): skin off the plane, and its mirror image, and skin on
    it all end outside, and the bone stays its own mirror image. Without the plane, the skin
    point off the plane pushes one side only."""
    from faceforge.geometry.mirror import Mirror

    mirror = Mirror((0.0, 0.0, 0.0), (1.0, 0.0, 0.0))
    bone = trimesh.creation.icosphere(subdivisions=4, radius=1.0)
    v0 = np.asarray(bone.vertices)
    skin = np.array([[0.3, 0.2, 0.9], [-0.3, 0.2, 0.9], [0.0, -0.3, 0.93]])
    partner, dist = mirror.partners(v0)
    assert dist.max() < 1e-9                               # the icosphere is its own mirror image
    for plane, symmetric in ((mirror, True), (None, False)):
        v = v0
        for g in clearance_fields([(v0, bone.faces)], skin[:1] if plane is None else skin, 0.01, 0.3,
                                  mirror=plane):
            v = g(v)
        off = np.abs(mirror(v)[partner] - v).max()
        assert (off < 1e-9) == symmetric, off
        if symmetric:
            assert not swallowed([(v, bone.faces)], skin).any()
