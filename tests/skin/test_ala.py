"""The ala's insertion (faceforge.skin.ala): the nose's wing on the lips' sphincter or the bone
moves to the levator labii superioris alaeque nasi (``bind.ala_mm``, ``bind.ala_muscles``)."""

import numpy as np

from faceforge.skin.ala import ala_mask
from faceforge.skin.binding import Binding, Body
from faceforge.skin.casting import CRANIUM, MUSCLE
from faceforge.skin.cheek import cheek_binding
from tests.skin.test_cheek import LANDMARKS as EYES

# a face in the xy plane, y up, 1 unit = 1 mm: the eyes of test_cheek, the alae 45 mm below them
LANDMARKS = {**EYES, "9.1": (16.0, -45.0, 0.0), "9.2": (-16.0, -45.0, 0.0)}


def test_mask_is_the_skin_around_the_alae():
    pts = np.array([[16.0, -45.0, 0.0],    # on 9.1
                    [16.0, -36.0, 0.0],    # 9 mm above it (the side of the nose)
                    [16.0, -60.0, 0.0],    # 15 mm below: the upper lip, out of reach
                    [-12.0, -47.0, 0.0],   # beside 9.2
                    [0.0, -45.0, 0.0]])    # the columella, 16 mm from either
    assert ala_mask(pts, LANDMARKS, 12.0).tolist() == [True, True, False, True, False]
    assert not ala_mask(pts, LANDMARKS, 0.0).any()                                   # the default: off
    assert not ala_mask(pts, {k: v for k, v in LANDMARKS.items() if k[0] != "9"}, 12.0).any()


def _plane(z: float, x0: float, x1: float, y0: float = -70.0, y1: float = -30.0):
    v = np.array([[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]])
    return v, np.array([[0, 1, 2], [0, 2, 3]])


def _binding(bodies, v, status, body, depth):
    pts = v * [1.0, 1.0, 0.0] + np.c_[np.zeros((len(v), 2)), -np.asarray(depth, float)]
    n = len(v)
    return Binding(body_names=tuple(b.name for b in bodies), status=np.asarray(status, np.int8),
                   vertex_ids=np.arange(n), body=np.asarray(body), face_ids=np.zeros(n, np.int64),
                   bary=np.full((n, 3), 1 / 3), points=pts, distance=np.asarray(depth, float),
                   outward=np.zeros(n, bool), normals=np.tile([0.0, 0.0, 1.0], (n, 1)), closest=np.zeros(n, bool))


def test_ala_skin_on_the_sphincter_or_bone_moves_to_the_levator():
    """The ala's skin whose ray found the lips' sphincter (the MakeHuman sample: 50 of the 94
    vertices MakeHuman's nose-elevation unit moves most) or the bone goes to the levator;
    without ``also_from`` (the cheek's rule) only the bone's does."""
    bodies = [Body("levator_labii_inner_L", "muscle", *_plane(-5.0, 8.0, 30.0)),
              Body("orbicularis_oris", "muscle", *_plane(-3.0, -30.0, 30.0)),
              Body("zygomaticus_major_L", "muscle", *_plane(-2.0, 30.0, 60.0)),
              Body("cranium", "cranium", *_plane(-20.0, -100.0, 100.0, -100.0, 0.0))]
    v = np.array([[16.0, -45.0, 0.0],      # the ala, on the sphincter
                  [18.0, -40.0, 0.0],      # the side of the nose, on the bone
                  [20.0, -47.0, 0.0],      # the ala, on another muscle: kept
                  [16.0, -62.0, 0.0]])     # the upper lip, on the sphincter, outside the mask: kept
    binding = _binding(bodies, v, [MUSCLE, CRANIUM, MUSCLE, MUSCLE], [1, 3, 2, 1], [3.0, 20.0, 2.0, 3.0])
    mask = ala_mask(v, LANDMARKS, 12.0)
    assert mask.tolist() == [True, True, True, False]
    out, moved = cheek_binding(binding, v, bodies, [0], mask, 10.0, also_from=[1])
    assert moved == 2
    assert out.body.tolist() == [0, 0, 2, 1]
    assert out.status.tolist() == [MUSCLE, MUSCLE, MUSCLE, MUSCLE]
    np.testing.assert_allclose(out.points[0], [16.0, -45.0, -5.0])
    tri = bodies[0].vertices[bodies[0].faces[out.face_ids[0]]]
    np.testing.assert_allclose(out.bary[0] @ tri, out.points[0])
    cheek_rule, moved = cheek_binding(binding, v, bodies, [0], mask, 10.0)     # bone only
    assert moved == 1 and cheek_rule.body.tolist() == [1, 0, 2, 1]
    assert binding.body.tolist() == [1, 3, 2, 1]   # the input is not changed
