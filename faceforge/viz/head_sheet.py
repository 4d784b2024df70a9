"""A bound head's held poses side by side, as the sheet stages draw them (expressions, visemes, match).

:func:`head_sheet` frames the face without its neck (:func:`faceforge.viz.contact_sheet.face_region`,
else the head above the bones' lowest point), draws the mouth's inside dark (:func:`faceforge.viz.
smooth.mouth_cavity`, from the lip FDPs) and puts a heat map of 0-8 mm of motion from the first
pose beside each pose.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

#: the heat maps' full scale (mm of motion from the first pose)
HEAT_MM = 8.0


def head_sheet(path, head, poses: np.ndarray, labels, title: str, cols: int) -> Path:
    """Write ``poses (k, n, 3)`` (working skin; the first is the reference, usually rest) of ``head``
    (a :class:`faceforge.animation.rig.BoundHead`) as a smooth-shaded sheet at ``path``; ``labels``:
    one per pose; ``cols``: poses a row (each with its heat map)."""
    from faceforge.anatomy.tissue import units_per_mm
    from faceforge.viz.contact_sheet import contact_sheet

    mm = units_per_mm(head.landmarks)
    faces, region, dim = head.faces, face_framing(head), cavity(head, mm)
    if getattr(head, "embedding", None) is not None:   # a proxy-simulated head: the user's mesh is drawn
        poses, faces, region = head.carried(poses), head.user_faces, region[head.user_index]
        dim = None if dim is None else cavity(head, mm, head.carried(head.rest[None])[0], faces)   # on its own triangles
    return contact_sheet(path, poses, faces, range(len(poses)), 1.0, cols=cols, panel=3.2, dpi=120,
                         labels=list(labels), title=f"{title}, heat map 0-{HEAT_MM:g} mm", region=region,
                         heat=HEAT_MM * mm, heat_label=f"0-{HEAT_MM:g} mm", dim=dim)


def cavity(head, mm: float, vertices=None, faces=None):
    """(n,) in [0, 1]: the mouth's inside, drawn dark (None without the lip FDPs); ``mm``: head
    units per mm. ``vertices (n, 3)``/``faces`` (default the working skin's rest): another mesh
    of the same head (a proxy's user mesh, whose own triangles are marked, not the proxy's
    coarse ones read back through the nearest proxy vertex)."""
    from faceforge.viz.smooth import mouth_cavity

    fv = head.fdp_vertex
    if not all(k in fv for k in ("2.2", "2.3", "8.1", "8.2", "8.3", "8.4")):
        return None
    r = head.rest
    v, f = (r, head.faces) if vertices is None else (vertices, faces)
    return mouth_cavity(v, f, r[fv["2.2"]], r[fv["2.3"]], r[[fv["8.3"], fv["8.4"]]], r[[fv["8.1"], fv["8.2"]]], mm)


def face_framing(head) -> np.ndarray:
    """(n,) bool: the face to frame (:func:`faceforge.viz.contact_sheet.face_region`), else the
    whole head above the bone's lowest point."""
    from faceforge.viz.contact_sheet import face_region

    region = face_region(head.rest, head.landmarks)
    return region if region is not None else head.rest[:, 1] >= head.bone_heights()[0]
