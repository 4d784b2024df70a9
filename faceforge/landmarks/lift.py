"""Back-projection: 2D points of a render -> points on the mesh, holes snapped to their rim.

The rasteriser's buffers already are the answer of a ray cast: the pixel's triangle and
barycentric coordinates give the first surface the orthographic ray meets. A ray through
a hole (an eye without eyeball, an open mouth) meets the inside of the head far behind
the face; such a point is recognised because nearer surface surrounds it in the picture
(a depth step of :data:`HOLE_DEPTH` of the diagonal in at least :data:`RING_HITS` of
:data:`RING_DIRECTIONS` directions within the ring's radius), and it moves to the nearest
pixel of that nearer surface: the hole's rim. An occluding nose lies on one side only,
so points beside it are not taken for holes.
"""

from __future__ import annotations

import numpy as np

from faceforge.landmarks.raster import Render, surface_at

#: a hit this much (fraction of the bounding-box diagonal) behind its surroundings is in a hole
HOLE_DEPTH = 0.01
RING_DIRECTIONS = 16
RING_HITS = 11


def _pixels(render_: Render, points: np.ndarray):
    n = render_.depth.shape[0]
    cols = np.clip(np.floor(points[:, 0]).astype(np.int64), 0, n - 1)
    rows = np.clip(np.floor(points[:, 1]).astype(np.int64), 0, n - 1)
    return rows, cols


def in_hole(render_: Render, points: np.ndarray, radius_px: float, step: float) -> np.ndarray:
    """(k,) bool: the pixel under each of ``points (k, 2)`` lies in a hole (module docstring).
    ``step``: the depth step (mesh units)."""
    rows, cols = _pixels(render_, points)
    n = render_.depth.shape[0]
    depth = render_.depth[rows, cols]
    ang = np.linspace(0.0, 2 * np.pi, RING_DIRECTIONS, endpoint=False)
    radii = np.arange(1.0, radius_px + 1.0)
    dc = np.cos(ang)[:, None] * radii[None, :]          # (dirs, steps)
    dr = np.sin(ang)[:, None] * radii[None, :]
    rr = np.clip(np.round(rows[:, None, None] + dr[None]).astype(np.int64), 0, n - 1)
    cc = np.clip(np.round(cols[:, None, None] + dc[None]).astype(np.int64), 0, n - 1)
    ring = render_.depth[rr, cc]                         # (k, dirs, steps)
    nearer = np.any(ring < (depth - step)[:, None, None], axis=2)   # inf depth (background) -> nothing nearer
    return np.sum(nearer, axis=1) >= RING_HITS


def lift(render_: Render, vertices: np.ndarray, faces: np.ndarray, points: np.ndarray,
         diagonal: float, radius_px: float) -> tuple[np.ndarray, np.ndarray]:
    """Surface points under ``points (k, 2)`` (pixels) -> ``(positions (k, 3), snapped (k,) bool)``.

    Points in a hole move to the nearest pixel of the nearer surface around it (the rim);
    points on the background are NaN.
    """
    points = np.asarray(points, dtype=np.float64)
    rows, cols = _pixels(render_, points)
    step = HOLE_DEPTH * diagonal
    hole = in_hole(render_, points, radius_px, step)
    hole &= np.isfinite(render_.depth[rows, cols])
    n = render_.depth.shape[0]
    r = int(np.ceil(radius_px))
    for i in np.flatnonzero(hole):
        r0, r1 = max(rows[i] - r, 0), min(rows[i] + r + 1, n)
        c0, c1 = max(cols[i] - r, 0), min(cols[i] + r + 1, n)
        win = render_.depth[r0:r1, c0:c1]
        ok = np.argwhere(win < render_.depth[rows[i], cols[i]] - step)
        if len(ok):
            dist = np.hypot(ok[:, 0] + r0 + 0.5 - points[i, 1], ok[:, 1] + c0 + 0.5 - points[i, 0])
            k = int(np.argmin(dist))
            rows[i], cols[i] = ok[k, 0] + r0, ok[k, 1] + c0
    return surface_at(render_, faces, vertices, rows, cols), hole


def view_depth(render_: Render, positions: np.ndarray) -> np.ndarray:
    """(k,) depth along the view of mesh points ``(k, 3)``."""
    return render_.view.project(positions)[:, 2]
