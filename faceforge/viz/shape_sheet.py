"""A smooth-shaded contact sheet of named shapes (the bake's ``shapes.png``).

Each panel is the face seen from the front, Gouraud-shaded: a Lambert intensity per vertex from
the area-weighted vertex normals, interpolated across each triangle (matplotlib ``tripcolor``
with ``shading="gouraud"``), triangles drawn back to front (painter's algorithm), those facing
away from the camera left out. All panels share one frame (the ``region``'s extent at rest), so
a shape's motion is visible as motion against the others.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from faceforge.viz.render import LIGHT, view_matrix


def smooth_shade(vertices: np.ndarray, faces: np.ndarray, view: str = "front", ambient: float = 0.3):
    """Projected vertices (n, 2), visible triangles back to front (k, 3), per-vertex intensity
    (n,) in [ambient, 1]. vertices (n, 3) float, faces (m, 3) int."""
    from faceforge.geometry.triangles import vertex_normals

    r = view_matrix(view)
    v = np.asarray(vertices, dtype=float) @ r.T
    f = np.asarray(faces, dtype=np.int64)
    n = np.asarray(vertex_normals(v, f), dtype=float)
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    shade = ambient + (1.0 - ambient) * np.clip(np.abs(n @ LIGHT), 0.0, 1.0)
    tri = v[f]
    fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area2 = np.abs(fn[:, 2])
    keep = (fn[:, 2] > 0.0) & (area2 > 1e-12 * max(float(area2.max(initial=0.0)), 1e-300))
    order = np.argsort(tri[keep][:, :, 2].mean(axis=1), kind="stable")
    return v[:, :2], f[keep][order], shade


def shape_sheet(out_png, frames: np.ndarray, faces: np.ndarray, labels, region: np.ndarray | None = None,
                cols: int = 8, panel: float = 3.0, dpi: int = 110, title: str | None = None,
                color=(0.88, 0.82, 0.74)) -> Path:
    """Write a grid of smooth-shaded front views of ``frames`` (k, n, 3) (head frame: +Y up, face
    +Z), one per label; ``region`` (n,) bool: the vertices to frame (default all)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LinearSegmentedColormap
    from matplotlib.tri import Triangulation

    frames = np.asarray(frames, dtype=float)
    labels = list(labels)
    rows = -(-len(labels) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(panel * cols, panel * 1.1 * rows), dpi=dpi, squeeze=False)
    keep = np.ones(frames.shape[1], bool) if region is None else np.asarray(region, bool)
    r = view_matrix("front")
    p = frames[0][keep] @ r.T
    lo, hi = p[:, :2].min(axis=0), p[:, :2].max(axis=0)
    pad = 0.04 * (hi - lo).max()
    cmap = LinearSegmentedColormap.from_list("skin", [(0, 0, 0), color])
    for ax in axes.ravel():
        ax.axis("off")
    box = (lo - 2 * pad, hi + 2 * pad)
    for ax, frame, name in zip(axes.ravel(), frames, labels):
        xy, tri, shade = smooth_shade(frame, faces)
        centre = xy[tri].mean(axis=1)        # only the triangles in the panel (speed)
        tri = tri[np.all((centre >= box[0]) & (centre <= box[1]), axis=1)]
        if len(tri):
            ax.tripcolor(Triangulation(xy[:, 0], xy[:, 1], tri), shade, shading="gouraud", cmap=cmap,
                         vmin=0.0, vmax=1.0, rasterized=True)
        ax.set_xlim(lo[0] - pad, hi[0] + pad)
        ax.set_ylim(lo[1] - pad, hi[1] + pad)
        ax.set_aspect("equal")
        # a label placed in axes coordinates: set_title and tight_layout measured every axis's
        # tick boxes (two thirds of the sheet's CPU time on 43 panels, MakeHuman's bake)
        ax.text(0.5, 1.01, name, transform=ax.transAxes, ha="center", va="bottom", fontsize=9)
    top = 1.0 - (0.6 if title else 0.3) / (panel * 1.1 * rows)
    if title:
        fig.suptitle(title, fontsize=11, y=1.0 - 0.08 / (panel * 1.1 * rows), va="top")
    fig.subplots_adjust(left=0.01, right=0.99, bottom=0.01, top=top, wspace=0.05, hspace=0.12)
    out_png = Path(out_png)
    out_png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out_png, pil_kwargs={"compress_level": 3})
    plt.close(fig)
    return out_png
