"""The six basic expressions as high-level FAP 2 tracks (paper §9, ISO/IEC 14496-2 Annex C).

FAP 2 carries six values per frame: ``expression_select1, expression_intensity1,
expression_select2, expression_intensity2, init_face, expression_def``. The standard numbers
the expressions 1 joy, 2 sadness, 3 anger, 4 fear, 5 disgust, 6 surprise (0 = neutral) and
scales intensities from 0 to 63.

:func:`expression_track` builds a preset: one expression that ramps in from neutral, holds,
and ramps out again. :func:`expression_weights` turns any track's FAP 2 values into
per-expression weights in [0, 1] for the animation stage.
"""

from __future__ import annotations

import math

import numpy as np

from faceforge.exceptions import FapError

from .fap import FapTrack
from .tables import N_FAPS

#: expression names by the standard's ``expression_select`` code minus one
EXPRESSIONS = ("joy", "sadness", "anger", "fear", "disgust", "surprise")
#: name -> expression_select code (1..6)
EXPRESSION_CODES = {name: code for code, name in enumerate(EXPRESSIONS, start=1)}
#: expression_intensity value of a full expression
MAX_INTENSITY = 63.0


def ramp_envelope(n_frames: int, fps: float, ramp: float) -> np.ndarray:
    """Smooth in-hold-out envelope.

    Parameters
    ----------
    n_frames : int
    fps : float
    ramp : float
        Seconds of each ramp; clipped to half the duration ``(n_frames - 1) / fps``.

    Returns
    -------
    (n_frames,) float64
        0 at the first and last frame, 1 on the hold, smoothstep ``3s^2 - 2s^3`` on the ramps.
    """
    t = np.arange(n_frames) / fps
    duration = (n_frames - 1) / fps
    ramp = min(ramp, duration / 2)
    if ramp <= 0:
        return np.ones(n_frames)
    s = np.clip(np.minimum(t, duration - t) / ramp, 0.0, 1.0)
    return s * s * (3.0 - 2.0 * s)


def expression_track(
    name: str, intensity: float = 1.0, fps: float = 25.0, seconds: float = 3.0, ramp: float = 0.5
) -> FapTrack:
    """A FAP track that plays one basic expression.

    Parameters
    ----------
    name : str
        One of :data:`EXPRESSIONS`.
    intensity : float
        Peak strength in [0, 1]; ``expression_intensity1 = 63 * intensity * envelope``
        (floats, not rounded to the standard's integers).
    fps : float
        Frame rate (> 0).
    seconds : float
        Duration (> 0); the track has ``round(seconds * fps) + 1`` frames.
    ramp : float
        Seconds to ramp in and, at the end, out (>= 0; see :func:`ramp_envelope`).

    Returns
    -------
    FapTrack
        FAP 2 given in every frame (select1 = the expression's code, select2 = 0,
        intensity2 = 0, init_face = 0, expression_def = 0); low-level FAPs absent (0).

    Raises
    ------
    FapError
        Unknown name (the message lists the valid ones) or out-of-range numbers.
    """
    if name not in EXPRESSION_CODES:
        raise FapError(f"unknown expression {name!r}; valid: {', '.join(EXPRESSIONS)}")
    checks = {
        "intensity": (intensity, 0 <= intensity <= 1, "in [0, 1]"),
        "fps": (fps, fps > 0, "> 0"),
        "seconds": (seconds, seconds > 0, "> 0"),
        "ramp": (ramp, ramp >= 0, ">= 0"),
    }
    for key, (value, ok, rule) in checks.items():
        if not (math.isfinite(value) and ok):
            raise FapError(f"expression {key} must be {rule}, got {value!r}")
    n = int(round(seconds * fps)) + 1
    envelope = ramp_envelope(n, fps, ramp)
    expression = np.zeros((n, 6))
    expression[:, 0] = EXPRESSION_CODES[name]
    expression[:, 1] = MAX_INTENSITY * intensity * envelope
    mask = np.zeros((n, N_FAPS), dtype=bool)
    mask[:, 1] = True
    return FapTrack.from_given(fps, mask, np.zeros((n, N_FAPS)), expression=expression, name=f"expression_{name}")


def expression_weights(expression: np.ndarray) -> np.ndarray:
    """Per-expression weights from FAP 2 parameters.

    Parameters
    ----------
    expression : (n, 6) float
        ``FapTrack.expression``.

    Returns
    -------
    (n, 6) float64
        Column ``k`` is the weight of :data:`EXPRESSIONS` ``[k]``: ``intensity / 63`` of
        whichever of the two selected slots names it (summed if both do), clipped to
        [0, 1]. Select codes outside 1..6 (0 = neutral) contribute nothing.
    """
    expression = np.asarray(expression, dtype=np.float64)
    if expression.ndim != 2 or expression.shape[1] != 6:
        raise ValueError(f"expression must be (n, 6), got {expression.shape}")
    weights = np.zeros((expression.shape[0], len(EXPRESSIONS)))
    for select, strength in ((0, 1), (2, 3)):
        codes = np.rint(expression[:, select]).astype(np.int64)
        valid = (codes >= 1) & (codes <= len(EXPRESSIONS))
        rows = np.flatnonzero(valid)
        np.add.at(weights, (rows, codes[valid] - 1), expression[valid, strength] / MAX_INTENSITY)
    return np.clip(weights, 0.0, 1.0)
