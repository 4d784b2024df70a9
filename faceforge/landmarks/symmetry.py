"""Left/right symmetry: find a mesh's mirror plane and make FDP pairs mirror images.

:func:`mirror_plane` starts from the plane the detected landmarks suggest (normal along
the mean left-right difference of the pairs, through their midpoints) and refines it by
matching every vertex with the vertex nearest its mirror image (a few rounds). The mesh
is symmetric when, after that, 90 % of the vertices have a mirror partner within
:data:`SYMMETRY_TOLERANCE` of the diagonal.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: a mesh whose vertices' mirror images lie this close (90th percentile, fraction of the
#: diagonal) to another vertex is symmetric
SYMMETRY_TOLERANCE = 0.002
#: at most about this many vertices refine the plane (every k-th vertex)
SAMPLE = 5000


@dataclass(frozen=True)
class MirrorPlane:
    """The plane ``x . normal = offset``; ``partner (n,) int64``: each vertex's mirror vertex;
    ``error``: 90th-percentile mirror distance, fraction of the diagonal."""

    normal: np.ndarray
    offset: float
    partner: np.ndarray
    error: float

    def reflect(self, points: np.ndarray) -> np.ndarray:
        """(k, 3) -> (k, 3) mirror images."""
        p = np.asarray(points, dtype=np.float64)
        return p - 2.0 * np.outer(p @ self.normal - self.offset, self.normal)

    def onto(self, points: np.ndarray) -> np.ndarray:
        """(k, 3) points moved onto the plane along its normal."""
        p = np.asarray(points, dtype=np.float64)
        return p - np.outer(p @ self.normal - self.offset, self.normal)


def mirror_plane(vertices: np.ndarray, left: np.ndarray, right: np.ndarray, diagonal: float,
                 rounds: int = 4) -> MirrorPlane:
    """The mirror plane of ``vertices (n, 3)``, started from landmark pairs ``left, right (p, 3)``
    (subject's left and right points of the same features)."""
    from scipy.spatial import cKDTree

    v = np.asarray(vertices, dtype=np.float64)
    normal = np.mean(np.asarray(left) - np.asarray(right), axis=0)
    normal /= np.linalg.norm(normal)
    offset = float(np.mean((np.asarray(left) + np.asarray(right)) / 2 @ normal))
    tree = cKDTree(v)
    sample = v[:: max(1, len(v) // SAMPLE)]       # the plane's rounds need only a few thousand vertices
    for _ in range(rounds):
        plane = MirrorPlane(normal, offset, np.zeros(0, np.int64), 1.0)
        dist, partner = tree.query(plane.reflect(sample))
        apart = sample - v[partner]
        far = np.linalg.norm(apart, axis=1) > 1e-3 * diagonal
        side = np.sign(apart[far] @ normal)
        d = apart[far] * side[:, None]
        if len(d) < 3:
            break
        normal = np.mean(d, axis=0)
        normal /= np.linalg.norm(normal)
        offset = float(np.mean((sample[far] + v[partner[far]]) / 2 @ normal))
    dist, partner = tree.query(MirrorPlane(normal, offset, partner, 1.0).reflect(v))
    return MirrorPlane(normal, offset, partner.astype(np.int64), float(np.percentile(dist, 90) / diagonal))


def symmetric(plane: MirrorPlane) -> bool:
    """True when the mesh is mirror-symmetric about ``plane`` (module docstring)."""
    return plane.error <= SYMMETRY_TOLERANCE
