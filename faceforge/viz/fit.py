"""The fit stage's picture (Fig. 8b): skull and muscles inside the translucent skin."""

from __future__ import annotations


def save_fit_png(path, skin_v, skin_f, layers: list, title: str = "fit", points=None) -> None:
    """Front and side pictures: ``layers`` [(name, vertices, faces, rgb)] inside the translucent
    skin, with optional ``points`` (k, 3) (the landmark targets, as in Fig. 8).

    Uses :func:`faceforge.viz.render.render_meshes` (painter's algorithm, Agg).
    """
    from faceforge.viz.render import Layer, render_meshes

    drawn = [Layer(v, f, color=c) for name, v, f, c in layers]
    drawn.append(Layer(skin_v, skin_f, color=(0.95, 0.78, 0.68), alpha=0.25))
    render_meshes(path, drawn, views=("front", "side"), title=title, points=points)
