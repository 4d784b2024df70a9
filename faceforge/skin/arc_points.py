"""Closest points on the ring around the mouth, taken at the lip vertex's own place along the lip.

The lip skin whose rays miss binds to its own arc of the orbicularis oris (``bind.lips_to_ring``,
:func:`faceforge.skin.casting._closest_fallback`). Where the fitted ring lies a centimetre or two
off the lips (ICT: 1.7-2.3 cm above the upper lip's inner edge), the closest point of the arc to a
vertex near the lip's middle is not above it but on the arc's nearest bulge to the side: ICT's
inner upper lip 1.8 mm either side of the midline bound 6-8 mm out, on the other side's half. A
carried anchor moves its vertex as its surface point moves (``skin.carry``), and the sphincter draws
its ring toward the middle in proportion to the distance from it: the vertices took the motion of
points four times further out, crossed the midline and creased it (the ``u`` viseme: 31 folded
edges on the upper lip's midline, "the philtrum drawn to a point").

:func:`arc_closest` measures the distance with the ring's long axis (across the mouth, its
largest principal axis) weighed ``stretch`` times, so the point found lies nearly at the vertex's
own place along the lip. A linear map keeps barycentric coordinates, so the point found in the
stretched space, mapped back, is on the same triangle of the real ring.
"""

from __future__ import annotations

import numpy as np

#: how many times a step along the ring's long axis counts against one across it
ARC_STRETCH = 2.0


def long_axis(vertices: np.ndarray) -> np.ndarray:
    """Unit ``(3,)`` principal axis of largest spread of ``vertices (n, 3)`` (a ring around the
    mouth: across the mouth)."""
    v = np.asarray(vertices, dtype=np.float64)
    _, _, vt = np.linalg.svd(v - v.mean(axis=0), full_matrices=False)
    return vt[0]


def arc_closest(points, vertices, faces, stretch: float = ARC_STRETCH):
    """Closest point of the mesh ``vertices (n, 3)``, ``faces (m, 3)`` to each of ``points
    (k, 3)`` in the metric that weighs the mesh's long axis (:func:`long_axis`) ``stretch``
    times. Returns ``(closest (k, 3), distance (k,), face_ids (k,))`` as
    :func:`faceforge.geometry.surface_points.closest_points` does, the distance the true
    (Euclidean) one in skin units."""
    from faceforge.geometry.surface_points import closest_points

    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    v = np.asarray(vertices, dtype=np.float64)
    if stretch == 1.0 or len(p) == 0:
        return closest_points(p, v, faces)
    a = long_axis(v)
    scale = np.eye(3) + (float(stretch) - 1.0) * np.outer(a, a)   # symmetric: x -> x + (s-1)(x.a)a
    unscale = np.eye(3) + (1.0 / float(stretch) - 1.0) * np.outer(a, a)
    q, _, tri = closest_points(p @ scale, v @ scale, faces)
    q = q @ unscale
    return q, np.linalg.norm(q - p, axis=1), tri
