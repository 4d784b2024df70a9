"""The brow's insertion (faceforge.skin.brow): brow skin on the bone moves to the brow muscles."""

import numpy as np

from faceforge.skin.binding import Body
from faceforge.skin.brow import brow_anchors, brow_mask
from faceforge.skin.casting import CRANIUM, MUSCLE

# a face in the xy plane, y up, eyes 63 units apart (1 unit = 1 mm)
LANDMARKS = {"3.5": (31.5, 0.0, 0.0), "3.6": (-31.5, 0.0, 0.0), "3.1": (31.5, 5.0, 0.0), "3.2": (-31.5, 5.0, 0.0),
             "4.1": (10.0, 20.0, 0.0), "4.3": (30.0, 24.0, 0.0), "4.5": (48.0, 18.0, 0.0),
             "4.2": (-10.0, 20.0, 0.0), "4.4": (-30.0, 24.0, 0.0), "4.6": (-48.0, 18.0, 0.0)}


def test_mask_is_the_band_along_the_brows_above_the_lids():
    pts = np.array([[30.0, 24.0, 0.0],     # on the brow
                    [30.0, 33.0, 0.0],     # 9 mm above it
                    [30.0, 36.0, 0.0],     # 12 mm above: forehead
                    [30.0, 7.0, 0.0],      # 2 mm above the upper lid FDP: a lid
                    [30.0, 15.0, 0.0],     # between lid and brow
                    [-30.0, 20.0, 0.0],    # the other brow
                    [0.0, 60.0, 0.0]])     # high forehead
    assert brow_mask(pts, LANDMARKS).tolist() == [True, True, False, False, True, True, False]
    assert not brow_mask(pts, LANDMARKS, band_mm=0.0).any()
    assert not brow_mask(pts, {k: v for k, v in LANDMARKS.items() if k[0] != "3"}).any()   # no ES0


def _plane(z: float, x0: float, x1: float):
    v = np.array([[x0, 0.0, z], [x1, 0.0, z], [x1, 40.0, z], [x0, 40.0, z]])
    return v, np.array([[0, 1, 2], [0, 2, 3]])


def test_brow_skin_on_bone_moves_to_the_nearest_brow_muscle_within_reach():
    bodies = [Body("frontalis_L", "muscle", *_plane(-5.0, 0.0, 60.0)),
              Body("orbicularis_oculi_L", "muscle", *_plane(-2.0, 40.0, 60.0)),
              Body("cranium", "cranium", *_plane(-30.0, -100.0, 100.0))]
    kinds = np.array([MUSCLE, MUSCLE, CRANIUM])
    v = np.array([[30.0, 20.0, 0.0], [50.0, 20.0, 0.0], [30.0, 10.0, 0.0], [-30.0, 20.0, 0.0]])
    mask = np.array([True, True, True, False])
    body = np.array([2, 2, 0, 2])
    face = np.zeros(4, int)
    pts = np.zeros((4, 3))
    dist = np.array([30.0, 30.0, 5.0, 30.0])
    moved = brow_anchors(v, bodies, kinds, [0], mask, 20.0, body, face, pts, dist)
    # on the bone and in the band: to the frontalis (the orbicularis, nearer, is not a brow muscle
    # here); already on a muscle, or outside the band: unchanged
    assert moved.tolist() == [True, True, False, False]
    assert body.tolist() == [0, 0, 0, 2]
    np.testing.assert_allclose(pts[:2], [[30.0, 20.0, -5.0], [50.0, 20.0, -5.0]])
    np.testing.assert_allclose(dist[:2], 5.0)
    # nothing within reach: the vertex keeps its anchor on the bone
    body2 = np.array([2, 2, 0, 2])
    assert not brow_anchors(v, bodies, kinds, [0], mask, 4.0, body2, face, pts.copy(), dist.copy()).any()
    assert body2.tolist() == [2, 2, 0, 2]


# the eyes' corners and lids of the face above (inner / outer canthus, upper / lower lid FDPs)
EYE_LANDMARKS = {**LANDMARKS, "3.11": (19.0, 0.0, 0.0), "3.7": (44.0, 0.0, 0.0), "3.3": (31.5, -4.0, 0.0),
                 "3.12": (-19.0, 0.0, 0.0), "3.8": (-44.0, 0.0, 0.0), "3.4": (-31.5, -4.0, 0.0)}


