"""The contact sheets' faces drawn through a z-buffer (:mod:`faceforge.geometry.raster`), not by
painting triangles back to front.

Painting sorts whole triangles by their centroid's depth, so where two surfaces touch (lips
pressed together, a lid closing on the lower lid) a triangle of the hidden one is painted over
the visible one, and the seam reads as a row of teeth. Here each pixel shows the surface nearest
the camera, and what is drawn there is interpolated from the triangle's corners with the pixel's
barycentric coordinates: a light from the vertex normals (Phong: the normal interpolated, then
lit), a darkening (the mouth's inside), a heat value. Camera coordinates throughout: x right, y
up, z toward the viewer (:func:`faceforge.viz.render.view_matrix`); the picture is a square of
``px`` pixels covering ``box``, transparent where no triangle is, drawn with ``imshow`` over the
holes' fill (:func:`faceforge.viz.smooth.fill_holes`).
"""

from __future__ import annotations

import numpy as np

from faceforge.geometry.raster import interpolate

#: the pictures are rasterised at this many pixels a side unless the caller says (a 3.2 in panel at
#: 120 dpi is 384 pixels: about twice that, so matplotlib's downsampling smooths the edges)
PX = 768


def panel_buffers(cam: np.ndarray, faces: np.ndarray, box, px: int = PX):
    """Z-buffer of ``cam (n, 3)`` (camera coordinates), ``faces (m, 3)`` over the square around
    ``box = (lo (2,), hi (2,))`` (its larger side, centred): ``face_id (px, px)`` int64 (-1: no
    triangle), ``bary (px, px, 3)``, and the square's ``extent (x0, x1, y0, y1)`` for ``imshow``."""
    from faceforge.geometry.raster import View, rasterise

    lo, hi = np.asarray(box[0], dtype=float), np.asarray(box[1], dtype=float)
    side = float(max(hi - lo))
    cx, cy = 0.5 * (lo + hi)
    view = View(np.array([0.0, 0.0, -1.0]), np.array([0.0, 1.0, 0.0]), np.array([cx, cy, 0.0]),
                px / max(side, 1e-300), int(px))
    _, face_id, bary = rasterise(np.asarray(cam, dtype=np.float64), np.asarray(faces, dtype=np.int64), view)
    half = 0.5 * side
    return face_id, bary, (cx - half, cx + half, cy - half, cy + half)


def lit(cam: np.ndarray, faces: np.ndarray, face_id: np.ndarray, bary: np.ndarray, light: np.ndarray,
        ambient: float) -> np.ndarray:
    """(px, px) light in [ambient, 1] at each pixel: the vertex normals of ``cam (n, 3)``
    interpolated, normalised and turned toward the camera (two-sided: a hole's far wall is lit as
    its inside), ``ambient + (1 - ambient) max(0, n . light)``; ``light (3,)`` unit."""
    from faceforge.geometry.triangles import vertex_normals

    n = interpolate(vertex_normals(np.asarray(cam, dtype=float), np.asarray(faces, dtype=np.int64)), faces,
                    face_id, bary)
    length = np.sqrt(np.einsum("rck,rck->rc", n, n))
    cos = (n @ np.asarray(light, dtype=float)) * np.where(n[:, :, 2] < 0.0, -1.0, 1.0) / np.maximum(length, 1e-300)
    return ambient + (1.0 - ambient) * np.clip(cos, 0.0, 1.0)


def shade(cam: np.ndarray, faces: np.ndarray, box, px: int, light: np.ndarray, ambient: float,
          dim: np.ndarray | None = None):
    """The skin's light over a panel: :func:`panel_buffers` of ``cam (n, 3)``, ``faces (m, 3)``,
    ``box``, ``px``, then :func:`lit`, times ``1 - 0.85 dim`` interpolated where ``dim (n,)`` in
    [0, 1] darkens vertices (the mouth's inside). Returns ``(light (px, px), face_id (px, px),
    extent)``."""
    face_id, bary, extent = panel_buffers(cam, faces, box, px)
    out = lit(cam, faces, face_id, bary, light, ambient)
    if dim is not None:
        d = np.clip(np.asarray(dim, dtype=float), 0.0, 1.0)
        out = out * (1.0 - 0.85 * interpolate(d[:, None], faces, face_id, bary)[:, :, 0])
    return out, face_id, extent


def show(ax, rgb: np.ndarray, face_id: np.ndarray, extent, clip=None):
    """Draw ``rgb (px, px, 3)`` in [0, 1] into ``ax`` at ``extent``, transparent where
    ``face_id`` is -1, above the holes' fill (zorder 1); clipped to the patch ``clip`` if given."""
    rgba = np.empty(face_id.shape + (4,), dtype=np.uint8)
    rgba[:, :, :3] = np.round(255.0 * np.clip(rgb, 0.0, 1.0))
    rgba[:, :, 3] = np.where(face_id >= 0, 255, 0)
    art = ax.imshow(rgba, extent=extent, origin="upper", interpolation="antialiased", zorder=1)
    if clip is not None:
        art.set_clip_path(clip)
    return art
