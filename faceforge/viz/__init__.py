"""Headless pictures (matplotlib Agg): meshes, the template skull and muscle map.

``render_template(skull, muscles, out_png, jaw=(pitch, yaw, protrusion), contractions=None)``
lives in :mod:`faceforge.viz.template`; generic mesh drawing in :mod:`faceforge.viz.render`.
Imported lazily so that ``import faceforge.viz`` does not load matplotlib.
"""

from __future__ import annotations

__all__ = ["render_template", "render_meshes", "Layer"]


def __getattr__(name):
    if name == "render_template":
        from faceforge.viz.template import render_template

        return render_template
    if name in ("render_meshes", "Layer"):
        from faceforge.viz import render

        return getattr(render, name)
    raise AttributeError(f"module 'faceforge.viz' has no attribute {name!r}")
