"""Eye pieces found at the pupils and turned rigidly about the eyeball's centre."""

from __future__ import annotations

import numpy as np
import pytest

from faceforge.animation.eyeballs import EYEBALL_RADIUS, apply_gaze, eye_pieces, gaze_rotation, rotate_eye


def _head():
    """A skin sheet (3 x 3 vertices) and two iris discs (a fan of 4 triangles each) at the pupils."""
    skin = np.array([[x, y, 0] for y in (-5, 0, 5) for x in (-5, 0, 5)], dtype=float)
    faces = [[r * 3 + c + a, r * 3 + c + b, r * 3 + c + d] for r in range(2) for c in range(2)
             for a, b, d in ((0, 1, 4), (0, 4, 3))]
    verts = [skin]
    for cx in (2.0, -2.0):
        k = sum(len(v) for v in verts)
        ring = [[cx + 0.3 * np.cos(a), 1 + 0.3 * np.sin(a), 0.5] for a in np.linspace(0, 2 * np.pi, 4, endpoint=False)]
        verts.append(np.array([[cx, 1, 0.5], *ring]))
        faces += [[k, k + 1 + i, k + 1 + (i + 1) % 4] for i in range(4)]
    v = np.concatenate(verts)
    lm = {"3.5": [2, 1, 0.5], "3.7": [3.5, 1, 0.2], "3.11": [0.5, 1, 0.2],
          "3.6": [-2, 1, 0.5], "3.12": [-3.5, 1, 0.2], "3.8": [-0.5, 1, 0.2]}
    return v, np.array(faces), {k: np.array(p, float) for k, p in lm.items()}


def test_pieces_at_the_pupils_and_none_without():
    v, f, lm = _head()
    eyes = eye_pieces(v, f, lm)
    assert set(eyes) == {"L", "R"}
    assert list(eyes["L"][0]) == [9, 10, 11, 12, 13] and list(eyes["R"][0]) == [14, 15, 16, 17, 18]
    assert np.allclose(eyes["L"][1], [2, 1, 0.5 - EYEBALL_RADIUS * 1.5])
    assert eye_pieces(v[:9], f[:8], lm) == {}                           # skin only
    assert set(eye_pieces(v, f, {k: p for k, p in lm.items() if k != "3.6"})) == {"L"}


def test_gaze_turns_the_piece_rigidly_towards_its_direction():
    v, f, lm = _head()
    ids, c = eye_pieces(v, f, lm)["L"]
    out = rotate_eye(v, ids, c, np.radians(30), 0.0)
    assert np.array_equal(out[:9], v[:9]) and np.array_equal(out[14:], v[14:])   # nothing else moves
    d0, d1 = v[ids] - c, out[ids] - c
    assert np.allclose(np.linalg.norm(d0, axis=1), np.linalg.norm(d1, axis=1))  # rigid about the centre
    assert out[9, 0] > v[9, 0]                                               # yaw + looks towards +X
    assert np.allclose(gaze_rotation(0.0, np.radians(20)) @ [0, 0, 1], [0, np.sin(np.radians(20)), np.cos(np.radians(20))])
    g = np.array([[0.0, 0, 0, 0], [np.radians(30), 0, 0, 0]])
    frames = apply_gaze(np.stack([v, v]), g, {"L": (ids, c)})
    assert np.array_equal(frames[0], v) and np.allclose(frames[1], out)


def test_the_eyeball_faps_turn_left_and_down_as_mpeg4_says():
    """FAP 23 / 24 (yaw) positive to the subject's left, 25 / 26 (pitch) positive down, in AU."""
    from faceforge.animation.eyeballs import gaze_from_faps

    faps = np.zeros((2, 68))
    faps[0, 22], faps[0, 24] = 10000, 20000                # yaw_l 0.1 rad, pitch_l 0.2 rad down
    faps[1, 23], faps[1, 25] = -30000, -5000               # yaw_r 0.3 rad right, pitch_r 0.05 rad up
    g = gaze_from_faps(faps)
    assert np.allclose(g, [[0.1, -0.2, 0.0, 0.0], [0.0, 0.0, -0.3, 0.05]])
    forward = gaze_rotation(g[0, 0], g[0, 1]) @ [0.0, 0.0, 1.0]
    assert forward[0] > 0.0 and forward[1] < 0.0            # towards the subject's left, and down


def test_a_whole_eyeball_turns_in_place_with_its_iris():
    """A sphere (the eyeball) and a disc in front of it (the iris), two pieces: both turn about the
    sphere's centre, so the eyeball spins in place instead of swinging about a point behind it."""
    import trimesh

    v, f, lm = _head()
    ball = trimesh.creation.icosphere(subdivisions=2, radius=1.2)
    ball.apply_translation([2.0, 1.0, 0.5 - 1.25])
    n = len(v)
    v2 = np.concatenate([v, ball.vertices])
    f2 = np.concatenate([f, ball.faces + n])
    ids, c = eye_pieces(v2, f2, lm)["L"]
    assert set(range(9, 14)) <= set(ids.tolist()) and set(range(n, len(v2))) <= set(ids.tolist())
    assert np.allclose(c, [2.0, 1.0, 0.5 - 1.25], atol=1e-6)
    out = rotate_eye(v2, ids, c, np.radians(25), np.radians(-10))
    assert np.allclose(out[n:].mean(axis=0), v2[n:].mean(axis=0), atol=1e-9)   # the ball stays put