def test_eye_mask_is_the_lids_and_the_socket_behind_them_not_the_brow_or_cheek():
    from faceforge.skin.brow import eye_mask

    pts = np.array([[31.5, 4.0, 1.0],      # upper lid
                    [31.5, -4.0, 1.0],     # lower lid margin
                    [-31.5, 0.0, 0.0],     # the other eye
                    [31.5, -12.0, -20.0],  # the socket's floor, deep behind the canthi
                    [31.5, 4.0, -15.0],    # the socket's roof
                    [31.5, -12.0, 0.0],    # the cheek below the lower lid, in front
                    [30.0, 15.0, -10.0],   # between the lid and the brow, above the lid + 3 mm
                    [30.0, 24.0, 0.0],     # the brow
                    [80.0, 0.0, -20.0]])   # behind, but beyond the eye's reach (the temple)
    assert eye_mask(pts, EYE_LANDMARKS).tolist() == [True, True, True, True, True, False, False, False, False]
    assert not eye_mask(pts, LANDMARKS).any()   # no canthi: no eye


def test_eye_skin_on_a_brow_muscle_moves_to_the_bone():
    from faceforge.skin.brow import eye_anchors

    bodies = [Body("corrugator_L", "muscle", *_plane(-5.0, 0.0, 60.0)),
              Body("zygomaticus_L", "muscle", *_plane(-3.0, 0.0, 60.0)),
              Body("cranium", "cranium", *_plane(-30.0, -100.0, 100.0))]
    kinds = np.array([MUSCLE, MUSCLE, CRANIUM])
    v = np.array([[30.0, 2.0, -10.0], [31.0, 2.0, -10.0], [30.0, 20.0, 0.0]])
    mask = np.array([True, True, False])
    body = np.array([0, 1, 0])
    face, pts, dist = np.zeros(3, int), np.zeros((3, 3)), np.array([5.0, 7.0, 5.0])
    moved = eye_anchors(v, bodies, kinds, [0], mask, 25.0, body, face, pts, dist)
    # in the eye and on a brow muscle: to the bone; on another muscle or outside the eye: kept
    assert moved.tolist() == [True, False, False]
    assert body.tolist() == [2, 1, 0]
    np.testing.assert_allclose(pts[0], [30.0, 2.0, -30.0])
    np.testing.assert_allclose(dist[0], 20.0)


def test_brow_skin_on_one_insertion_also_anchors_to_the_nearest_other_within_reach():
    from faceforge.skin.brow import shared_anchors

    bodies = [Body("corrugator_L", "muscle", *_plane(-5.0, 0.0, 30.0)),
              Body("depressor_supercilii_L", "muscle", *_plane(-6.0, 0.0, 20.0)),
              Body("frontalis_L", "muscle", *_plane(-4.0, 0.0, 60.0)),
              Body("cranium", "cranium", *_plane(-30.0, -100.0, 100.0))]
    v = np.array([[10.0, 20.0, 0.0], [28.0, 20.0, 0.0], [15.0, 20.0, 0.0], [12.0, 20.0, 0.0], [40.0, 20.0, 0.0]])
    ids = np.array([0, 1, 2, 3, 3, 4])
    body = np.array([0, 0, 2, 0, 1, 3])
    pts = v[ids] * [1.0, 1.0, 0.0] + np.array([[0, 0, -5.0], [0, 0, -5.0], [0, 0, -4.0], [0, 0, -5.0],
                                                 [0, 0, -6.0], [0, 0, -30.0]])
    anchors = (ids, body, np.zeros(6, int), pts, np.abs(pts[:, 2]), np.zeros(6, bool), np.zeros(6, bool))
    mask = np.array([True, True, True, True, False])
    out = shared_anchors(v, bodies, anchors, mask, [0, 1, 2], [0, 1], 4.0)
    # vertex 0 (corrugator) gains the depressor below it; 1 lies beyond the depressor's reach
    # (8 mm off its edge); 2 (frontalis) gains the nearer insertion, the corrugator; 3 has two
    # anchors already; 4 is outside the brow
    assert out[0].tolist() == [0, 0, 1, 2, 2, 3, 3, 4]
    assert out[1].tolist() == [0, 1, 0, 2, 0, 0, 1, 3]
    np.testing.assert_allclose(out[3][1], [10.0, 20.0, -6.0])
    np.testing.assert_allclose(out[3][4], [15.0, 20.0, -5.0])
    assert shared_anchors(v, bodies, anchors, mask, [0, 1, 2], [0, 1], 0.5)[0].tolist() == ids.tolist()


