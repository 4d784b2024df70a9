"""The nose on its cartilages, off the ring behind the nostrils (faceforge.skin.rules.nose_mask,
bind.nose_on_bone; docs/notes/tent17.md)."""

import numpy as np

from faceforge.skin.rules import NOSE_BASE_MM, nose_mask

# a face looking along +z, y up (1 unit = 1 mm): the nose base 9.15 at the origin, the tip 15 mm
# in front of it and 12 mm up, the alar bases 12 mm to each side at 1 mm up, the alar creases
# 18 mm to each side at 8 mm up
LANDMARKS = {"9.15": (0.0, 0.0, 0.0), "9.3": (0.0, 12.0, 15.0), "9.4": (-12.0, 1.0, -4.0),
             "9.5": (12.0, 1.0, -4.0), "9.2": (-18.0, 8.0, -6.0), "9.1": (18.0, 8.0, -6.0)}


def test_the_mask_is_the_nose_above_its_base_within_the_alae():
    pts = np.array([[0.0, 0.0, 0.0],       # 0: the nose base itself -> in
                    [0.0, -3.0, 0.0],      # 1: the philtrum below it -> out
                    [0.0, 12.0, 15.0],     # 2: the tip -> in
                    [3.0, 4.0, -8.0],      # 3: inside a nostril, 8 mm behind the base -> in
                    [11.0, 1.0, -3.0],     # 4: the ala at its base -> in
                    [14.0, 1.0, -3.0],     # 5: beside the alar base (the cheek, the lip's top) -> out
                    [16.0, 8.0, -5.0],     # 6: the ala at the crease's height, inside it -> in
                    [16.0, 3.0, -5.0],     # 7: as far out, lower (the width 13.7 there) -> out
                    [0.0, 5.0, -20.0],     # 8: behind the nose deeper than the tip is in front (the palate) -> out
                    [-16.0, 20.0, 0.0],    # 9: the nose's side above the creases, the other half -> in
                    [8.0, 0.5, -2.0]])     # 10: the sill under a nostril, below the base-to-alar-base line -> out
    # no ES0 (FDPs 3.5 / 3.6) in these landmarks: the outline starts at the nose base itself
    assert nose_mask(pts, LANDMARKS).tolist() == [True, False, True, True, True, False, True, False, False, True,
                                                  False]
    for k in LANDMARKS:   # each of the six FDPs is needed
        assert not nose_mask(pts, {j: p for j, p in LANDMARKS.items() if j != k}).any()


def test_the_nose_base_itself_stays_with_the_lip():
    """With ES0 (eyes 63 units apart: 1 unit = 1 mm) the skin within NOSE_BASE_MM above 9.15 is
    the lip's (the subnasale, where the ring's upper fibres insert); above it, the nose's."""
    eyes = {**LANDMARKS, "3.5": (31.5, 40.0, -10.0), "3.6": (-31.5, 40.0, -10.0)}
    pts = np.array([[0.0, 0.0, 0.0], [0.0, 0.5 * NOSE_BASE_MM, 0.5], [0.0, 1.5 * NOSE_BASE_MM, 1.0],
                    [0.0, 12.0, 15.0]])
    assert nose_mask(pts, eyes).tolist() == [False, False, True, True]
    assert nose_mask(pts, eyes, base_mm=0.0).tolist() == [True, True, True, True]


def test_the_mask_follows_the_given_up_direction():
    turn = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])   # +y -> +z, +z -> -y
    pts = np.array([[0.0, 0.0, 0.0], [0.0, -3.0, 0.0], [0.0, 12.0, 15.0], [14.0, 1.0, -3.0]])
    rot = {k: np.asarray(p) @ turn.T for k, p in LANDMARKS.items()}
    assert nose_mask(pts @ turn.T, rot, up=(0.0, 0.0, 1.0)).tolist() == [True, False, True, False]
    assert nose_mask(pts @ turn.T, rot, up=(0.0, 1.0, 0.0)).tolist() != [True, False, True, False]
