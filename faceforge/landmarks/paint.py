"""Eyes drawn on a grey render from a first detection: a second look for featureless eyes.

The detector was trained on photos. A mesh whose eyes are neither holes nor recessed
sockets (a face mask or a scan whose eyes are triangulated shut, flush with the lids) shows
it nothing there, and it guesses the eyes and the brows from the rest of the face. Drawing
the eyes where its first pass put them (a light eye opening, a dark iris, a dark lid margin)
and detecting again moves its eye, iris and brow points towards the mesh's eyes: on the
MediaPipe mask, whose vertex i is MediaPipe point i, the median error of the eye contours
fell from 1.29-1.34 to 0.69-1.01 % of the diagonal, of the irises from 1.32 to 0.51 %, of the
brows from 1.90-2.12 to 1.61-1.93 % (branch mask23). The other points are the first look's:
taken from the second look too, the face's outline and the lower lip moved away (the lower inner
lip 1.0 -> 2.0 %). Drawing brows as well (a dark band) made them worse.

Pure functions on pixel arrays: ``points (478, 2)`` are the detector's pixel column, row.
"""

from __future__ import annotations

import numpy as np

#: MediaPipe's eye contours (subject's left, right), in order around the opening
LEFT_EYE = (263, 249, 390, 373, 374, 380, 381, 382, 362, 398, 384, 385, 386, 387, 388, 466)
RIGHT_EYE = (33, 7, 163, 144, 145, 153, 154, 155, 133, 173, 157, 158, 159, 160, 161, 246)
#: the iris centres (478-point model)
IRIS_CENTRES = (473, 468)
#: MediaPipe's brow points
LEFT_BROW = (276, 283, 282, 295, 285, 300, 293, 334, 296, 336)
RIGHT_BROW = (46, 53, 52, 65, 55, 70, 63, 105, 66, 107)
#: the points taken from the second look: both eye contours, the ten iris points, both brows
REPAINTED = np.array(sorted(set(LEFT_EYE + RIGHT_EYE + LEFT_BROW + RIGHT_BROW) | set(range(468, 478))))
#: the drawing, in fractions of the outer eye corners' distance (263 - 33) and 8-bit greys. The dark
#: disc is about twice an iris (0.065) and is not clipped to the opening: the first look's opening on
#: the mask is a slit, and a disc clipped to it (radius 0.065-0.11) left the mask at 0.98 / 2.28 / 3.31 %
#: (median / p90 / max of the diagonal) against 0.92 / 1.96 / 3.13; unclipped 0.065: 0.98 / 1.89 / 3.15
IRIS_RADIUS = 0.11
LID_LINE = 0.015
SCLERA, IRIS, LID = 235, 60, 35
#: an eye is open in a render when this share of the pixels inside its contour is background (a hole
#: seen through: ICT cut to a mask's extent, 0.93) or their median depth lies this far (fraction of the
#: eye's width, corner to corner) behind the contour's (a socket or a hole: the sample heads
#: 0.077-0.147, cut to a mask 0.10-0.66; the MediaPipe mask's shut eyes -0.005 / -0.003)
OPEN_BACKGROUND = 0.1
OPEN_RECESS = 0.03


def polygon_mask(polygon: np.ndarray, shape: tuple) -> np.ndarray:
    """(h, w) bool: the pixel centres (col + 0.5, row + 0.5) inside ``polygon (k, 2)`` (pixel
    column, row; even-odd rule)."""
    h, w = shape
    out = np.zeros((h, w), dtype=bool)
    lo = np.clip(np.floor(polygon.min(axis=0)).astype(int), 0, [w, h])
    hi = np.clip(np.ceil(polygon.max(axis=0)).astype(int) + 1, 0, [w, h])
    if (hi <= lo).any():
        return out
    x = np.arange(lo[0], hi[0]) + 0.5
    y = np.arange(lo[1], hi[1]) + 0.5
    px, py = np.meshgrid(x, y)
    inside = np.zeros(px.shape, dtype=bool)
    a, b = polygon, np.roll(polygon, -1, axis=0)
    for (x0, y0), (x1, y1) in zip(a, b):
        if y0 == y1:
            continue
        crosses = (y0 > py) != (y1 > py)
        xc = x0 + (py - y0) * (x1 - x0) / (y1 - y0)
        inside ^= crosses & (px < xc)
    out[lo[1]:hi[1], lo[0]:hi[0]] = inside
    return out


