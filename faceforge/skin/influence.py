"""The influence map (§8, Fig. 9): how much each skin vertex follows the simulation.

The skin's displacement is not propagated to the back of the head. The
geodesic distance ``d`` over the skin (heat method,
:mod:`faceforge.geometry.geodesic`) from the *sources* -- skin vertices
anchored to a muscle or to the mandible -- is normalised by ``D``, the
geodesic distance from the anchored region to the back of the head: the
distance at FDP 11.6 (back of skull) when the head has it, else the largest
finite distance on the skin. With ``t = clip(d / D, 0, 1)`` the weight is

    w = 1 - (3 t^2 - 2 t^3)        (a smoothstep: w = 1 at the sources,
                                     w = 0 from the back of the head on,
                                     zero slope at both ends)

Vertices no source can reach (another connected component) get ``w = 0``.
The animated skin is ``rest + w * (simulated - rest)`` (:func:`apply_influence`).
"""

from __future__ import annotations

import numpy as np

from faceforge.constants import FLOAT, INT
from faceforge.geometry.geodesic import geodesic_distance

__all__ = ["influence_weights", "apply_influence", "smoothstep_falloff", "save_influence_png"]


def smoothstep_falloff(t) -> np.ndarray:
    """``1 - smoothstep(clip(t, 0, 1))``: 1 at t <= 0, 0 at t >= 1; ``(n,) float64``."""
    t = np.clip(np.asarray(t, FLOAT), 0.0, 1.0)
    return 1.0 - t * t * (3.0 - 2.0 * t)


def influence_weights(vertices, faces, sources, back_vertex: int | None = None):
    """Influence weight of every skin vertex.

    Parameters
    ----------
    vertices : (n, 3) float
    faces : (m, 3) int
    sources : (s,) int
        Skin vertices anchored to a muscle or to the mandible.
    back_vertex : int, optional
        Vertex at the back of the head (FDP 11.6); its geodesic distance is
        the normalisation ``D``. Default: the largest finite distance.

    Returns
    -------
    weights : (n,) float64 in [0, 1]
    distance : (n,) float64
        Geodesic distance from the sources (``inf`` where unreachable).
    scale : float
        The normalisation ``D`` (skin units).
    """
    v = np.asarray(vertices, FLOAT)
    src = np.unique(np.asarray(sources, INT).reshape(-1))
    if len(src) == 0:
        return np.zeros(len(v)), np.full(len(v), np.inf), 0.0
    # a vertex no face references (a stray vertex, or one whose degenerate faces the mesh
    # check dropped) spreads nothing over the surface; it keeps its own weight 1 below
    referenced = np.zeros(len(v), bool)
    referenced[np.asarray(faces, INT).reshape(-1)] = True
    on_surface = src[referenced[src]]
    if len(on_surface) == 0:
        w = np.zeros(len(v))
        w[src] = 1.0
        return w, np.full(len(v), np.inf), 0.0
    d = geodesic_distance(v, faces, on_surface)
    finite = np.isfinite(d)
    scale = 0.0
    if back_vertex is not None and np.isfinite(d[back_vertex]):
        scale = float(d[back_vertex])
    if scale <= 0.0 and finite.any():
        scale = float(d[finite].max())
    if scale <= 0.0:
        w = np.where(finite, 1.0, 0.0)
    else:
        w = np.where(finite, smoothstep_falloff(np.where(finite, d, 0.0) / scale), 0.0)
    w[src] = 1.0
    return w, d, scale


def apply_influence(rest, simulated, weights) -> np.ndarray:
    """Weighted displacement ``rest + w[:, None] * (simulated - rest)``, ``(n, 3)``."""
    r = np.asarray(rest, FLOAT)
    s = np.asarray(simulated, FLOAT)
    w = np.asarray(weights, FLOAT).reshape(-1, 1)
    if r.shape != s.shape or len(w) != len(r):
        raise ValueError(f"rest {r.shape}, simulated {s.shape} and weights {w.shape} disagree")
    return r + w * (s - r)


def save_influence_png(path, vertices, faces, weights, title: str = "influence map") -> None:
    """Front and side views of the skin coloured by weight (red 1 = direct control,
    blue 0 = no control, as Fig. 9). Headless (matplotlib Agg)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection

    v = np.asarray(vertices, FLOAT)
    f = np.asarray(faces, INT)
    w = np.asarray(weights, FLOAT)
    cmap = plt.get_cmap("jet")
    fig, axes = plt.subplots(1, 2, figsize=(10, 5.4))
    # (horizontal axis, depth axis, sign): front looks along -Z, side from +X
    for ax, (hx, depth, label) in zip(axes, ((0, 2, "front"), (2, 0, "side (left)"))):
        tri = v[f]
        order = np.argsort(tri[:, :, depth].mean(axis=1))  # painter's algorithm
        tri = tri[order]
        # back-face culling: keep faces whose normal points to the viewer
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        vis = n[:, depth] > 0
        polys = tri[vis][:, :, [hx, 1]]
        if hx == 2:
            polys = polys * np.array([-1.0, 1.0])  # side view: face to the left
        colours = cmap(w[f[order][vis]].mean(axis=1))
        ax.add_collection(PolyCollection(polys, facecolors=colours, edgecolors="none", linewidths=0))
        ax.autoscale()
        ax.set_aspect("equal")
        ax.set_axis_off()
        ax.set_title(label)
    sm = plt.cm.ScalarMappable(cmap=cmap, norm=plt.Normalize(0, 1))
    fig.colorbar(sm, ax=axes, shrink=0.7, label="influence (1 = direct control)")
    fig.suptitle(title)
    fig.savefig(path, dpi=90)
    plt.close(fig)
