"""The range a FAP value can take on a face, and clamping to it.

ISO/IEC 14496-2 codes FAP values as integers in their FAP units (FAPU) without a
physical bound; a value of 1e9 is syntactically valid and turned the head 5.7e5
degrees. faceforge takes these as the largest meaningful magnitudes:

* a length FAPU (IRISD, ES, ENS, MNS, MW) is 1/1024 of a distance on the neutral face,
  so 1024 moves a point by the whole distance (1 IRISD closes an eyelid; the sample
  tracks peak at 870 MNS for a wide-open jaw). :data:`MAX_LENGTH_UNITS` = 3072 is three
  whole distances, past anything a face does;
* an angle (AU, 1e-5 rad): :data:`MAX_ANGLE_UNITS` = pi / 2 rad, 90 degrees (the neck turns
  about 80 degrees each way, the eyes about 50).

Values past these are clamped (:func:`clamp_to_range`); the reader warns, or with
``strict`` refuses the file.
"""

from __future__ import annotations

import math

import numpy as np

from .tables import AU_RADIANS, FAP_TABLE, N_FAPS

#: largest |value| of a FAP in a length unit (FAPU = distance / 1024)
MAX_LENGTH_UNITS = 3072.0
#: largest |value| of a FAP in the angle unit AU (1e-5 rad): pi / 2
MAX_ANGLE_UNITS = float(math.floor(0.5 * math.pi / AU_RADIANS))


def value_limits() -> np.ndarray:
    """(68,) float64: the largest |value| of each FAP (inf for FAPs 1 and 2, which carry no value)."""
    out = np.full(N_FAPS, np.inf)
    for record in FAP_TABLE[2:]:
        out[record.id - 1] = MAX_ANGLE_UNITS if record.unit == "AU" else MAX_LENGTH_UNITS
    return out


LIMITS = value_limits()


def clamp_to_range(values: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, str]:
    """Clamp the given entries of ``values`` (n, 68) float (FAPU; only where ``mask`` (n, 68)
    bool) to :data:`LIMITS`. Returns ``(clamped copy, summary)``; the summary names each FAP
    that was clamped with its largest |value| and frame count (empty string: nothing clamped)."""
    out, worst, count = clamp_block(values, mask)
    return out, range_summary(worst, count)


def clamp_block(values: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`clamp_to_range` of one block of frames without the summary: ``(clamped (n, 68),
    worst (68,) float64 largest clamped |value| per FAP (0 where none), count (68,) int64 frames
    clamped per FAP)``; a file read block by block adds up ``count`` and takes the maximum of
    ``worst`` (:func:`range_summary`)."""
    values = np.asarray(values, dtype=np.float64)
    given = np.asarray(mask, dtype=bool)
    over = given & (np.abs(np.nan_to_num(values)) > LIMITS)
    worst = np.zeros(N_FAPS)
    count = over.sum(axis=0).astype(np.int64)
    if not over.any():
        return values, worst, count
    for k in np.flatnonzero(count):
        worst[k] = float(np.abs(values[over[:, k], k]).max())
    return np.where(over, np.clip(values, -LIMITS, LIMITS), values), worst, count


def range_summary(worst: np.ndarray, count: np.ndarray) -> str:
    """The clamping summary of :func:`clamp_to_range` from the per-FAP largest clamped |value|
    ``worst (68,)`` and frame count ``count (68,)`` (empty string: nothing clamped)."""
    parts = []
    for k in np.flatnonzero(np.asarray(count) > 0):
        record, n = FAP_TABLE[k], int(count[k])
        parts.append(f"FAP {record.id} {record.name} up to {float(worst[k]):.3g} {record.unit} in {n} "
                     f"frame{'s' if n > 1 else ''} (limit {LIMITS[k]:g})")
    return "; ".join(parts[:6]) + (f"; and {len(parts) - 6} more FAPs" if len(parts) > 6 else "")
