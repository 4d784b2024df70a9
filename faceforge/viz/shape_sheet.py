"""A smooth-shaded contact sheet of named shapes (the bake's ``shapes.png``).

Each panel is the face seen from the front, Gouraud-shaded: a Lambert intensity per vertex from
the area-weighted vertex normals, interpolated across each triangle (matplotlib ``tripcolor``
with ``shading="gouraud"``), triangles drawn back to front (painter's algorithm), those facing
away from the camera left out; a hole one can see through is drawn dark
(:func:`faceforge.viz.smooth.fill_holes`), and the mouth's inside too when the caller gives it. All panels share one frame (the ``region``'s extent at rest), so
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
                color=(0.88, 0.82, 0.74), dim: np.ndarray | None = None) -> Path:
    """Write a grid of smooth-shaded front views of ``frames`` (k, n, 3) (head frame: +Y up, face
    +Z), one per label; ``region`` (n,) bool: the vertices to frame (default all); ``dim`` (n,) in
    [0, 1]: vertices drawn darker (the mouth's inside, :func:`faceforge.viz.smooth.mouth_cavity`,
    which the front light would show lit as the skin; as :func:`faceforge.viz.smooth.draw_smooth`)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LinearSegmentedColormap
    from matplotlib.patches import Rectangle
    from matplotlib.tri import Triangulation

    from faceforge.io.mesh_check import boundary_loops
    from faceforge.viz.smooth import fill_holes

    frames = np.asarray(frames, dtype=float)
    labels = list(labels)
    rows = -(-len(labels) // cols)
    keep = np.ones(frames.shape[1], bool) if region is None else np.asarray(region, bool)
    r = view_matrix("front")
    p = frames[0][keep] @ r.T
    lo, hi = p[:, :2].min(axis=0), p[:, :2].max(axis=0)
    pad = 0.04 * (hi - lo).max()
    lo, hi = lo - pad, hi + pad                 # a panel's view (the same on every panel)
    w, h = hi - lo
    # one axes for every panel (48 axes cost a third of the sheet's CPU time): panel k's view is
    # moved to its cell, (cw, ch) apart, and clipped to it
    cw, ch = 1.05 * w, 1.16 * h
    width = panel * cols
    height = width * (rows * ch) / (cols * cw) + (0.35 if title else 0.05)
    fig = plt.figure(figsize=(width, height), dpi=dpi)
    top = 1.0 - (0.35 if title else 0.05) / height
    ax = fig.add_axes((0.0, 0.0, 1.0, top))
    ax.axis("off")
    cmap = LinearSegmentedColormap.from_list("skin", [(0, 0, 0), color])
    box = (lo - pad, hi + pad)
    loops = boundary_loops(np.asarray(faces, dtype=np.int64))
    for k, (frame, name) in enumerate(zip(frames, labels)):
        xy, tri, shade = smooth_shade(frame, faces)
        if dim is not None:
            shade = shade * (1.0 - 0.85 * np.clip(np.asarray(dim, dtype=float), 0.0, 1.0))
        centre = xy[tri].mean(axis=1)        # only the triangles in the panel (speed)
        tri = tri[np.all((centre >= box[0]) & (centre <= box[1]), axis=1)]
        x0, y0 = (k % cols) * cw, -(k // cols) * ch
        if len(tri):
            at = xy - lo + (x0, y0)
            cell = Rectangle((x0, y0), w, h, transform=ax.transData)
            fill_holes(ax, at, faces, clip=cell, loops=loops)
            art = ax.tripcolor(Triangulation(at[:, 0], at[:, 1], tri), shade, shading="gouraud", cmap=cmap,
                               vmin=0.0, vmax=1.0, rasterized=True)
            art.set_clip_path(cell)
        ax.text(x0 + 0.5 * w, y0 + h + 0.01 * h, name, ha="center", va="bottom", fontsize=9)
    ax.set_xlim(-0.5 * (cw - w), cols * cw - 0.5 * (cw - w))
    ax.set_ylim(-(rows - 1) * ch - 0.02 * h, ch - 0.02 * h)
    ax.set_aspect("equal")
    if title:
        fig.suptitle(title, fontsize=11, y=1.0 - 0.08 / height, va="top")
    out_png = Path(out_png)
    out_png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out_png, pil_kwargs={"compress_level": 3})
    plt.close(fig)
    return out_png
