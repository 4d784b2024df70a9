"""The fourteen MPEG-4 visemes as high-level FAP 1 tracks (ISO/IEC 14496-2 Annex C).

FAP 1 carries four values per frame: ``viseme_select1, viseme_select2, viseme_blend,
viseme_def``. The standard numbers the visemes by their phonemes (0 = none) and mixes two of
them, ``select1 x blend / 63 + select2 x (1 - blend / 63)``; their mouth shapes are left to
the decoder (faceforge's are the ``visemes`` table of the FAP mapping).

:func:`viseme_track` builds a track from a sequence of visemes, each cross-fading from the
one before, as a speech decoder writes them.
"""

from __future__ import annotations

import math

import numpy as np

from faceforge.exceptions import FapError

from .fap import FapTrack
from .tables import N_FAPS

#: viseme names by the standard's ``viseme_select`` code minus one, after their phonemes:
#: p b m, f v, T D (think), t d, k g, tS dZ S (chair), s z, n l, r, A: (car), e (bed),
#: I (tip), Q (top), U (book)
VISEMES = ("p_b_m", "f_v", "th", "t_d", "k_g", "ch_j_sh", "s_z", "n_l", "r", "a", "e", "i", "o", "u")
#: name -> viseme_select code (1..14)
VISEME_CODES = {name: code for code, name in enumerate(VISEMES, start=1)}
#: viseme_blend of a frame that is all viseme_select1
MAX_BLEND = 63.0


def viseme_track(names, fps: float = 25.0, each: float = 0.2, blend: float = 0.08,
                 ramp: float = 0.15) -> FapTrack:
    """A FAP track that says a sequence of visemes.

    Parameters
    ----------
    names : sequence of str
        Visemes (:data:`VISEMES`), one after the other; ``"none"`` is the neutral mouth.
    fps : float
        Frame rate (> 0).
    each : float
        Seconds each viseme lasts, its cross-fade from the one before included (> 0).
    blend : float
        Seconds of each cross-fade (smoothstep; 0 <= blend <= each): ``select1`` is the viseme,
        ``select2`` the one before, ``viseme_blend`` rising from 0 to 63.
    ramp : float
        Seconds of the neutral mouth before the first viseme (which fades in from it like any
        other, over ``blend``) and after the last (which fades out to it over the whole ramp,
        so the track ends at rest) (>= 0).

    Returns
    -------
    FapTrack
        FAP 1 given in every frame; low-level FAPs absent (0).

    Raises
    ------
    FapError
        An unknown name (the message lists the valid ones) or an out-of-range number.
    """
    names = list(names)
    codes = {"none": 0, **VISEME_CODES}
    for name in names:
        if name not in codes:
            raise FapError(f"unknown viseme {name!r}; valid: none, {', '.join(VISEMES)}")
    if not names:
        raise FapError("a viseme track needs at least one viseme")
    checks = {"fps": (fps, fps > 0, "> 0"), "each": (each, each > 0, "> 0"),
              "blend": (blend, 0 <= blend <= each, f"in [0, each = {each}]"),
              "ramp": (ramp, ramp >= 0, ">= 0")}
    for key, (value, ok, rule) in checks.items():
        if not (math.isfinite(value) and ok):
            raise FapError(f"viseme track {key} must be {rule}, got {value!r}")
    seq = [0, *(codes[n] for n in names), 0]
    spans = [ramp, *([each] * len(names)), ramp]      # seconds of each segment
    starts = np.concatenate([[0.0], np.cumsum(spans)])
    n = int(round(starts[-1] * fps)) + 1
    t = np.arange(n) / fps
    k = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(seq) - 1)
    into = t - starts[k]
    # a segment fades in from the one before over its first ``blend`` seconds (the closing
    # neutral segment over its whole ramp, so the track ends at rest): select1's weight
    fade = np.where(k == len(seq) - 1, ramp, blend)
    weight = np.ones(n)
    on = fade > 0
    s = np.clip(into[on] / fade[on], 0.0, 1.0)
    weight[on] = s * s * (3.0 - 2.0 * s)
    weight[k == 0] = 1.0                              # the opening rest: none after none
    viseme = np.zeros((n, 4))
    viseme[:, 0] = np.asarray(seq)[k]
    viseme[:, 1] = np.asarray(seq)[np.maximum(k - 1, 0)]
    viseme[:, 2] = MAX_BLEND * weight
    mask = np.zeros((n, N_FAPS), dtype=bool)
    mask[:, 0] = True
    name = "visemes_" + "_".join(names)
    return FapTrack.from_given(fps, mask, np.zeros((n, N_FAPS)), viseme=viseme,
                               name=name if len(name) <= 64 else name[:61] + "...")

