"""points_inside reuses a mesh's parity grid while the same bones come back (the bake's checks)."""

from __future__ import annotations

import numpy as np


def _cube(shift=0.0):
    v = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], dtype=float) + [shift, 0.0, 0.0]
    f = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                  [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    return v, f


def test_the_grid_is_reused_for_the_same_mesh_and_rebuilt_for_a_moved_one():
    from faceforge.animation import checks

    pts = np.array([[0.5, 0.5, 0.5], [1.7, 0.5, 0.5], [2.2, 0.4, 0.6]])
    v, f = _cube()
    assert list(checks.points_inside(pts, v, f)) == [True, False, False]
    grid = checks._grid(v, f)
    assert checks._grid(v.copy(), f.copy()) is grid                    # same bytes: same grid
    v2, _ = _cube(1.5)                                                 # the bone moved (a jaw pose)
    assert list(checks.points_inside(pts, v2, f)) == [False, True, True]
    assert checks._grid(v2, f) is not grid
    assert list(checks.points_inside(pts, v, f)) == [True, False, False]   # the old one still right
