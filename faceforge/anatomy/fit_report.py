"""Checks of a fit: how deep the skull and muscles lie beneath the skin.

Inside test (:func:`depth_below_skin`). For a watertight skin the sign comes from
ray parity (``trimesh.Trimesh.contains``). Heads are usually open (neck, eyes, mouth;
a face mask is all open), so otherwise the sign is that of the offset from the
closest skin point along the skin's smooth normal there (interpolated area-weighted
vertex normals): positive beneath the skin. A point whose closest skin point lies on
the skin's boundary (beyond the edge of a mask, through an eye hole) is *not covered*:
no skin is above it, so it is neither inside nor outside and is left out of the
fractions (the back of the skull need not fit, §7). A point on the outer side of its
closest skin point whose ray along that outward normal meets the skin again lies in a
pocket the skin wraps around (a modelled mouth cavity or eye socket: teeth and orbits
belong there) and counts as inside, at depth 0.
"""

from __future__ import annotations

import numpy as np


def depth_below_skin(points: np.ndarray, skin) -> tuple[np.ndarray, np.ndarray]:
    """Signed depth (k,) float (positive beneath the skin, head units; 0 in a pocket) and
    covered (k,) bool; see :func:`faceforge.anatomy.fit.signed_skin_depth`."""
    from faceforge.anatomy.fit import signed_skin_depth

    depth, _, _, covered, _ = signed_skin_depth(points, skin)
    return depth, covered


def inside_stats(depth: np.ndarray, covered: np.ndarray, diagonal: float, tol: float = 0.0) -> dict:
    """Summary of signed depths: fraction inside (depth > -tol), worst poke, min/median."""
    d = depth[covered]
    if len(d) == 0:
        return {"count": 0, "inside_fraction": None, "max_outside": 0.0, "max_outside_rel": 0.0,
                "min_depth": None, "median_depth": None}
    poke = float(max(0.0, -d.min()))
    return {
        "count": int(len(d)),
        "inside_fraction": float(np.mean(d >= -tol)),
        "max_outside": poke,
        "max_outside_rel": poke / diagonal,
        "min_depth": float(d.min()),
        "median_depth": float(np.median(d)),
    }


def landmark_residuals(fdps, reached: np.ndarray, targets: np.ndarray, diagonal: float) -> dict:
    """``{fdp: distance / diagonal}`` between reached (n, 3) and target (n, 3) points."""
    r = np.linalg.norm(np.asarray(reached) - np.asarray(targets), axis=1) / diagonal
    return {f: float(x) for f, x in zip(fdps, r)}


def save_fit_png(path, skin_v, skin_f, layers: list, title: str = "fit") -> None:
    """Front and side pictures: ``layers`` [(vertices, faces, rgb)] inside the translucent skin.

    Uses :func:`faceforge.viz.render.render_meshes` (painter's algorithm, Agg).
    """
    from faceforge.viz.render import Layer, render_meshes

    drawn = [Layer(v, f, color=c, label=name) for name, v, f, c in layers]
    drawn.append(Layer(skin_v, skin_f, color=(0.95, 0.78, 0.68), alpha=0.25, label="skin"))
    render_meshes(path, drawn, views=("front", "side"), title=title)