def test_outer_brow_on_the_orbicularis_also_anchors_to_the_frontalis_outer():
    from faceforge.skin.brow import outer_shared_anchors

    bodies = [Body("orbicularis_oculi_L", "muscle", *_plane(-5.0, 30.0, 60.0)),
              Body("frontalis_outer_L", "muscle", *_plane(-7.0, 20.0, 60.0)),
              Body("corrugator_supercilii_L", "muscle", *_plane(-6.0, 0.0, 20.0)),
              Body("cranium", "cranium", *_plane(-30.0, -100.0, 100.0))]
    v = np.array([[40.0, 20.0, 0.0], [10.0, 20.0, 0.0], [25.0, 20.0, 0.0]])
    ids = np.array([0, 1, 2])
    body = np.array([0, 2, 1])
    pts = v[ids] * [1.0, 1.0, 0.0] + np.array([[0, 0, -5.0], [0, 0, -6.0], [0, 0, -7.0]])
    anchors = (ids, body, np.zeros(3, int), pts, np.abs(pts[:, 2]), np.zeros(3, bool), np.zeros(3, bool))
    out = outer_shared_anchors(v, bodies, anchors, np.ones(3, bool), 4.0)
    # 0 (orbicularis) gains the frontalis 2 mm below; 1 (corrugator) is neither; 2 (frontalis)
    # is 5 mm off the orbicularis' edge, beyond reach
    assert out[0].tolist() == [0, 0, 1, 2]
    assert out[1].tolist() == [0, 1, 2, 1]
    np.testing.assert_allclose(out[3][1], [40.0, 20.0, -7.0])
    # without the pair (a map of one's own): unchanged
    assert outer_shared_anchors(v, bodies[2:], anchors, np.ones(3, bool), 4.0) is anchors


def test_brow_skin_on_a_depressor_also_anchors_to_the_frontalis_that_raises_it():
    from faceforge.skin.brow import raiser_anchors

    bodies = [Body("corrugator_supercilii_L", "muscle", *_plane(-5.0, 0.0, 30.0)),
              Body("depressor_supercilii_L", "muscle", *_plane(-6.0, 0.0, 20.0)),
              Body("frontalis_inner_L", "muscle", *_plane(-4.0, 0.0, 60.0)),
              Body("cranium", "cranium", *_plane(-30.0, -100.0, 100.0))]
    v = np.array([[10.0, 20.0, 0.0], [15.0, 20.0, 0.0], [12.0, 20.0, 0.0], [40.0, 20.0, 0.0],
                  [70.0, 20.0, 0.0]])
    ids = np.array([0, 0, 1, 2, 3, 4])
    body = np.array([0, 1, 2, 0, 3, 0])
    pts = v[ids] * [1.0, 1.0, 0.0] + np.array([[0, 0, -5.0], [0, 0, -6.0], [0, 0, -4.0], [0, 0, -5.0],
                                                 [0, 0, -30.0], [0, 0, -5.0]])
    anchors = (ids, body, np.zeros(6, int), pts, np.abs(pts[:, 2]), np.zeros(6, bool), np.zeros(6, bool))
    mask = np.array([True, True, False, True, True])
    out = raiser_anchors(v, bodies, anchors, mask, [2], 4.0)
    # 0 (corrugator + depressor) gains the frontalis above them, after its two rows; 1 is on the
    # frontalis already; 2 is outside the brow; 3 is on the bone; 4 lies 10 mm beyond the
    # frontalis' edge
    assert out[0].tolist() == [0, 0, 0, 1, 2, 3, 4]
    assert out[1].tolist() == [0, 1, 2, 2, 0, 3, 0]
    np.testing.assert_allclose(out[3][2], [10.0, 20.0, -4.0])
    assert raiser_anchors(v, bodies, anchors, mask, [], 4.0) is anchors
