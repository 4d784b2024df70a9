"""Skin found inside a rigid bone is put back out (animation.guards.bone_collision)."""

from __future__ import annotations

import numpy as np
import trimesh

from faceforge.animation.checks import points_inside
from faceforge.animation.guards.bone_collision import BoneCollision


def box(centre=(0.0, 0.0, 0.0)):
    b = trimesh.creation.box(extents=(2.0, 2.0, 2.0))
    return np.asarray(b.vertices) + centre, np.asarray(b.faces)


def rigid(angle, shift):
    """(4, 4): rotation by ``angle`` rad about y, then translation ``shift``."""
    c, s = np.cos(angle), np.sin(angle)
    t = np.eye(4)
    t[:3, :3] = [[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]]
    t[:3, 3] = shift
    return t


def test_rest_is_left_alone_and_skin_pushed_in_comes_out_at_its_floor():
    bv, bf = box()
    rest = np.array([[0.0, 0.0, 1.2], [0.3, 0.2, 1.4], [0.0, 0.0, 3.0], [0.0, 0.0, 0.5]])
    col = BoneCollision(rest, {"bone": (bv, bf)}, reach=0.5, keep=0.5)
    ids, _, floor, _ = col.guarded["bone"]
    assert ids.tolist() == [0, 1]                      # near and outside; far, and inside at rest, skipped
    assert np.allclose(floor, [0.1, 0.2])
    x = rest.copy()
    assert col.apply(x, {}) == 0 and np.array_equal(x, rest)
    x = rest + [0.0, 0.0, -0.5]                        # both guarded vertices pushed 0.3 / 0.1 into the top face
    before = x.copy()
    assert col.apply(x, {}) == 2
    assert np.allclose(x[:2], [[0.0, 0.0, 1.1], [0.3, 0.2, 1.2]])   # straight out, to half the rest gap
    assert np.array_equal(x[2:], before[2:])
    assert not points_inside(x[:2], bv, bf).any()


def test_a_moved_bone_is_tested_where_it_is():
    bv, bf = box()
    rest = np.array([[1.3, 0.0, 0.0], [0.0, 1.3, 0.0]])
    col = BoneCollision(rest, {"mandible": (bv, bf)}, reach=0.5, keep=0.5)
    t = rigid(0.3, [0.5, -0.2, 0.1])
    moved_bone = bv @ t[:3, :3].T + t[:3, 3]
    x = rest.copy()                                    # the skin stays; the bone moved into it
    inside = points_inside(x, moved_bone, bf)
    assert inside.any()
    assert col.apply(x, {"mandible": t}) == int(inside.sum())
    assert not points_inside(x, moved_bone, bf).any()
    # the pushed vertex sits keep * d0 = 0.15 from the moved bone
    d = trimesh.proximity.closest_point(trimesh.Trimesh(moved_bone, bf, process=False), x[inside])[1]
    assert np.allclose(d, 0.15)


def test_two_bones_in_one_query_do_not_see_each_other():
    a, fa = box()
    b, fb = box((0.0, -3.0, 0.0))
    rest = np.array([[0.0, 1.2, 0.0], [0.0, -4.2, 0.0]])   # one above the upper box, one below the lower
    col = BoneCollision(rest, {"cranium": (a, fa), "mandible": (b, fb)}, reach=0.5, keep=0.5)
    x = rest + [[0.0, -0.4, 0.0], [0.0, 0.0, 0.0]]         # only the first goes into its bone
    assert col.apply(x, {}) == 1
    assert np.allclose(x, [[0.0, 1.1, 0.0], [0.0, -4.2, 0.0]])


def test_push_direction_does_not_amplify_round_off():
    """Skin just inside a bone is put out along the closest triangle's normal: moving the
    vertex by 1e-12 moves where it lands by no more than that (along ``q - p``, a vertex
    1e-6 inside would move 1e-12 * floor / 1e-6, a million times more)."""
    v, f = box((0.0, 0.0, 0.0))                  # the unit-ish box of the tests above
    rest = np.array([[0.3, 0.2, 1.5]])
    col = BoneCollision(rest, {"cranium": (v, f)}, reach=1.0, keep=0.5)
    x = np.array([[0.3, 0.2, 1.0 - 1e-6]])
    a, b = x.copy(), x + [1e-12, -1e-12, 0.0]
    assert col.apply(a, {}) == col.apply(b, {}) == 1
    assert np.abs(a - b).max() <= 2e-12
    np.testing.assert_allclose(a[0, 2], 1.0 + 0.5 * 0.5, atol=1e-12)   # floor: keep * d0


