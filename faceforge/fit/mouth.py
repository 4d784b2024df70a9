"""The muscles around the mouth follow the skin's lips (beyond §7).

The skull fit uses only FDPs with bone beneath them (:mod:`faceforge.anatomy.tissue`): the
lips are soft tissue, free to sit higher or lower in front of the teeth from one face to the
next, so nothing in the fit tells the muscle map where this head's mouth is. The map is
morphed with the skull, and the orbicularis oris, whose inner loop the template puts on the
bone counterparts of the inner lip contour (FDPs 2.2-2.9), landed where the template's mouth
sits relative to its teeth: on the three sample heads its inner loop lay 0.9-2.2 cm above
the lip line (ICT: all of it above the upper lip's inner contour, its upper arc at the nose
base), so the lips bound to the wrong arc of the ring or to the teeth, and the ring pulled
the skin above the lips.

:class:`MouthField` moves the muscle map, not the skull, so that the bone counterparts of the
lip FDPs (morphed with the skull) come in front of the skin's lip FDPs: each such point
``s_i`` gets the shift ``delta_i`` = skin FDP minus ``s_i`` in the face's frontal plane (its
depth is left to the muscles' projection onto what they lie on). In between, the shift is
the Gaussian-weighted mean of the ``delta_i`` (Shepard), at full strength within ``inner``
of the mouth's centre and fading to zero, smoothly, at ``outer``. Muscles of expression run
from the bone to the soft tissue, so each point takes the shift times its *weight*
(:func:`point_weights`, :func:`sheet_weights`): 1 on the sphincter and at a linear muscle's
insertion, 0 at its origin, the fraction of the way along its fibres in between. The muscles
inserting into the lips and the mouth corners (levators, depressors, zygomaticus, risorius,
mentalis) then follow the ring at their lip ends and stay on their bone at the other: moved
whole, the mentalis and the depressors slid down the chin on MediaPipe (a 2.4 cm shift) and
stopped moving the lower lip and the corners.

Experimental, off by default (``fit.mouth_follows_lips``). It puts the ring around the mouth
opening on all three sample heads and calibrates MakeHuman to a 9.1 % median (69 rows within
10 %) and MediaPipe to 6.3 % (78), but ICT to 14.2 % (8.0 % without it), and calibrated ICT
joy.fap diverges (all with ``bind.lips_to_ring``): the fitted teeth sit 1.9-2.4 cm above the
samples' lips (the skull fit has no target at the lips), so the ring's upper inner arc, now
at the lip line, lies on the lower teeth and follows the jaw down. The teeth, not only the
muscles, need to come to the lips first.

Functions on arrays; the frame is the fit's (+Y up, +Z forward).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from faceforge.anatomy.muscles.muscle_map import POINTS_ORDER

#: FDPs of the lip contours (MPEG-4 groups 2 and 8) whose bone counterparts carry the shift
LIP_FDPS = ("2.2", "2.3", "2.4", "2.5", "2.6", "2.7", "2.8", "2.9",
            "8.1", "8.2", "8.3", "8.4", "8.5", "8.6", "8.7", "8.8")


@dataclass(frozen=True)
class MouthField:
    """A smooth shift of points near the mouth, ``x -> x + f(|x - centre|) shepard(x)``.

    sources (k, 3), shifts (k, 3) float: where the shift is prescribed and by how much;
    centre (3,); inner, outer: full shift within ``inner`` of the centre, none beyond
    ``outer`` (smoothstep between); sigma: the Gaussian width of the Shepard weights.
    Units are the head's.
    """

    sources: np.ndarray
    shifts: np.ndarray
    centre: np.ndarray
    inner: float
    outer: float
    sigma: float

    def displacement(self, points) -> np.ndarray:
        """``(n, 3)`` shift of ``points (n, 3)``."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        d2 = ((p[:, None, :] - self.sources[None]) ** 2).sum(axis=2)
        w = np.exp(-(d2 - d2.min(axis=1, keepdims=True)) / (self.sigma * self.sigma))   # (n, k), max 1
        mean = (w @ self.shifts) / w.sum(axis=1, keepdims=True)
        r = np.linalg.norm(p - self.centre, axis=1)
        t = np.clip((self.outer - r) / (self.outer - self.inner), 0.0, 1.0)
        return (t * t * (3.0 - 2.0 * t))[:, None] * mean

    def __call__(self, points, weights=None) -> np.ndarray:
        """``points (..., 3)`` shifted, each by its ``weights`` (same leading shape; default 1)."""
        p = np.asarray(points, dtype=np.float64)
        d = self.displacement(p)
        if weights is not None:
            d = d * np.asarray(weights, dtype=np.float64).reshape(-1, 1)
        return (p.reshape(-1, 3) + d).reshape(p.shape)


