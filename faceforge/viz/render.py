"""Headless mesh drawing with matplotlib (Agg): flat Lambert shading, painter's order.

Every function works on ``(vertices (n, 3) float, faces (m, 3) int)`` arrays in the
project frame (+Y up, face looking along +Z, subject's left = +X). A *view* maps that
frame to the picture: ``"front"`` looks at the face (camera on +Z), ``"side"`` looks
at the subject's left cheek (camera on +X, so the face points to the picture's left),
``"top"`` looks down from +Y. Triangles of all meshes drawn into one axes are sorted
together by depth, so interleaved layers (skull, muscles) occlude correctly.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import matplotlib

matplotlib.use("Agg")  # headless: no display, no GPU

import numpy as np  # noqa: E402
from matplotlib.collections import PolyCollection  # noqa: E402

#: view name -> (3, 3) rows: picture x axis, picture y axis, towards-camera axis
VIEWS: dict[str, np.ndarray] = {
    "front": np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]),
    "side": np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]]),
    "top": np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]),
}

#: direction towards the light in camera coordinates (upper left, in front)
LIGHT = np.array([-0.35, 0.45, 0.82]) / np.linalg.norm([-0.35, 0.45, 0.82])


def view_matrix(view: str) -> np.ndarray:
    """The (3, 3) rotation of ``view`` (rows: picture x, picture y, towards camera)."""
    try:
        return VIEWS[view]
    except KeyError:
        raise ValueError(f"unknown view {view!r}; valid: {sorted(VIEWS)}") from None


def lambert(normals: np.ndarray, light: np.ndarray = LIGHT, ambient: float = 0.35) -> np.ndarray:
    """Lambert intensity in [ambient, 1] for unit ``normals`` (m, 3) in camera coordinates.

    Two-sided: a face turned away from the camera is lit by its flipped normal, so open
    or inconsistently oriented meshes still read as solid.
    """
    n = normals * np.where(normals[:, 2:3] < 0.0, -1.0, 1.0)
    return ambient + (1.0 - ambient) * np.clip(n @ light, 0.0, 1.0)


@dataclass
class Layer:
    """One mesh to draw: geometry, an RGB(A) colour in [0, 1], optional edge width."""

    vertices: np.ndarray
    faces: np.ndarray
    color: tuple = (0.9, 0.87, 0.8)
    alpha: float = 1.0
    edge_width: float = 0.0
    label: str | None = None
    label_color: tuple = field(default=(0.0, 0.0, 0.0))


def shaded_polygons(layers: list[Layer], view: str):
    """Project and shade ``layers``; return (polygons (k, 3, 2), rgba (k, 4), depth (k,)).

    Triangles are sorted back to front by their centroid depth (painter's algorithm).
    Degenerate triangles (zero area) are dropped.
    """
    r = view_matrix(view)
    polys, colors, depths, widths = [], [], [], []
    for layer in layers:
        v = np.asarray(layer.vertices, dtype=float) @ r.T
        f = np.asarray(layer.faces, dtype=np.int64)
        if len(f) == 0:
            continue
        tri = v[f]
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        length = np.linalg.norm(n, axis=1)
        keep = length > 0.0
        tri, n = tri[keep], n[keep] / length[keep, None]
        shade = lambert(n)
        base = np.array(matplotlib.colors.to_rgba(layer.color, layer.alpha))
        rgba = np.empty((len(tri), 4))
        rgba[:, :3] = np.clip(base[None, :3] * shade[:, None], 0.0, 1.0)
        rgba[:, 3] = base[3]
        polys.append(tri[:, :, :2])
        colors.append(rgba)
        depths.append(tri[:, :, 2].mean(axis=1))
        widths.append(np.full(len(tri), layer.edge_width))
    if not polys:
        return np.zeros((0, 3, 2)), np.zeros((0, 4)), np.zeros(0), np.zeros(0)
    polys, colors = np.concatenate(polys), np.concatenate(colors)
    depths, widths = np.concatenate(depths), np.concatenate(widths)
    order = np.argsort(depths, kind="stable")
    return polys[order], colors[order], depths[order], widths[order]


def draw_layers(ax, layers: list[Layer], view: str, points=None, point_color="crimson",
                point_size: float = 8.0, labels: bool = True) -> None:
    """Draw ``layers`` into matplotlib axes ``ax`` as seen from ``view``.

    Parameters
    ----------
    ax : matplotlib Axes (2D)
    layers : list of Layer, drawn together (depth-sorted across layers)
    view : "front" | "side" | "top"
    points : optional (k, 3) float, markers drawn on top (e.g. landmarks)
    labels : write each layer's ``label`` at its visible centroid
    """
    polys, colors, _, widths = shaded_polygons(layers, view)
    edge = colors.copy()
    edge[:, :3] *= 0.6
    pc = PolyCollection(polys, facecolors=colors, edgecolors=np.where(widths[:, None] > 0, edge, colors),
                        linewidths=np.maximum(widths, 0.15), antialiaseds=False)
    ax.add_collection(pc)
    r = view_matrix(view)
    allv = np.concatenate([np.asarray(l.vertices) for l in layers]) @ r.T
    lo, hi = allv[:, :2].min(axis=0), allv[:, :2].max(axis=0)
    pad = 0.04 * (hi - lo).max()
    ax.set_xlim(lo[0] - pad, hi[0] + pad)
    ax.set_ylim(lo[1] - pad, hi[1] + pad)
    ax.set_aspect("equal")
    ax.axis("off")
    if points is not None and len(points):
        p = np.asarray(points, dtype=float) @ r.T
        ax.scatter(p[:, 0], p[:, 1], s=point_size, c=point_color, zorder=5, linewidths=0)
    if labels:
        for layer in layers:
            if not layer.label:
                continue
            c = (np.asarray(layer.vertices, dtype=float) @ r.T)
            # label only layers that face this camera at least partly
            if view == "side" and c[:, 2].mean() < 0.0:
                continue
            ax.annotate(layer.label, c[:, :2].mean(axis=0), fontsize=5, ha="center", va="center",
                        color=layer.label_color, zorder=6,
                        bbox=dict(boxstyle="round,pad=0.1", fc=(1, 1, 1, 0.6), lw=0))


def render_meshes(out_png, layers: list[Layer], views=("front", "side"), points=None,
                  title: str | None = None, size: float = 5.0, dpi: int = 150) -> None:
    """Write a PNG with one panel per view of ``layers`` (and optional ``points`` (k, 3))."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(views), figsize=(size * len(views), size * 1.1), dpi=dpi)
    axes = np.atleast_1d(axes)
    for ax, view in zip(axes, views):
        draw_layers(ax, layers, view, points=points)
        ax.set_title(view, fontsize=9)
    if title:
        fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    fig.savefig(out_png)
    plt.close(fig)
