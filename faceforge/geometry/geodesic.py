"""Geodesic distance on a triangle mesh (heat method, potpourri3d).

potpourri3d's solver needs a mesh without unreferenced vertices and answers
within one connected component. :func:`geodesic_distance` therefore removes
unreferenced vertices, splits the mesh into connected components, solves in
each component that contains a source, and reports ``inf`` for vertices that
no source can reach (other components, unreferenced vertices).
"""

from __future__ import annotations

import numpy as np

from faceforge.constants import FLOAT, INT
from faceforge.geometry.triangles import check_mesh, vertex_components

__all__ = ["GeodesicSolver", "geodesic_distance"]


class GeodesicSolver:
    """Heat-method geodesic distances on ``(vertices (n, 3), faces (m, 3))``.

    The per-component heat solvers are factored lazily on first use and kept,
    so repeated queries on the same mesh are cheap.
    """

    def __init__(self, vertices, faces, t_coef: float = 1.0):
        v, f = check_mesh(vertices, faces)
        if len(f) == 0:
            raise ValueError("geodesic distance needs a mesh with faces")
        self.vertices, self.faces, self.t_coef = v, f, t_coef
        self.labels = vertex_components(len(v), f)
        self._solvers: dict[int, tuple] = {}

    def _solver(self, label: int):
        if label not in self._solvers:
            import potpourri3d as pp3d

            verts = np.flatnonzero(self.labels == label)
            local = np.full(len(self.vertices), -1, INT)
            local[verts] = np.arange(len(verts))
            fmask = self.labels[self.faces[:, 0]] == label
            lf = local[self.faces[fmask]]
            solver = pp3d.MeshHeatMethodDistanceSolver(self.vertices[verts], lf, t_coef=self.t_coef)
            self._solvers[label] = (verts, local, solver)
        return self._solvers[label]

    def distance(self, sources) -> np.ndarray:
        """Distance ``(n,) float64`` from the nearest of the vertex ids ``sources``.

        ``inf`` where no source shares the vertex's component. Raises
        ``ValueError`` for out-of-range ids or a source on an unreferenced vertex.
        """
        src = np.unique(np.asarray(sources, dtype=INT).reshape(-1))
        n = len(self.vertices)
        if len(src) == 0:
            raise ValueError("geodesic distance needs at least one source vertex")
        if src.min() < 0 or src.max() >= n:
            raise ValueError(f"source vertex ids must lie in [0, {n})")
        if np.any(self.labels[src] < 0):
            raise ValueError("a source vertex is referenced by no face")
        out = np.full(n, np.inf, FLOAT)
        for label in np.unique(self.labels[src]):
            verts, local, solver = self._solver(int(label))
            s = local[src[self.labels[src] == label]]
            d = solver.compute_distance_multisource(s) if len(s) > 1 else solver.compute_distance(s[0])
            out[verts] = np.maximum(np.asarray(d, FLOAT), 0.0)
        return out


def geodesic_distance(vertices, faces, sources, t_coef: float = 1.0) -> np.ndarray:
    """One-shot :meth:`GeodesicSolver.distance`."""
    return GeodesicSolver(vertices, faces, t_coef).distance(sources)
