"""Facial Animation Parameter Units (FAPU) measured on a neutral face.

MPEG-4 expresses every FAP value in a unit tied to the face's own proportions
(``data/fapu.csv``), so one FAP track drives faces of any size:

=======  ===========================================  ===========================
FAPU     neutral-face distance (model units)          definition on FDPs
=======  ===========================================  ===========================
IRISD    IRISD0 / 1024, upper to lower eyelid         3.1.y - 3.3.y (= 3.2.y - 3.4.y)
ES       ES0 / 1024, between the pupils               3.5.x - 3.6.x
ENS      ENS0 / 1024, eyes to nose (vertical)         3.5.y - 9.15.y (pupils' mean y)
MNS      MNS0 / 1024, mouth to nose (vertical)        9.15.y - 2.2.y
MW       MW0 / 1024, mouth width                      8.3.x - 8.4.x
AU       1e-5 rad                                     --
=======  ===========================================  ===========================

The FDP coordinates are components in the MPEG-4 frame (+Y up, +X = subject's left,
face along +Z); a non-positive distance means the landmarks are not in that frame
and raises :class:`~faceforge.exceptions.LandmarkError`. IRISD0 is the mean over
the eyes whose two eyelid points are both given, and ENS0 uses the mean height of the two
pupils (the FDP table lists both for ENS0; equal on a level, symmetric face). A pupil may be a point that is
not a mesh vertex (eyeless meshes): only its position is used.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from faceforge.exceptions import LandmarkError

from .tables import AU_RADIANS, DIRECTION_VECTORS, FAP_TABLE, N_FAPS, fap_record

#: one unit is the neutral-face distance divided by this
FAPU_DIVISOR = 1024.0

#: FDPs needed by each neutral-face distance (IRISD0: either eye)
_REQUIRED = {
    "ES0": ("3.5", "3.6"),
    "ENS0": ("3.5", "3.6", "9.15"),
    "MNS0": ("9.15", "2.2"),
    "MW0": ("8.3", "8.4"),
}
_EYELIDS = (("3.1", "3.3"), ("3.2", "3.4"))


@dataclass(frozen=True)
class Fapu:
    """The five neutral-face distances, in the landmarks' length unit.

    Attributes
    ----------
    es0, ens0, mns0, mw0, irisd0 : float
        Eye separation, eye-nose separation, mouth-nose separation, mouth width and
        iris diameter (eyelid gap) of the neutral face. One FAPU is the distance / 1024.
    """

    es0: float
    ens0: float
    mns0: float
    mw0: float
    irisd0: float

    def unit(self, name: str) -> float:
        """Size of one FAPU ``name`` (``"ES"``, ..., ``"AU"``): length units, or radians for AU."""
        if name == "AU":
            return AU_RADIANS
        try:
            return getattr(self, name.lower() + "0") / FAPU_DIVISOR
        except AttributeError:
            raise KeyError(f"unknown FAPU {name!r}; valid: IRISD, ES, ENS, MNS, MW, AU") from None

    def as_dict(self) -> dict[str, float]:
        """``{"IRISD": ..., "ES": ..., "ENS": ..., "MNS": ..., "MW": ..., "AU": 1e-5}`` (one unit each)."""
        return {name: self.unit(name) for name in ("IRISD", "ES", "ENS", "MNS", "MW", "AU")}

    def per_fap(self) -> np.ndarray:
        """``(68,) float64``: the size of one unit of each FAP (NaN for FAPs 1, 2)."""
        return np.array([np.nan if r.unit is None else self.unit(r.unit) for r in FAP_TABLE])


def _position(landmarks: Mapping[str, object], fdp: str) -> np.ndarray:
    point = np.asarray(landmarks[fdp], dtype=np.float64)
    if point.shape != (3,):
        raise ValueError(f"landmark {fdp}: expected a (3,) position, got shape {point.shape}")
    return point


def fapu_from_landmarks(landmarks: Mapping[str, object], source: str | Path | None = None) -> Fapu:
    """Measure the FAPU on a neutral face.

    Parameters
    ----------
    landmarks : mapping str -> (3,) float
        FDP id (``"3.5"``) to position, in model units, MPEG-4 frame (+Y up, +X left).
        Needs 3.5, 3.6, 9.15, 2.2, 8.3, 8.4 and one eye's eyelids (3.1 + 3.3 or 3.2 + 3.4).
    source : path, optional
        The landmark file, named in error messages.

    Returns
    -------
    Fapu

    Raises
    ------
    LandmarkError
        Naming the missing FDPs, or a distance that is not positive (landmarks not in
        the +Y up, subject's left = +X frame).
    """
    missing = sorted(
        {fdp for fdps in _REQUIRED.values() for fdp in fdps if fdp not in landmarks},
        key=lambda s: tuple(int(x) for x in s.split(".")),
    )
    eyes = [pair for pair in _EYELIDS if all(fdp in landmarks for fdp in pair)]
    if missing or not eyes:
        what = ", ".join(missing)
        if not eyes:
            what = (what + "; " if what else "") + "IRISD0 needs 3.1 and 3.3 (or 3.2 and 3.4)"
        raise LandmarkError(f"cannot measure the FAPU, missing FDPs: {what}", source)
    p = {fdp: _position(landmarks, fdp) for fdps in _REQUIRED.values() for fdp in fdps}
    values = {
        "ES0": p["3.5"][0] - p["3.6"][0],
        "ENS0": (p["3.5"][1] + p["3.6"][1]) / 2 - p["9.15"][1],
        "MNS0": p["9.15"][1] - p["2.2"][1],
        "MW0": p["8.3"][0] - p["8.4"][0],
        "IRISD0": float(np.mean([_position(landmarks, a)[1] - _position(landmarks, b)[1] for a, b in eyes])),
    }
    for name, value in values.items():
        if not np.isfinite(value) or value <= 0:
            raise LandmarkError(
                f"FAPU {name} = {value:.6g} is not positive: landmarks are not in the MPEG-4 frame "
                "(+Y up, subject's left = +X) or are misplaced",
                source,
            )
    return Fapu(
        es0=float(values["ES0"]),
        ens0=float(values["ENS0"]),
        mns0=float(values["MNS0"]),
        mw0=float(values["MW0"]),
        irisd0=float(values["IRISD0"]),
    )


def fap_displacement(fap: int | str, value: float, fapu: Fapu) -> tuple[str, np.ndarray]:
    """Where a low-level FAP moves its feature point on the face.

    Parameters
    ----------
    fap : int or str
        A translational FAP (id or name): unit IRISD, ES, ENS, MNS or MW and direction
        up/down/left/right/forward. E.g. ``3`` (open_jaw): FDP 2.1, downward in MNS.
    value : float
        The FAP value in its FAPU (negative moves against the positive direction).
    fapu : Fapu

    Returns
    -------
    fdp : str
        The feature point moved, e.g. ``"2.1"``.
    displacement : (3,) float64
        ``value * unit * direction``, model units, MPEG-4 frame.

    Raises
    ------
    ValueError
        For FAPs that are not translations (1, 2 high-level; eyeball and head rotations in
        AU; pupil dilation; tongue roll), naming the FAP.
    """
    record = fap_record(fap)
    if not record.is_translation:
        raise ValueError(
            f"FAP {record.id} ({record.name}) is not a translation "
            f"(unit {record.unit}, direction {record.direction}); it has no displacement vector"
        )
    direction = np.asarray(DIRECTION_VECTORS[record.direction], dtype=np.float64)
    return record.fdp, float(value) * fapu.unit(record.unit) * direction


__all__ = ["FAPU_DIVISOR", "Fapu", "fap_displacement", "fapu_from_landmarks", "N_FAPS"]
