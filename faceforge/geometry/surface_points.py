"""Surface points (§5.1.1, Fig. 2): a triangle id plus barycentric coordinates.

A surface point carries no position of its own: its position and normal are
recomputed from the current vertices of its triangle, so it follows any
deformation or rigid motion of the mesh it lies on.
"""

from __future__ import annotations

import hashlib
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

from faceforge.constants import FLOAT, INT
from faceforge.geometry.triangles import (
    barycentric,
    check_mesh,
    points_from_barycentric,
    vertex_normals,
)

__all__ = ["SurfacePoints", "SurfaceProjector", "projector", "project_to_surface", "closest_points"]


@dataclass(frozen=True)
class SurfacePoints:
    """``n`` points on a triangle mesh.

    Attributes
    ----------
    face_ids : (n,) int64
        Triangle of each point.
    bary : (n, 3) float64
        Homogeneous barycentric coordinates w.r.t. ``faces[face_ids]`` (sum 1).
    """

    face_ids: np.ndarray
    bary: np.ndarray

    def __post_init__(self):
        ids = np.asarray(self.face_ids, dtype=INT).reshape(-1)
        w = np.asarray(self.bary, dtype=FLOAT).reshape(-1, 3)
        if len(ids) != len(w):
            raise ValueError(f"face_ids {ids.shape} and bary {w.shape} differ in length")
        object.__setattr__(self, "face_ids", ids)
        object.__setattr__(self, "bary", w)

    def __len__(self) -> int:
        return len(self.face_ids)

    def take(self, index) -> "SurfacePoints":
        """The subset (or reordering) ``index`` of these points."""
        return SurfacePoints(self.face_ids[index], self.bary[index])

    @staticmethod
    def concatenate(parts) -> "SurfacePoints":
        """Join several :class:`SurfacePoints` on the same mesh, in order."""
        parts = list(parts)
        if not parts:
            return SurfacePoints(np.zeros(0, INT), np.zeros((0, 3), FLOAT))
        return SurfacePoints(
            np.concatenate([p.face_ids for p in parts]), np.concatenate([p.bary for p in parts])
        )

    def positions(self, vertices, faces) -> np.ndarray:
        """Current positions ``(n, 3) float64``: barycentric blend of the triangle's vertices."""
        return points_from_barycentric(vertices, faces, self.face_ids, self.bary)

    def normals(self, vertices, faces, vnormals=None) -> np.ndarray:
        """Current unit normals ``(n, 3) float64``.

        The barycentric blend of the vertex normals (area-weighted, see
        :func:`~faceforge.geometry.triangles.vertex_normals`), normalized, as
        §5.1.1 prescribes. Pass ``vnormals (V, 3)`` to reuse normals already
        computed for this frame.
        """
        v, f = check_mesh(vertices, faces)
        vn = vertex_normals(v, f) if vnormals is None else np.asarray(vnormals, dtype=FLOAT)
        n = np.einsum("ij,ijk->ik", self.bary, vn[f[self.face_ids]])
        length = np.linalg.norm(n, axis=1, keepdims=True)
        return np.divide(n, length, out=np.zeros_like(n), where=length > 0)


class SurfaceProjector:
    """Closest-point queries (and rays) on one mesh, with the search trees kept.

    The closest points come from a :class:`~faceforge.geometry.closest.TriangleGrid` (a uniform
    grid of the triangles and a compiled search, several times faster than
    ``trimesh.proximity.closest_point``, which also rebuilds an r-tree of the triangles'
    boxes for every fresh mesh); this object builds its grid and ray caster once. The one-shot
    twins are :func:`closest_points` and :func:`project_to_surface`, which reuse a projector
    from a small cache keyed by the mesh's *content* (so equal arrays share one, edited
    arrays never see a stale grid).
    """

    def __init__(self, vertices, faces):
        v, f = check_mesh(vertices, faces)
        if len(f) == 0:
            raise ValueError("cannot project onto a mesh without faces")
        self.vertices, self.faces = v, f
        self._caster = None
        self._tree = None
        self._derived = {}

    @property
    def caster(self):
        """A :class:`~faceforge.geometry.rays.RayCaster` on the same mesh (built on first use)."""
        if self._caster is None:
            from faceforge.geometry.rays import RayCaster

            self._caster = RayCaster(self.vertices, self.faces)
        return self._caster

    @property
    def tree(self):
        """A :class:`~faceforge.geometry.closest.TriangleGrid` of the mesh (built on first use)."""
        if self._tree is None:
            from faceforge.geometry.closest import TriangleGrid

            self._tree = TriangleGrid(self.vertices[self.faces])
        return self._tree

    def derived(self, name: str, compute):
        """``compute(vertices, faces)`` of this mesh, computed once per ``name`` and kept (the
        vertex and face normals, the centre, the mean edge length: every action line of a muscle
        projected onto one layer mesh asks for them again). Read-only arrays come back."""
        if name not in self._derived:
            value = compute(self.vertices, self.faces)
            if isinstance(value, np.ndarray):
                value.setflags(write=False)
            self._derived[name] = value
        return self._derived[name]

    def closest(self, points) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(closest (k, 3), distance (k,), face_ids (k,))`` for ``points (k, 3)``."""
        p = np.asarray(points, dtype=FLOAT).reshape(-1, 3)
        if len(p) == 0:
            return np.zeros((0, 3)), np.zeros(0), np.zeros(0, INT)
        closest, tri = self.tree.closest(p)
        return closest, np.linalg.norm(p - closest, axis=1), tri.astype(INT)

    def project(self, points) -> SurfacePoints:
        """Surface points at the closest points (see :func:`project_to_surface`)."""
        closest, _, tri = self.closest(points)
        w = barycentric(closest, self.vertices, self.faces, tri)
        w = np.clip(w, 0.0, None)
        s = w.sum(axis=1, keepdims=True)
        w = np.divide(w, s, out=np.full_like(w, 1.0 / 3.0), where=s > 0)
        return SurfacePoints(tri, w)


_CACHE: "OrderedDict[tuple, SurfaceProjector]" = OrderedDict()
_CACHE_SIZE = 8


def projector(vertices, faces) -> SurfaceProjector:
    """A :class:`SurfaceProjector` for this mesh, shared while the content is unchanged."""
    v, f = check_mesh(vertices, faces)
    digest = hashlib.blake2b(np.ascontiguousarray(v).tobytes(), digest_size=16)
    digest.update(np.ascontiguousarray(f).tobytes())
    key = (v.shape, f.shape, digest.hexdigest())
    hit = _CACHE.get(key)
    if hit is None:
        hit = _CACHE[key] = SurfaceProjector(v, f)
        while len(_CACHE) > _CACHE_SIZE:
            _CACHE.popitem(last=False)
    else:
        _CACHE.move_to_end(key)
    return hit


def closest_points(points, vertices, faces) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Closest point of the mesh to each query point.

    Uses a :class:`~faceforge.geometry.closest.TriangleGrid` (a uniform grid of the
    triangles plus the exact point-triangle distance), through :func:`projector`. Returns
    ``(closest (k, 3), distance (k,), face_ids (k,))``.
    """
    return projector(vertices, faces).closest(points)


def project_to_surface(points, vertices, faces) -> SurfacePoints:
    """Surface points at the closest point of the mesh to each of ``points (k, 3)``.

    The barycentric coordinates of the closest point are clipped to the
    triangle (tiny negative values from round-off) and renormalized, so the
    result lies exactly on the surface.
    """
    return projector(vertices, faces).project(points)
