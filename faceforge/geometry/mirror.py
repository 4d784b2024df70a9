"""Reflection about a plane (a head's midsagittal plane)."""

from __future__ import annotations

import numpy as np

#: largest vertex-to-mirror-partner gap, as a fraction of the mesh's extent, of a mesh taken as
#: its own mirror image (:meth:`Mirror.exact_partners`): a file's float32 rounding (OBJ, FBX and
#: glTF exports carry ~6e-8 of the extent; MediaPipe's face 7.8e-8), not a sculpted asymmetry
EXACT_GAP = 1e-6


class Mirror:
    """Reflection about the plane through ``point (3,)`` with unit ``normal (3,)`` (mesh units)."""

    def __init__(self, point, normal):
        n = np.asarray(normal, dtype=np.float64)
        self.normal = n / np.linalg.norm(n)
        self.point = np.asarray(point, dtype=np.float64)

    def __call__(self, p: np.ndarray) -> np.ndarray:
        """Points (..., 3) reflected."""
        p = np.asarray(p, dtype=np.float64)
        return p - 2.0 * ((p - self.point) @ self.normal)[..., None] * self.normal

    def direction(self, d: np.ndarray) -> np.ndarray:
        """Directions (..., 3) reflected (no translation)."""
        d = np.asarray(d, dtype=np.float64)
        return d - 2.0 * (d @ self.normal)[..., None] * self.normal

    def partners(self, vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For each of ``vertices (n, 3)``: the index (n,) of the vertex nearest its mirror image,
        and that distance (n,) in mesh units (all 0 for a mesh that is its own mirror image)."""
        from scipy.spatial import cKDTree

        v = np.asarray(vertices, dtype=np.float64)
        d, j = cKDTree(v).query(self(v))
        return j, d

    def exact_partners(self, vertices: np.ndarray, gap: float = EXACT_GAP) -> np.ndarray | None:
        """:meth:`partners` (n,) of ``vertices (n, 3)`` when every vertex has one within ``gap`` x
        the mesh's largest extent (the mesh is its own mirror image up to rounding), else None."""
        v = np.asarray(vertices, dtype=np.float64)
        j, d = self.partners(v)
        return j if d.max() <= gap * float(np.ptp(v, axis=0).max()) else None

    def side(self, p: np.ndarray) -> np.ndarray:
        """Signed distance (...,) of points (..., 3) from the plane (positive: the normal's side)."""
        return (np.asarray(p, dtype=np.float64) - self.point) @ self.normal

    def onto_plane(self, p: np.ndarray) -> np.ndarray:
        """Points (..., 3) moved onto the plane (closest point)."""
        p = np.asarray(p, dtype=np.float64)
        return p - self.side(p)[..., None] * self.normal

    def as_arrays(self) -> dict:
        """``{"mirror_point": (3,), "mirror_normal": (3,)}`` for a stage file."""
        return {"mirror_point": self.point.copy(), "mirror_normal": self.normal.copy()}

    @classmethod
    def from_arrays(cls, arrays) -> "Mirror | None":
        """Inverse of :meth:`as_arrays`; None when ``arrays`` has no mirror (an asymmetric head)."""
        if "mirror_normal" not in arrays or not np.all(np.isfinite(arrays["mirror_normal"])):
            return None
        return cls(arrays["mirror_point"], arrays["mirror_normal"])

