"""The cheek's insertion (faceforge.skin.cheek): cheek skin on the bone moves to the cheek raiser."""

import numpy as np

from faceforge.skin.binding import Binding, Body
from faceforge.skin.casting import CRANIUM, MUSCLE
from faceforge.skin.cheek import cheek_binding, cheek_mask

# a face in the xy plane, y up, eyes 63 units apart (1 unit = 1 mm), cheek bones 20 mm below them
LANDMARKS = {"3.5": (31.5, 0.0, 0.0), "3.6": (-31.5, 0.0, 0.0), "5.3": (35.0, -20.0, 0.0),
             "5.4": (-35.0, -20.0, 0.0), "3.11": (19.0, 0.0, 0.0), "3.7": (44.0, 0.0, 0.0),
             "3.3": (31.5, -4.0, 0.0), "3.1": (31.5, 5.0, 0.0), "3.12": (-19.0, 0.0, 0.0),
             "3.8": (-44.0, 0.0, 0.0), "3.4": (-31.5, -4.0, 0.0), "3.2": (-31.5, 5.0, 0.0)}


def one_anchor_binding(bodies, status, body, points):
    """A :class:`Binding` of ``len(status)`` skin vertices, one anchor each on ``body`` at ``points``
    (depth along z, normals +z): the rebinding passes' input."""
    n = len(status)
    return Binding(body_names=tuple(b.name for b in bodies), status=status, vertex_ids=np.arange(n),
                   body=body, face_ids=np.zeros(n, np.int64), bary=np.full((n, 3), 1 / 3),
                   points=points, distance=np.abs(points[:, 2]), outward=np.zeros(n, bool),
                   normals=np.tile([0.0, 0.0, 1.0], (n, 1)), closest=np.zeros(n, bool))


def test_mask_is_the_skin_around_the_cheek_bones_outside_the_lids():
    pts = np.array([[35.0, -20.0, 0.0],    # on 5.3
                    [35.0, -32.0, 0.0],    # 12 mm below it
                    [35.0, -38.0, 0.0],    # 18 mm below: out of reach
                    [-30.0, -14.0, 0.0],   # near 5.4
                    [31.5, -4.0, 1.0],     # the lower lid's margin (the eye's skin)
                    [0.0, -20.0, 0.0]])    # the nose
    assert cheek_mask(pts, LANDMARKS, 15.0).tolist() == [True, True, False, True, False, False]
    assert not cheek_mask(pts, LANDMARKS, 0.0).any()
    assert not cheek_mask(pts, {k: v for k, v in LANDMARKS.items() if k[0] != "5"}).any()   # no cheek FDPs


def _plane(z: float, x0: float, x1: float):
    v = np.array([[x0, -40.0, z], [x1, -40.0, z], [x1, 0.0, z], [x0, 0.0, z]])
    return v, np.array([[0, 1, 2], [0, 2, 3]])


def test_cheek_skin_on_bone_moves_to_the_cheek_raiser_within_reach():
    bodies = [Body("orbicularis_oculi_lower_L", "muscle", *_plane(-4.0, 20.0, 60.0)),
              Body("zygomaticus_major_L", "muscle", *_plane(-2.0, 20.0, 60.0)),
              Body("cranium", "cranium", *_plane(-20.0, -100.0, 100.0))]
    v = np.array([[35.0, -20.0, 0.0], [40.0, -25.0, 0.0], [30.0, -15.0, 0.0], [-35.0, -20.0, 0.0]])
    status = np.array([CRANIUM, MUSCLE, CRANIUM, CRANIUM], np.int8)
    body = np.array([2, 1, 2, 2])
    pts = v * [1.0, 1.0, 0.0] + [0.0, 0.0, -20.0]
    pts[1, 2] = -2.0
    binding = one_anchor_binding(bodies, status, body, pts)
    mask = np.array([True, True, False, True])
    out, moved = cheek_binding(binding, v, bodies, [0], mask, 10.0)
    # on the bone and in the cheek: to the cheek raiser; on a muscle, outside the mask, or with
    # no cheek muscle in reach (the right cheek: the raiser here is the left one): unchanged
    assert moved == 1
    assert out.body.tolist() == [0, 1, 2, 2]
    assert out.status.tolist() == [MUSCLE, MUSCLE, CRANIUM, CRANIUM]
    np.testing.assert_allclose(out.points[0], [35.0, -20.0, -4.0])
    np.testing.assert_allclose(out.distance[0], 4.0)
    tri = bodies[0].vertices[bodies[0].faces[out.face_ids[0]]]
    np.testing.assert_allclose(out.bary[0] @ tri, out.points[0])
    assert binding.body.tolist() == [2, 1, 2, 2]   # the input is not changed
    same, none = cheek_binding(binding, v, bodies, [0], mask, 3.0)   # nothing in reach
    assert none == 0 and same is binding
