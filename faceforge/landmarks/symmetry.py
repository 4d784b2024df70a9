"""Left/right symmetry: find a mesh's mirror plane and make FDP pairs mirror images.

:func:`mirror_plane` starts from the plane the detected landmarks suggest (normal along
the mean left-right difference of the pairs, through their midpoints) and refines it by
matching every vertex with the vertex nearest its mirror image (a few rounds; vertices whose
mirror image is far from any vertex, :data:`OUTLIER`, such as a piece on one side only, are
left out of the refinement). The mesh
is symmetric when, after that, 90 % of the vertices have a mirror partner within
:data:`SYMMETRY_TOLERANCE` of the diagonal.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from faceforge.geometry.mirror import Mirror

#: a mesh whose vertices' mirror images lie this close (90th percentile, fraction of the
#: diagonal) to another vertex is symmetric
SYMMETRY_TOLERANCE = 0.002
#: at most about this many vertices refine the plane (every k-th vertex)
SAMPLE = 5000
#: a vertex whose mirror image lies farther than this many times the median from any vertex does
#: not refine the plane (:func:`mirror_plane`)
OUTLIER = 3.0


@dataclass(frozen=True)
class MirrorFit:
    """A mesh's mirror plane: ``mirror`` (:class:`faceforge.geometry.mirror.Mirror`, point +
    unit normal), ``partner (n,) int64``: each vertex's mirror vertex; ``error``: 90th-percentile
    mirror distance, fraction of the diagonal."""

    mirror: Mirror
    partner: np.ndarray
    error: float


def mirror_plane(vertices: np.ndarray, left: np.ndarray, right: np.ndarray, diagonal: float,
                 rounds: int = 4) -> MirrorFit:
    """The mirror plane of ``vertices (n, 3)``, started from landmark pairs ``left, right (p, 3)``
    (subject's left and right points of the same features)."""
    from scipy.spatial import cKDTree

    v = np.asarray(vertices, dtype=np.float64)
    normal = np.mean(np.asarray(left) - np.asarray(right), axis=0)
    normal /= np.linalg.norm(normal)
    point = normal * np.mean((np.asarray(left) + np.asarray(right)) / 2 @ normal)   # the foot of the origin
    tree = cKDTree(v)
    sample = v[:: max(1, len(v) // SAMPLE)]       # the plane's rounds need only a few thousand vertices
    for _ in range(rounds):
        mirror = Mirror(point, normal)
        dist, partner = tree.query(mirror(sample))
        apart = sample - v[partner]
        # the pairs that mirror each other: a piece on one side only (a lash card, an earring) has
        # no mirror image, and its far-off partners tilted the plane (every FDP pair then moved)
        mirrored = dist <= max(OUTLIER * np.median(dist), 1e-3 * diagonal)
        far = (np.linalg.norm(apart, axis=1) > 1e-3 * diagonal) & mirrored
        side = np.sign(apart[far] @ mirror.normal)
        d = apart[far] * side[:, None]
        if len(d) < 3:
            break
        normal = np.mean(d, axis=0)
        normal /= np.linalg.norm(normal)
        point = normal * np.mean((sample[far] + v[partner[far]]) / 2 @ normal)
    mirror = Mirror(point, normal)
    dist, partner = tree.query(mirror(v))
    return MirrorFit(mirror, partner.astype(np.int64), float(np.percentile(dist, 90) / diagonal))


def symmetric(plane: MirrorFit) -> bool:
    """True when the mesh is mirror-symmetric about ``plane`` (module docstring)."""
    return plane.error <= SYMMETRY_TOLERANCE
