"""A smooth-shaded contact sheet of named shapes (the bake's ``shapes.png``).

Each panel is the face seen from the front through a z-buffer (:mod:`faceforge.viz.zbuffer`): at
each pixel the nearest surface, lit with the area-weighted vertex normals interpolated across its
triangle (two-sided); a hole one can see through is drawn dark
(:func:`faceforge.viz.smooth.fill_holes`), and the mouth's inside too when the caller gives it.
All panels share one frame (the ``region``'s extent at rest), so a shape's motion is visible as
motion against the others.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from faceforge.viz.render import LIGHT, view_matrix


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
    from matplotlib.patches import Rectangle

    from faceforge.io.mesh_check import boundary_loops
    from faceforge.viz.smooth import fill_holes
    from faceforge.viz.zbuffer import shade, show

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
    px = int(round(2 * panel * dpi))                # rasterised at twice a panel's pixels
    faces = np.asarray(faces, dtype=np.int64)
    loops = boundary_loops(faces)
    for k, (frame, name) in enumerate(zip(frames, labels)):
        cam = frame @ r.T
        light, face_id, extent = shade(cam, faces, (lo, hi), px, LIGHT, 0.3, dim)
        x0, y0 = (k % cols) * cw, -(k // cols) * ch
        cell = Rectangle((x0, y0), w, h, transform=ax.transData)
        shift = np.array([x0 - lo[0], x0 - lo[0], y0 - lo[1], y0 - lo[1]])
        fill_holes(ax, cam[:, :2] - lo + (x0, y0), faces, clip=cell, loops=loops)
        show(ax, light[:, :, None] * np.asarray(color), face_id, tuple(np.asarray(extent) + shift), clip=cell)
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
