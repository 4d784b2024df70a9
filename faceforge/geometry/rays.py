"""Ray casting against a triangle mesh (trimesh, with Embree when installed).

:class:`RayCaster` holds the acceleration structure of one mesh; the one-shot
twin :func:`first_hit` builds it for a single query.
"""

from __future__ import annotations

import numpy as np

from faceforge.constants import FLOAT, INT
from faceforge.geometry.triangles import check_mesh

__all__ = ["RayCaster", "first_hit", "has_embree"]


def has_embree() -> bool:
    """True when trimesh can use Embree (package ``embreex``)."""
    try:
        from trimesh.ray import ray_pyembree  # noqa: F401
    except Exception:  # ImportError, or embree's own load error
        return False
    return True


class RayCaster:
    """Intersect rays with the mesh ``(vertices (n, 3), faces (m, 3))``.

    Parameters
    ----------
    use_embree : bool or None
        None: Embree when importable, else trimesh's pure-Python r-tree engine.
        The engine actually used is ``self.engine`` ("embree" or "triangle").
    """

    def __init__(self, vertices, faces, use_embree: bool | None = None):
        import trimesh

        v, f = check_mesh(vertices, faces)
        self.vertices, self.faces = v, f
        self.mesh = trimesh.Trimesh(v, f, process=False, validate=False)
        if use_embree is None:
            use_embree = has_embree()
        if use_embree:
            from trimesh.ray.ray_pyembree import RayMeshIntersector

            self.engine = "embree"
        else:
            from trimesh.ray.ray_triangle import RayMeshIntersector

            self.engine = "triangle"
        self._intersector = RayMeshIntersector(self.mesh)

    @staticmethod
    def _rays(origins, directions):
        o = np.asarray(origins, dtype=FLOAT).reshape(-1, 3)
        d = np.asarray(directions, dtype=FLOAT).reshape(-1, 3)
        if len(d) == 1 and len(o) > 1:
            d = np.repeat(d, len(o), axis=0)
        if len(o) != len(d):
            raise ValueError(f"origins {o.shape} and directions {d.shape} differ in length")
        length = np.linalg.norm(d, axis=1, keepdims=True)
        if np.any(length == 0):
            raise ValueError("ray directions must be non-zero")
        return o, d / length

    def all_hits(self, origins, directions):
        """Every intersection along every ray.

        Returns ``(ray_ids (h,), face_ids (h,), points (h, 3), distances (h,))``
        sorted by ray, then by distance from the origin.
        """
        o, d = self._rays(origins, directions)
        if len(o) == 0:
            return np.zeros(0, INT), np.zeros(0, INT), np.zeros((0, 3)), np.zeros(0)
        tri, ray, loc = self._intersector.intersects_id(
            o, d, multiple_hits=True, return_locations=True
        )
        tri = np.asarray(tri, INT)
        ray = np.asarray(ray, INT)
        loc = np.asarray(loc, FLOAT).reshape(-1, 3)
        dist = np.einsum("ij,ij->i", loc - o[ray], d[ray])
        order = np.lexsort((dist, ray))
        return ray[order], tri[order], loc[order], dist[order]

    def first_hit(self, origins, directions, max_distance: float = np.inf):
        """Nearest intersection in front of each origin (distance >= 0).

        Returns ``(face_ids (k,) int64, points (k, 3), distances (k,))``; rays that
        miss or hit farther than ``max_distance`` get face -1, NaN point and
        ``inf`` distance.
        """
        o, d = self._rays(origins, directions)
        k = len(o)
        face = np.full(k, -1, INT)
        point = np.full((k, 3), np.nan)
        dist = np.full(k, np.inf)
        ray, tri, loc, t = self.all_hits(o, d)
        keep = (t >= 0) & (t <= max_distance)
        ray, tri, loc, t = ray[keep], tri[keep], loc[keep], t[keep]
        if len(ray):
            first = np.r_[True, ray[1:] != ray[:-1]]
            r = ray[first]
            face[r], point[r], dist[r] = tri[first], loc[first], t[first]
        return face, point, dist


def first_hit(vertices, faces, origins, directions, max_distance: float = np.inf):
    """One-shot :meth:`RayCaster.first_hit`."""
    return RayCaster(vertices, faces).first_hit(origins, directions, max_distance)
