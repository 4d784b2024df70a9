"""The ala on the levator labii alaeque nasi (faceforge.skin.ala, bind.ala_mm; docs/notes/nose21.md)."""

import numpy as np

from faceforge.skin.ala import ala_binding, ala_mask, stretched_closest
from faceforge.skin.binding import Binding, Body
from faceforge.skin.casting import CRANIUM, MUSCLE
from tests.skin.test_cheek import one_anchor_binding

# a face looking along +z, y up, eyes 63 units apart (1 unit = 1 mm): the alar bases 12 mm to each
# side of the midline at 1 mm up, the alar creases 18 mm to each side at 8 mm up
LANDMARKS = {"9.4": (-12.0, 1.0, -4.0), "9.5": (12.0, 1.0, -4.0), "9.2": (-18.0, 8.0, -6.0),
             "9.1": (18.0, 8.0, -6.0), "3.5": (31.5, 40.0, -10.0), "3.6": (-31.5, 40.0, -10.0)}


def test_the_mask_is_the_ala_from_its_base_to_its_crease():
    pts = np.array([[12.0, 1.0, -4.0],     # the left alar base -> in
                    [15.0, 4.5, -1.0],     # on the ala between base and crease, 3 mm out -> in
                    [-18.0, 12.0, -6.0],   # 4 mm above the right crease -> in
                    [0.0, 0.0, 0.0],       # the nose base at the midline -> out
                    [24.0, 8.0, -6.0],     # 6 mm beside the crease (the cheek) -> out
                    [12.0, 1.0, 3.0]])     # 7 mm in front of the alar base -> out
    assert ala_mask(pts, LANDMARKS, 5.0).tolist() == [True, True, True, False, False, False]
    assert ala_mask(pts, LANDMARKS, 8.0)[5]          # the reach in mm
    assert not ala_mask(pts, LANDMARKS, 0.0).any()   # off
    for k in ("9.1", "9.2", "9.4", "9.5", "3.5"):    # each of the four FDPs, and ES0, is needed
        assert not ala_mask(pts, {j: p for j, p in LANDMARKS.items() if j != k}).any()


def _strip():
    """A muscle 4 mm wide in x (10-14), from y -10 to 20, in the plane z = -10, sloping back below
    y 0 (its lowest row 6 mm deeper): two quads."""
    v = np.array([[10.0, -10.0, -16.0], [14.0, -10.0, -16.0], [14.0, 0.0, -10.0], [10.0, 0.0, -10.0],
                  [14.0, 20.0, -10.0], [10.0, 20.0, -10.0]])
    return v, np.array([[0, 1, 2], [0, 2, 3], [3, 2, 4], [3, 4, 5]])


def test_the_stretched_metric_takes_the_point_at_the_skins_own_height():
    v, f = _strip()
    p = np.array([[12.0, -4.0, 0.0]])   # in front of the sloping part, 4 mm below its knee
    _, _, plain, _ = stretched_closest(p, v, f, stretch=1.0)
    tri, bary, level, d = stretched_closest(p, v, f, stretch=10.0)
    assert plain[0, 1] > -1.0            # the plain closest point: up at the knee, the nearer plane
    np.testing.assert_allclose(level[0, :2], [12.0, -4.0], atol=0.1)   # stretched: at about the point's height
    np.testing.assert_allclose(bary[0] @ v[f[tri[0]]], level[0])


def test_ala_skin_on_bone_moves_to_the_levator_at_its_height():
    v_m, f_m = _strip()
    bodies = [Body("levator_labii_inner_L", "muscle", v_m, f_m),
              Body("cranium", "cranium", np.array([[-100.0, -100.0, -30.0], [100.0, -100.0, -30.0],
                                                   [0.0, 100.0, -30.0]]), np.array([[0, 1, 2]]))]
    v = np.array([[12.0, -4.0, 0.0], [12.0, 5.0, 0.0], [12.0, 5.0, 1.0], [-12.0, 5.0, 0.0]])
    status = np.array([CRANIUM, MUSCLE, CRANIUM, CRANIUM], np.int8)
    body = np.array([1, 0, 1, 1])
    pts = v * [1.0, 1.0, 0.0] + [0.0, 0.0, -30.0]
    binding = one_anchor_binding(bodies, status, body, pts)
    mask = np.array([True, True, False, True])
    out, moved = ala_binding(binding, v, bodies, [0], mask, 200.0)
    # on the bone and in the ala: to the levator, at its own height; on a muscle or outside the mask: unchanged
    assert moved == 2
    assert out.body.tolist() == [0, 0, 1, 0]
    assert out.status.tolist() == [MUSCLE, MUSCLE, CRANIUM, MUSCLE]
    np.testing.assert_allclose(out.points[0, :2], [12.0, -4.0], atol=0.1)
    np.testing.assert_allclose(out.distance[0], np.linalg.norm(v[0] - out.points[0]))
    np.testing.assert_allclose(out.bary[0] @ v_m[f_m[out.face_ids[0]]], out.points[0])
    assert binding.body.tolist() == [1, 0, 1, 1]   # the input is not changed
    same, none = ala_binding(binding, v, bodies, [0], mask, 1.0)   # nothing in reach
    assert none == 0 and same is binding


def test_the_ala_binds_beside_itself_not_under_the_nostril():
    """Only the muscle's faces at least ALA_LATERAL of the alar base's distance from the midline
    (12 mm here: 9 mm) take the ala: the strip's half nearer the midline is left out."""
    from faceforge.skin.ala import beside_ala

    v = np.array([[0.0, 0.0, -10.0], [6.0, 0.0, -10.0], [6.0, 10.0, -10.0], [0.0, 10.0, -10.0],
                  [20.0, 0.0, -10.0], [20.0, 10.0, -10.0]])
    f = np.array([[0, 1, 2], [0, 2, 3], [1, 4, 5], [1, 5, 2]])
    assert beside_ala(v, f, LANDMARKS).tolist() == [False, False, True, True]
    assert beside_ala(v, f, LANDMARKS, 0.0).all() and beside_ala(v, f, {}).all()
    bodies = [Body("levator_labii_inner_L", "muscle", v, f)]
    binding = Binding(body_names=("levator_labii_inner_L", "cranium"), status=np.array([CRANIUM], np.int8),
                      vertex_ids=np.arange(1), body=np.array([1]), face_ids=np.zeros(1, np.int64),
                      bary=np.full((1, 3), 1 / 3), points=np.array([[2.0, 5.0, -30.0]]), distance=np.array([30.0]),
                      outward=np.zeros(1, bool), normals=np.array([[0.0, 0.0, 1.0]]), closest=np.zeros(1, bool))
    near = np.array([[2.0, 5.0, 0.0]])   # in front of the strip's medial half
    out, _ = ala_binding(binding, near, bodies, [0], np.array([True]), 200.0, landmarks=LANDMARKS)
    assert out.points[0, 0] >= 6.0 - 1e-9 and out.face_ids[0] in (2, 3)   # on the lateral faces
    out, _ = ala_binding(binding, near, bodies, [0], np.array([True]), 200.0)   # no landmarks: the closest
    np.testing.assert_allclose(out.points[0, :2], [2.0, 5.0])