def test_pushed_out_of_one_bone_into_the_other_comes_out_on_the_next_pass():
    """Two jaws with a thin gap: skin pushed out of the upper one the shortest way (down) lands
    in the lower one; a second pass (the skin step repeats the collision until it finds
    nothing) puts it out of that one (forward, its shortest way), and a third finds nothing."""
    up, fu = box((0.0, 1.03, 0.0))                    # y in [0.03, 2.03]
    low, fl = box((0.0, -1.03, 0.0))                  # y in [-2.03, -0.03]
    rest = np.array([[0.0, 0.0, 1.2]])                # in front of the gap, ~0.2 from both: floors ~0.1
    col = BoneCollision(rest, {"cranium": (up, fu), "mandible": (low, fl)}, reach=0.5, keep=0.5)
    x = np.array([[0.0, 0.05, 0.97]])                 # 0.02 into the upper bone from below
    assert points_inside(x, up, fu).all()
    assert col.apply(x, {}) == 1
    assert not points_inside(x, up, fu).any() and points_inside(x, low, fl).all()
    assert col.apply(x, {}) == 1
    assert not points_inside(x, up, fu).any() and not points_inside(x, low, fl).any()
    assert col.apply(x, {}) == 0


def test_a_repeat_pass_tests_only_what_moved_and_finds_the_same():
    """``only``: after a pass, a repeat need test just the vertices that moved since (the others
    were found outside and the bones have not moved); it moves what a full pass moves."""
    up, fu = box((0.0, 1.03, 0.0))
    low, fl = box((0.0, -1.03, 0.0))
    rest = np.array([[0.0, 0.0, 1.2], [0.5, 0.0, 1.2], [-0.5, 0.0, 1.2]])
    bones = {"cranium": (up, fu), "mandible": (low, fl)}
    x = np.array([[0.0, 0.05, 0.97], [0.5, 0.0, 1.2], [-0.5, 0.05, 0.97]])
    full = BoneCollision(rest, bones, reach=0.5, keep=0.5)
    part = BoneCollision(rest, bones, reach=0.5, keep=0.5)
    a, b = x.copy(), x.copy()
    assert full.apply(a, {}) == part.apply(b, {}) == 2
    assert sorted(part.moved.tolist()) == [0, 2]
    assert full.apply(a, {}) == part.apply(b, {}, part.moved) == 2   # into the other jaw and out
    assert a.tobytes() == b.tobytes()
    b[2] = [-0.5, 0.05, 0.97]                      # moved back in, but not listed: left alone
    assert part.apply(b, {}, np.array([1])) == 0 and len(part.moved) == 0
    assert part.apply(b, {}, np.array([2])) == 1 and part.moved.tolist() == [2]


def test_skin_beyond_reach_that_the_moving_bone_meets_is_guarded_through_its_sweep():
    # a vertex 1.0 in front of the bone (reach 0.5): unguarded at rest; the bone then slides 1.2
    # forward into it (MediaPipe's upper lip and the gliding mandible, fear.fap)
    bv, bf = box()
    rest = np.array([[0.0, 0.0, 2.0]])
    slide = rigid(0.0, [0.0, 0.0, 1.2])
    moved_bone = bv @ slide[:3, :3].T + slide[:3, 3]
    assert points_inside(rest, moved_bone, bf).all()
    plain = BoneCollision(rest, {"mandible": (bv, bf)}, reach=0.5, keep=0.05)
    assert len(plain.guarded["mandible"][0]) == 0
    x = rest.copy()
    assert plain.apply(x, {"mandible": slide}) == 0 and points_inside(x, moved_bone, bf).all()
    sweep = np.stack([rigid(0.0, [0.0, 0.0, s]) for s in (0.4, 0.8, 1.2)])
    swept = BoneCollision(rest, {"mandible": (bv, bf)}, reach=0.5, keep=0.05, sweeps={"mandible": sweep})
    assert swept.guarded["mandible"][0].tolist() == [0]
    assert np.allclose(swept.guarded["mandible"][2], 0.05)          # floor: keep x rest distance
    assert swept.apply(x, {"mandible": slide}) == 1
    assert not points_inside(x, moved_bone, bf).any()


def test_jaw_sweep_spaces_the_opening_by_half_the_reach():
    from faceforge.anatomy.skull import JawAxes, Skull
    from faceforge.animation.rig import JAW_SWEEP_PITCH, jaw_sweep

    bv, bf = box((0.0, -3.0, 4.0))
    axes = JawAxes(pitch_point=np.zeros(3), pitch_dir=np.array([1.0, 0.0, 0.0]), yaw_point=np.zeros(3),
                   yaw_dir=np.array([0.0, 1.0, 0.0]), protrusion_dir=np.array([0.0, 0.0, 1.0]), limits={},
                   condyles=np.zeros((2, 3)), glide=np.array([0.0, -1.0, 2.0]))
    skull = Skull(cranium=(bv, bf), mandible=(bv, bf), landmarks={}, bones={}, jaw=axes)
    t = jaw_sweep(skull, bv, reach=0.5)
    assert t.shape[1:] == (4, 4)
    posed = np.einsum("pij,vj->pvi", t[:, :3, :3], bv) + t[:, None, :3, 3]
    opening = np.concatenate([bv[None], posed[:-2]])   # the last two: the side shifts
    assert np.linalg.norm(np.diff(opening, axis=0), axis=2).max() <= 0.25 + 1e-9
    assert np.allclose(t[-3], skull.jaw_transform(JAW_SWEEP_PITCH, 0.0, 0.0))
