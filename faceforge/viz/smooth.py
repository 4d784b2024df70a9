"""Smooth-shaded (Gouraud) renders and displacement heat maps for the contact sheets.

The flat painter's renderer (:mod:`faceforge.viz.render`) gives each triangle one colour, so
a dense face reads as facets and a crease is hard to tell from a triangle edge. Here each
vertex is lit with its area-weighted normal (:func:`faceforge.geometry.triangles.vertex_normals`)
and matplotlib interpolates across the triangle (``tripcolor(shading="gouraud")``), triangles
drawn back to front by centroid depth. A heat map colours each vertex by its displacement from
a reference pose instead.
"""

from __future__ import annotations

import numpy as np

from faceforge.viz.render import LIGHT, view_matrix

#: skin tone at full light; the shade scales it
SKIN = np.array([0.93, 0.86, 0.78])


def _project(vertices, faces, view: str):
    """Camera coordinates (n, 3) and the triangles (k, 3) facing the camera, back to front."""
    v = np.asarray(vertices, dtype=float) @ view_matrix(view).T
    f = np.asarray(faces, dtype=np.int64)
    t = v[f]
    n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    keep = np.linalg.norm(n, axis=1) > 0.0
    f = f[keep]
    order = np.argsort(v[f][:, :, 2].mean(axis=1), kind="stable")
    return v, f[order]


def draw_smooth(ax, vertices: np.ndarray, faces: np.ndarray, view: str = "front",
                ambient: float = 0.3) -> None:
    """Draw the mesh ``vertices (n, 3)``, ``faces (m, 3)`` smooth-shaded into ``ax``."""
    from matplotlib.colors import LinearSegmentedColormap

    from faceforge.geometry.triangles import vertex_normals

    v, f = _project(vertices, faces, view)
    n = vertex_normals(v, np.asarray(faces, dtype=np.int64))
    n = n * np.where(n[:, 2:3] < 0.0, -1.0, 1.0)
    light = ambient + (1.0 - ambient) * np.clip(n @ LIGHT, 0.0, 1.0)
    cmap = LinearSegmentedColormap.from_list("skin", [(0, 0, 0), tuple(SKIN)])
    ax.tripcolor(v[:, 0], v[:, 1], f, light, shading="gouraud", cmap=cmap, vmin=0.0, vmax=1.0,
                 rasterized=True)


def draw_heat(ax, vertices: np.ndarray, rest: np.ndarray, faces: np.ndarray, scale: float,
              view: str = "front", cmap: str = "inferno"):
    """Draw the mesh at ``vertices`` coloured by each vertex's distance from ``rest`` (n, 3),
    ``scale`` (same units) the top of the colour scale. Returns the mappable (for a colour bar)."""
    v, f = _project(vertices, faces, view)
    d = np.linalg.norm(np.asarray(vertices, float) - np.asarray(rest, float), axis=1)
    return ax.tripcolor(v[:, 0], v[:, 1], f, d, shading="gouraud", cmap=cmap, vmin=0.0,
                        vmax=max(float(scale), 1e-30), rasterized=True)