def eye_open(depth: np.ndarray, points: np.ndarray, scale: float) -> bool:
    """Whether either eye the detection ``points (478, 2)`` outlines is an opening in the render
    whose ``depth (h, w)`` buffer (mesh units along the view, inf: background) it was found on
    (``scale``: pixels per mesh unit): :data:`OPEN_BACKGROUND` of the pixels inside the contour see
    the background, or their median depth lies :data:`OPEN_RECESS` of the eye's width behind the
    contour's median depth."""
    h, w = depth.shape
    for contour in (LEFT_EYE, RIGHT_EYE):
        poly = points[list(contour)]
        inside = depth[polygon_mask(poly, (h, w))]
        if len(inside) == 0:
            continue
        cols = np.clip(poly[:, 0].astype(int), 0, w - 1)
        rows = np.clip(poly[:, 1].astype(int), 0, h - 1)
        rim = depth[rows, cols]
        seen = np.isfinite(inside)
        if np.mean(~seen) >= OPEN_BACKGROUND:
            return True
        width = float(np.linalg.norm(poly[0] - poly[8])) / scale    # outer to inner corner
        if np.isfinite(rim).any() and np.median(inside[seen]) - np.median(rim[np.isfinite(rim)]) > OPEN_RECESS * width:
            return True
    return False


def _segment_mask(a: np.ndarray, b: np.ndarray, width: float, shape: tuple) -> np.ndarray:
    """(h, w) bool: pixel centres within ``width / 2`` pixels of the segment ``a``-``b`` (2,)."""
    h, w = shape
    r = width / 2.0 + 1.0
    lo = np.clip(np.floor(np.minimum(a, b) - r).astype(int), 0, [w, h])
    hi = np.clip(np.ceil(np.maximum(a, b) + r).astype(int) + 1, 0, [w, h])
    out = np.zeros((h, w), dtype=bool)
    if (hi <= lo).any():
        return out
    px, py = np.meshgrid(np.arange(lo[0], hi[0]) + 0.5, np.arange(lo[1], hi[1]) + 0.5)
    d = b - a
    t = np.clip(((px - a[0]) * d[0] + (py - a[1]) * d[1]) / max(float(d @ d), 1e-12), 0.0, 1.0)
    out[lo[1]:hi[1], lo[0]:hi[0]] = np.hypot(px - a[0] - t * d[0], py - a[1] - t * d[1]) <= width / 2.0
    return out


def paint_eyes(image: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(h, w, 3) uint8: the grey render ``image (h, w) uint8`` with both eyes drawn where the
    detection ``points (478, 2)`` put them: the opening (the eye contour) light, a dark disc of
    :data:`IRIS_RADIUS` at the iris centre, the contour a dark line of :data:`LID_LINE` (both
    fractions of the outer eye corners' distance, at least a pixel wide)."""
    out = np.array(image, dtype=np.uint8, copy=True)
    span = float(np.linalg.norm(points[263] - points[33]))
    h, w = out.shape
    rows, cols = np.mgrid[0:h, 0:w] + 0.5
    for contour, iris in ((LEFT_EYE, IRIS_CENTRES[0]), (RIGHT_EYE, IRIS_CENTRES[1])):
        poly = points[list(contour)]
        out[polygon_mask(poly, (h, w))] = SCLERA
        c = points[iris]
        out[np.hypot(cols - c[0], rows - c[1]) <= IRIS_RADIUS * span] = IRIS    # over the lids too
        line = max(1.0, LID_LINE * span)
        for a, b in zip(poly, np.roll(poly, -1, axis=0)):
            out[_segment_mask(a, b, line, (h, w))] = LID
    return np.ascontiguousarray(np.repeat(out[:, :, None], 3, axis=2))
