"""fit_clearance: bone that swallowed skin gives way locally, and only locally."""

import numpy as np
import trimesh

from faceforge.anatomy.fit_clearance import BumpField, clearance_fields, swallowed, wendland_c2


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
