"""Lip skin binds to the ring around the mouth at its own place along the lip (issues 25, 27).

ICT's ring lies above its lips: the closest point of the upper arc to a vertex near the lip's
middle was on the arc's side, 6-8 mm out; carried, the vertex took the motion of that point when
the sphincter drew the ring in, crossed the midline and creased it (the ``u`` viseme). Here a
strip of skin under half an ellipse (the ring's upper arc, its centre above the strip) is bound
to the arc, the arc drawn in across the mouth to 60 %, and each skin vertex moved as its bound
point moved: bound by the plain closest point the strip folds, by :func:`arc_closest` it does not.
"""

import numpy as np
import pytest

from faceforge.animation.checks import folded_edges
from faceforge.geometry.surface_points import closest_points
from faceforge.skin.arc_points import arc_closest, long_axis
from tests.pbd.meshes import grid_faces


def _arc_and_strip(n: int = 21):
    t = np.linspace(0.0, np.pi, 41)
    ring = np.concatenate([np.c_[2.5 * np.cos(t), 1.2 * np.sin(t), np.full_like(t, z)] for z in (-0.5, 0.5)])
    faces = np.array([[i, i + 1, 41 + i] for i in range(40)] + [[i + 1, 42 + i, 41 + i] for i in range(40)])
    x, y = np.meshgrid(np.linspace(-1.0, 1.0, n), np.linspace(-1.2, -0.9, n))
    skin = np.c_[x.ravel(), y.ravel(), np.full(x.size, 0.3)]
    return ring, faces, skin, grid_faces(n)


def _folds_when_drawn_in(find) -> tuple[int, float]:
    ring, rf, skin, sf = _arc_and_strip()
    p, d, tri = find(skin, ring, rf)
    moved = p * [0.6, 1.0, 1.0]                  # the sphincter draws its ring in across the mouth
    target = skin + (moved - p)                  # carried: the skin moves as its bound point moves
    return int(folded_edges(skin, target[None], sf)[0].sum()), float(np.abs(p[:, 0] - skin[:, 0]).max())


def test_arc_binding_keeps_the_lip_smooth():
    folds, off = _folds_when_drawn_in(arc_closest)
    assert folds == 0
    assert off < 0.2                             # bound nearly above itself


def test_the_plain_closest_point_creases_it():
    """The test can fail: bound to the closest point, the same strip folds."""
    folds, off = _folds_when_drawn_in(closest_points)
    assert folds > 10 and off > 1.0


def test_arc_closest_lies_on_the_surface_and_reports_the_true_distance():
    ring, rf, skin, _ = _arc_and_strip(5)
    p, d, tri = arc_closest(skin, ring, rf)
    np.testing.assert_allclose(d, np.linalg.norm(p - skin, axis=1))
    a, b, c = (ring[rf[tri, k]] for k in range(3))
    n = np.cross(b - a, c - a)
    np.testing.assert_allclose(np.einsum("ij,ij->i", p - a, n), 0.0, atol=1e-9)   # on its triangle's plane
    assert abs(abs(long_axis(ring)[0]) - 1.0) < 1e-9
    q, e, _ = arc_closest(skin, ring, rf, stretch=1.0)
    q0, e0, _ = closest_points(skin, ring, rf)
    np.testing.assert_allclose(q, q0)


@pytest.mark.parametrize("stretch", [2.0, 4.0])
def test_stretch_keeps_the_lateral_place(stretch):
    ring, rf, skin, _ = _arc_and_strip(5)
    p, _, _ = arc_closest(skin, ring, rf, stretch=stretch)
    p0, _, _ = closest_points(skin, ring, rf)
    assert np.abs(p[:, 0] - skin[:, 0]).max() < np.abs(p0[:, 0] - skin[:, 0]).max()