def _fraction_along(line) -> np.ndarray:
    """``(k,)`` arc-length fraction of each point of the polyline ``line (k, 3)``, 0 to 1."""
    seg = np.linalg.norm(np.diff(line, axis=0), axis=1)
    run = np.concatenate([[0.0], np.cumsum(seg)])
    return run / run[-1] if run[-1] > 0 else np.zeros(len(line))


def point_weights(spec) -> np.ndarray:
    """How much of the mouth's shift each point of ``spec.points()`` takes, ``(k,)`` in [0, 1]:
    a sphincter's all of it; a linear muscle's origin none, its insertion all, a fibre's inner
    point the fraction of the way along its action line (A0 from the first origin point to the
    first insertion point, A2 from the last to the last: ``MuscleSpec.action_lines``)."""
    if spec.type != "linear":
        return np.ones(len(spec.points()))
    lines = spec.action_lines()
    weights = {k: np.ones(len(getattr(spec, k))) for k in POINTS_ORDER}
    weights["origin"] = np.zeros(len(spec.origin))
    weights["fibre_a"] = _fraction_along(lines["A0"])[1:-1]
    weights["fibre_b"] = _fraction_along(lines["A2"])[1:-1]
    return np.concatenate([weights[k] for k in POINTS_ORDER])


def sheet_weights(kind: str, h: int, w: int) -> np.ndarray:
    """:func:`point_weights` for a built muscle's particles ``(2 h w,)`` (bottom sheet, then
    top; row ``i`` of ``h`` runs from the origin, row 0, to the insertion): ``i / (h - 1)`` on a
    linear muscle, 1 on a sphincter."""
    if kind != "linear":
        return np.ones(2 * h * w)
    rows = np.repeat(np.arange(h) / max(h - 1, 1), w)
    return np.concatenate([rows, rows])


def mouth_field(bone_points: dict, skin_points: dict, forward=(0.0, 0.0, 1.0),
                inner: float = 1.2, outer: float = 2.4) -> MouthField | None:
    """The :class:`MouthField` that brings the lip FDPs' bone counterparts in front of the skin's.

    bone_points : {FDP: (3,)} the template skull landmarks as the skull fit placed them
    skin_points : {FDP: (3,)} the head's skin landmarks
    forward : the face's forward axis; the shift has no component along it
    inner, outer : in units of the mouth's half-width (half the distance of the corners
    8.3-8.4, else of the inner corners 2.4-2.5); sigma is half the half-width.

    Returns None when fewer than two lip FDPs are on both sides or the mouth has no corners.
    """
    fdps = [f for f in LIP_FDPS if f in bone_points and f in skin_points]
    corners = next((c for c in (("8.3", "8.4"), ("2.4", "2.5")) if all(k in skin_points for k in c)), None)
    if len(fdps) < 2 or corners is None:
        return None
    src = np.array([bone_points[f] for f in fdps], dtype=np.float64)
    dst = np.array([skin_points[f] for f in fdps], dtype=np.float64)
    fw = np.asarray(forward, dtype=np.float64)
    fw = fw / np.linalg.norm(fw)
    shift = dst - src
    shift -= np.outer(shift @ fw, fw)                     # in the frontal plane
    half = 0.5 * float(np.linalg.norm(np.asarray(skin_points[corners[0]]) - np.asarray(skin_points[corners[1]])))
    if not half > 0:
        return None
    return MouthField(src, shift, src.mean(axis=0), inner * half, outer * half, 0.5 * half)
