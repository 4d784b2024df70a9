"""The forehead above the brow on the bone (faceforge.skin.brow.onto_cranium, bind.forehead_bone_mm)."""

import numpy as np

from faceforge.skin.binding import Binding, Body
from faceforge.skin.brow import forehead_mask, onto_cranium
from faceforge.skin.casting import CRANIUM, MUSCLE

# a face in the xy plane, y up, eyes 63 units apart (1 unit = 1 mm), the brows 15 mm above them
LANDMARKS = {"3.5": (31.5, 0.0, 0.0), "3.6": (-31.5, 0.0, 0.0),
             "4.1": (12.0, 15.0, 0.0), "4.3": (30.0, 18.0, 0.0), "4.5": (48.0, 14.0, 0.0),
             "4.2": (-12.0, 15.0, 0.0), "4.4": (-30.0, 18.0, 0.0), "4.6": (-48.0, 14.0, 0.0)}


def test_mask_is_the_forehead_beyond_the_given_height_above_the_brows():
    pts = np.array([[30.0, 20.0, 0.0],     # on the brow (2 mm above 4.3)
                    [30.0, 30.0, 0.0],     # 12 mm above it
                    [30.0, 45.0, 0.0],     # 27 mm above it
                    [0.0, 45.0, 0.0],      # the midline, high
                    [-30.0, 40.0, 0.0],    # the right forehead
                    [30.0, 0.0, 0.0]])     # the eye, below the brow
    assert forehead_mask(pts, LANDMARKS, 15.0).tolist() == [False, False, True, True, True, False]
    assert forehead_mask(pts, LANDMARKS, 5.0).tolist() == [False, True, True, True, True, False]
    assert not forehead_mask(pts, LANDMARKS, 0.0).any()
    assert not forehead_mask(pts, {k: v for k, v in LANDMARKS.items() if k[0] != "3"}, 15.0).any()   # no ES0


def _plane(z: float, y0: float, y1: float):
    v = np.array([[-60.0, y0, z], [60.0, y0, z], [60.0, y1, z], [-60.0, y1, z]])
    return v, np.array([[0, 1, 2], [0, 2, 3]])


def test_forehead_skin_on_the_frontalis_only_moves_to_the_cranium():
    bodies = [Body("frontalis_inner_L", "muscle", *_plane(-3.0, 10.0, 80.0)),
              Body("corrugator_supercilii_L", "muscle", *_plane(-5.0, 10.0, 25.0)),
              Body("cranium", "cranium", *_plane(-8.0, -40.0, 100.0))]
    v = np.array([[20.0, 45.0, 0.0],    # 0: forehead, on the frontalis alone -> the bone
                  [25.0, 50.0, 0.0],    # 1: forehead, frontalis and corrugator -> kept
                  [30.0, 20.0, 0.0],    # 2: the brow, on the frontalis, outside the mask -> kept
                  [10.0, 60.0, 0.0]])   # 3: forehead, frontalis twice -> the bone, one anchor
    ids = np.array([0, 1, 1, 2, 3, 3])
    body = np.array([0, 0, 1, 0, 0, 0])
    pts = v[ids] * [1.0, 1.0, 0.0] + np.array([-3.0, -3.0, -5.0, -3.0, -3.0, -3.0])[:, None] * [0, 0, 1]
    binding = Binding(body_names=tuple(b.name for b in bodies), status=np.full(4, MUSCLE, np.int8),
                      vertex_ids=ids, body=body, face_ids=np.zeros(6, np.int64), bary=np.full((6, 3), 1 / 3),
                      points=pts, distance=np.abs(pts[:, 2]), outward=np.ones(6, bool),
                      normals=np.tile([0.0, 0.0, 1.0], (4, 1)), closest=np.zeros(6, bool))
    mask = np.array([True, True, False, True])
    out, moved = onto_cranium(binding, v, bodies, [0], mask, 20.0)
    assert moved == 2
    assert out.vertex_ids.tolist() == [0, 1, 1, 2, 3]
    assert out.body.tolist() == [2, 0, 1, 0, 2]
    assert out.status.tolist() == [CRANIUM, MUSCLE, MUSCLE, CRANIUM]
    np.testing.assert_allclose(out.points[0], [20.0, 45.0, -8.0])
    np.testing.assert_allclose(out.distance[[0, 4]], 8.0)
    assert not out.outward[0] and out.outward[1]
    tri = bodies[2].vertices[bodies[2].faces[out.face_ids[4]]]
    np.testing.assert_allclose(out.bary[4] @ tri, out.points[4])
    assert binding.body.tolist() == [0, 0, 1, 0, 0, 0]   # the input is not changed
    same, none = onto_cranium(binding, v, bodies, [0], mask, 5.0)   # no bone in reach
    assert none == 0 and same is binding
    same, none = onto_cranium(binding, v, bodies, [], mask, 20.0)   # no raisers
    assert none == 0 and same is binding
