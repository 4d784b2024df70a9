"""The inner lip contour of a closed mouth: the line where the lips meet.

A closed mouth is a seam: the lips touch along a line and the skin folds in behind it. A
face detector puts the inner-lip points (2.2-2.9) at the seam in the picture, but a
pixel or two off it the ray meets the lip's front surface, in front of the seam (MakeHuman:
the inner lip points 0.6-0.8 % of the diagonal in front of their hand points). In the
frontal render the seam is a groove: a narrow band of pixels recessed behind the lips
bridged over it (:func:`faceforge.landmarks.rules._recess`). Each inner-lip point moves to
the groove's deepest pixel in its column, within :data:`REACH` of the mouth's width (the
corners 2.4/2.5 stay the detector's: followed outward, the groove runs on past the
commissure into the cheek's fold, 2.6 % of the diagonal beyond ICT's corners). A mouth that
is open (the recessed band taller than :data:`SEAM_HEIGHT` of its width, or background:
a hole) is left to the detector and the lift, which put such points on the hole's rim.
"""

from __future__ import annotations

import numpy as np

#: inner-lip FDPs moved onto the seam; the corners (which set the mouth's width)
INNER_LIP = ("2.2", "2.3", "2.6", "2.7", "2.8", "2.9")
CORNERS = ("2.4", "2.5")
#: how far up and down from a detected point the seam is looked for (fraction of the mouth's width)
REACH = 0.08
#: a pixel recessed this much (fraction of the mouth's width) behind the lips bridged over it is in the seam
SEAM_DEPTH = 0.01
#: a pixel recessed this much (fraction of the mouth's width) sees through the slit (an open seam)
THROUGH = 0.3
#: FDPs of the upper lip (the others are the lower lip's)
UPPER = ("2.2", "2.6", "2.7")
#: a recessed band taller than this (fraction of the mouth's width) is an open mouth, not a seam
SEAM_HEIGHT = 0.1


def lip_seam(render_, vertices, faces, pos: dict) -> dict:
    """{fdp: (3,)} inner-lip points and corners on the seam of a closed mouth (module
    docstring); empty when the mouth is open or no seam is seen. ``render_``: the frontal
    render; ``pos``: {fdp: (3,)} detected points (mesh units)."""
    from faceforge.landmarks.raster import surface_at
    from faceforge.landmarks.rules import _recess

    if not all(k in pos for k in CORNERS):
        return {}
    view = render_.view
    n = render_.depth.shape[0]
    ends = view.project(np.array([pos["2.4"], pos["2.5"]]))[:, :2]
    width = float(np.linalg.norm(ends[0] - ends[1]))
    if width < 16:
        return {}
    mid = ends.mean(axis=0)
    c0, c1 = int(max(mid[0] - 0.8 * width, 0)), int(min(mid[0] + 0.8 * width, n))
    r0, r1 = int(max(mid[1] - 0.3 * width, 0)), int(min(mid[1] + 0.3 * width, n))
    win = render_.depth[r0:r1, c0:c1]
    if not np.isfinite(win).all():
        return {}
    recess = _recess(win, max(3, int(0.25 * width) | 1)) * view.scale / width   # fraction of the mouth's width
    reach = max(2, int(round(REACH * width)))
    picks = {}
    for k in INNER_LIP:
        if k not in pos:
            continue
        c, r = view.project(pos[k][None])[0, :2] - (c0, r0)
        row = _seam_row(recess, int(r), int(c), reach, width)
        if row is None:
            return {}          # no groove here, or an open mouth: leave the lips to the detector
        if recess[row, int(c)] > THROUGH:   # a pixel seeing through the slit: the lip's own edge beside it
            step = -1 if k in UPPER else 1
            while 0 <= row + step < recess.shape[0] and recess[row, int(c)] > THROUGH:
                row += step
        picks[k] = (row, int(c))
    if not picks:
        return {}
    rows = np.array([p[0] for p in picks.values()]) + r0
    cols = np.array([p[1] for p in picks.values()]) + c0
    pts = surface_at(render_, faces, vertices, rows, cols)
    return {k: p for k, p in zip(picks, pts) if np.isfinite(p).all()}


def _seam_row(recess: np.ndarray, row: int, col: int, reach: int, width: float) -> int | None:
    """The seam's row in column ``col`` within ``reach`` of ``row``: the most recessed pixel,
    when it is recessed :data:`SEAM_DEPTH` and the pixels recessed half as much around it form
    a band no taller than :data:`SEAM_HEIGHT`; else None."""
    if not 0 <= col < recess.shape[1]:
        return None
    lo, hi = max(row - reach, 0), min(row + reach + 1, recess.shape[0])
    column = recess[lo:hi, col]
    peak = int(np.argmax(column))
    if column[peak] < SEAM_DEPTH:
        return None
    strong = column >= 0.5 * min(column[peak], THROUGH)
    top, bottom = peak, peak
    while top > 0 and strong[top - 1]:
        top -= 1
    while bottom < len(column) - 1 and strong[bottom + 1]:
        bottom += 1
    if bottom - top + 1 > SEAM_HEIGHT * width:
        return None
    return lo + peak
