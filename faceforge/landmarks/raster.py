"""What the face detector sees: a Lambert-shaded grey picture of the mesh from the z-buffer
(:mod:`faceforge.geometry.raster`: the camera :class:`View` and :func:`rasterise` are there), and
the surface point under a pixel for back-projection."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from faceforge.geometry.raster import View, rasterise

__all__ = ["Render", "View", "rasterise", "render", "surface_at"]


@dataclass
class Render:
    """The buffers of one view.

    image : (size, size) uint8 grey picture; depth : (size, size) float (inf: background);
    face_id : (size, size) int64 (-1: background); bary : (size, size, 3) float.
    """

    view: View
    image: np.ndarray
    depth: np.ndarray
    face_id: np.ndarray
    bary: np.ndarray

    def rgb(self) -> np.ndarray:
        """(size, size, 3) uint8, the grey picture in three channels."""
        return np.ascontiguousarray(np.repeat(self.image[:, :, None], 3, axis=2))


def render(vertices: np.ndarray, faces: np.ndarray, vertex_normals: np.ndarray, view: View,
           ambient: float = 0.15, raise_light: float = 0.35) -> Render:
    """Lambert-shaded grey picture of the mesh (smooth normals, two-sided, a light at the camera
    raised by ``raise_light`` along the view's up; 0: a head light, the same picture for every
    ``up``), with its buffers. ``vertex_normals (n, 3)`` unit."""
    depth, face_id, bary = rasterise(vertices, faces, view)
    hit = face_id >= 0
    tri = faces[face_id[hit]]
    normal = np.einsum("kj,kjd->kd", bary[hit], vertex_normals[tri])
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
    light = -view.direction + raise_light * view.up
    light = light / np.linalg.norm(light)
    shade = ambient + (1.0 - ambient) * np.abs(normal @ light)
    image = np.zeros(depth.shape, dtype=np.uint8)
    image[hit] = np.clip(np.round(40 + 200 * shade), 0, 255).astype(np.uint8)
    return Render(view, image, depth, face_id, bary)


def surface_at(render_: Render, faces: np.ndarray, vertices: np.ndarray, rows: np.ndarray,
               cols: np.ndarray) -> np.ndarray:
    """(k, 3) mesh points seen at integer pixels ``rows, cols (k,)`` (NaN on background)."""
    fid = render_.face_id[rows, cols]
    out = np.full((len(rows), 3), np.nan)
    ok = fid >= 0
    out[ok] = np.einsum("kj,kjd->kd", render_.bary[rows[ok], cols[ok]], vertices[faces[fid[ok]]])
    return out
