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
