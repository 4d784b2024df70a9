"""A small headless z-buffer rasteriser: orthographic views of a mesh.

No OpenGL, no display: one numba pass writes, per pixel, the nearest triangle, its depth
and the barycentric coordinates of the pixel centre in it; what is drawn from those buffers
(a grey picture for the face detector, :mod:`faceforge.landmarks.raster`; the contact sheets'
shaded faces, :mod:`faceforge.viz.zbuffer`) is numpy on them.

Camera (:class:`View`): orthographic, looking along ``direction`` (unit (3,), the face
looks the other way), ``up`` (unit (3,), perpendicular), centred on ``centre`` (3,),
``scale`` pixels per mesh unit, an image of ``size`` x ``size`` pixels. Pixel (col, row)
has its centre at (col + 0.5, row + 0.5); rows grow downwards.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from faceforge.constants import NUMBA_OPTIONS


@dataclass(frozen=True)
class View:
    """An orthographic camera (see the module docstring); all lengths in mesh units."""

    direction: np.ndarray
    up: np.ndarray
    centre: np.ndarray
    scale: float
    size: int

    @property
    def right(self) -> np.ndarray:
        """(3,) the image's +column axis in mesh space (``up x direction``... the viewer's right)."""
        return np.cross(self.direction, self.up)

    def basis(self) -> np.ndarray:
        """(3, 3) rows right, up, direction."""
        return np.array([self.right, self.up, self.direction], dtype=np.float64)

    def project(self, points: np.ndarray) -> np.ndarray:
        """(k, 3) mesh points -> (k, 3) float: column, row (pixels, continuous), depth (mesh units)."""
        local = (np.asarray(points, dtype=np.float64) - self.centre) @ self.basis().T
        half = self.size / 2.0
        return np.column_stack([half + local[:, 0] * self.scale, half - local[:, 1] * self.scale, local[:, 2]])

    def unproject(self, pixels: np.ndarray, depth: np.ndarray) -> np.ndarray:
        """(k, 2) column, row and (k,) depth -> (k, 3) mesh points."""
        pixels = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
        half = self.size / 2.0
        x = (pixels[:, 0] - half) / self.scale
        y = (half - pixels[:, 1]) / self.scale
        return self.centre + np.column_stack([x, y, np.asarray(depth, dtype=np.float64)]) @ self.basis()


@numba.njit(**NUMBA_OPTIONS)
def _rasterise(screen, faces, size, depth, face_id, bary):  # pragma: no cover - twin in tests
    """Z-buffer: for each triangle, each pixel centre inside it (top-left-free: inclusive edges,
    nearer depth wins, ties to the lower triangle id) gets depth, triangle id and barycentrics."""
    for t in range(faces.shape[0]):
        a, b, c = faces[t, 0], faces[t, 1], faces[t, 2]
        x0, y0, z0 = screen[a, 0], screen[a, 1], screen[a, 2]
        x1, y1, z1 = screen[b, 0], screen[b, 1], screen[b, 2]
        x2, y2, z2 = screen[c, 0], screen[c, 1], screen[c, 2]
        area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        if area == 0.0:
            continue
        lo_c = max(int(np.floor(min(x0, min(x1, x2)) - 0.5)), 0)
        hi_c = min(int(np.ceil(max(x0, max(x1, x2)) - 0.5)), size - 1)
        lo_r = max(int(np.floor(min(y0, min(y1, y2)) - 0.5)), 0)
        hi_r = min(int(np.ceil(max(y0, max(y1, y2)) - 0.5)), size - 1)
        for r in range(lo_r, hi_r + 1):
            py = r + 0.5
            for col in range(lo_c, hi_c + 1):
                px = col + 0.5
                w0 = ((x1 - px) * (y2 - py) - (x2 - px) * (y1 - py)) / area
                w1 = ((x2 - px) * (y0 - py) - (x0 - px) * (y2 - py)) / area
                w2 = 1.0 - w0 - w1
                if w0 < 0.0 or w1 < 0.0 or w2 < 0.0:
                    continue
                z = w0 * z0 + w1 * z1 + w2 * z2
                if z < depth[r, col]:
                    depth[r, col] = z
                    face_id[r, col] = t
                    bary[r, col, 0] = w0
                    bary[r, col, 1] = w1
                    bary[r, col, 2] = w2


def rasterise(vertices: np.ndarray, faces: np.ndarray, view: View):
    """Depth, triangle-id and barycentric buffers of ``(vertices (n,3), faces (m,3))`` in ``view``."""
    screen = np.ascontiguousarray(view.project(vertices))
    n = int(view.size)
    depth = np.full((n, n), np.inf)
    face_id = np.full((n, n), -1, dtype=np.int64)
    bary = np.zeros((n, n, 3))
    _rasterise(screen, np.ascontiguousarray(faces, dtype=np.int64), n, depth, face_id, bary)
    return depth, face_id, bary


@numba.njit(**NUMBA_OPTIONS)
def _interpolate(face_id, bary, faces, values, out):  # pragma: no cover - twin in tests
    """out[r, c] = the barycentric mix of ``values`` at the corners of the triangle seen at pixel
    (r, c); left as it is where no triangle is (face_id -1)."""
    for r in range(face_id.shape[0]):
        for col in range(face_id.shape[1]):
            t = face_id[r, col]
            if t < 0:
                continue
            a, b, c = faces[t, 0], faces[t, 1], faces[t, 2]
            w0, w1, w2 = bary[r, col, 0], bary[r, col, 1], bary[r, col, 2]
            for k in range(values.shape[1]):
                out[r, col, k] = w0 * values[a, k] + w1 * values[b, k] + w2 * values[c, k]


def interpolate(values: np.ndarray, faces: np.ndarray, face_id: np.ndarray, bary: np.ndarray) -> np.ndarray:
    """(size, size, c) per-vertex ``values (n, c)`` at each pixel of :func:`rasterise`'s buffers
    ``face_id (size, size)``, ``bary (size, size, 3)``: the barycentric mix of the seen triangle's
    corners (``faces (m, 3)``), 0 where no triangle is."""
    values = np.ascontiguousarray(values, dtype=np.float64)
    out = np.zeros(face_id.shape + values.shape[1:])
    _interpolate(face_id, bary, np.ascontiguousarray(faces, dtype=np.int64), values, out)
    return out
