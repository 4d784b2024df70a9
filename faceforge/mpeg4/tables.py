"""The MPEG-4 facial animation tables as plain data (ISO/IEC 14496-2, Annex C).

Loaded once at import from the CSV files shipped in ``faceforge/mpeg4/data/``
(provenance in ``data/README.md``):

* :data:`FAP_TABLE` -- the 68 Facial Animation Parameters, ``FAP_TABLE[i].id == i + 1``.
  FAPs 1 (viseme) and 2 (expression) are high-level: they carry 4 and 6 values in a
  FAP file and have no unit, direction or feature point.
* :data:`FDP_TABLE` -- the 84 Facial Definition Parameters (feature points), ids
  such as ``"2.1"`` (strings: ``"2.10"`` and ``"2.1"`` differ).
* :data:`FAPU_NAMES` -- the FAP units; see :mod:`faceforge.mpeg4.fapu`.
* :data:`LIP_PAIRS` -- inner-lip FAPs 4..13 paired with outer-lip FAPs 51..60.

Coordinates follow the MPEG-4 neutral face (and the project's convention): right
handed, +Y up, the face looks along +Z, the subject's left is +X. A FAP's positive
``direction`` maps to a unit vector through :data:`DIRECTION_VECTORS`.
"""

from __future__ import annotations

import csv
import re
from dataclasses import dataclass
from importlib import resources

import numpy as np

#: number of FAPs in the standard
N_FAPS = 68
#: values a FAP file carries for the high-level FAPs 1 (viseme) and 2 (expression)
N_VISEME_VALUES = 4
N_EXPRESSION_VALUES = 6

#: FAP units. The first five are lengths measured on the neutral face (value / 1024),
#: AU is an angle unit of 1e-5 rad.
FAPU_NAMES = ("IRISD", "ES", "ENS", "MNS", "MW", "AU")
LENGTH_FAPU_NAMES = ("IRISD", "ES", "ENS", "MNS", "MW")
#: the angle unit in radians
AU_RADIANS = 1e-5

#: positive motion of a translational FAP as a unit vector (+Y up, +Z forward,
#: +X = the subject's left). Other directions (rotations, "growing") are not
#: translations and are absent on purpose.
DIRECTION_VECTORS = {
    "up": (0.0, 1.0, 0.0),
    "down": (0.0, -1.0, 0.0),
    "left": (1.0, 0.0, 0.0),
    "right": (-1.0, 0.0, 0.0),
    "forward": (0.0, 0.0, 1.0),
}


@dataclass(frozen=True)
class FapRecord:
    """One row of the FAP table.

    Attributes
    ----------
    id : int
        1..68.
    name : str
        The standard's name, e.g. ``"open_jaw"``.
    description : str
    unit : str or None
        One of :data:`FAPU_NAMES`; None for the high-level FAPs 1 and 2.
    bidirectional : bool or None
        True for "B" (the value may be negative), False for "U"; None for FAPs 1, 2.
    direction : str or None
        Positive motion: ``up``, ``down``, ``left``, ``right``, ``forward`` (translations,
        see :data:`DIRECTION_VECTORS`), ``growing`` (pupil dilation) or
        ``concave upward`` (tongue roll); None for FAPs 1, 2.
    fdps : tuple of str
        Feature points the FAP moves (usually one; two for tongue_roll; the pupil for
        the eyeball FAPs, as used in practice; empty for FAPs 1, 2).
    quant_step : float
        Quantisation step of the standard's bitstream coding (unverified, unused here).
    """

    id: int
    name: str
    description: str
    unit: str | None
    bidirectional: bool | None
    direction: str | None
    fdps: tuple[str, ...]
    quant_step: float

    @property
    def fdp(self) -> str | None:
        """The primary feature point moved by this FAP, or None."""
        return self.fdps[0] if self.fdps else None

    @property
    def is_translation(self) -> bool:
        """True if the FAP displaces its FDP along a straight direction in a length unit."""
        return self.unit in LENGTH_FAPU_NAMES and self.direction in DIRECTION_VECTORS


@dataclass(frozen=True)
class FdpRecord:
    """One row of the feature-point table.

    Attributes
    ----------
    id : str
        ``"group.index"``, e.g. ``"9.15"``.
    group : str
        Region name, e.g. ``"outer lip"``.
    description : str
    moved_by : tuple of int
        FAP ids that move this point.
    fapu : tuple of str
        FAPU definitions that use this point, e.g. ``("ES0", "ENS0")``.
    """

    id: str
    group: str
    description: str
    moved_by: tuple[int, ...]
    fapu: tuple[str, ...]


def _read_csv(name: str) -> list[dict[str, str]]:
    text = resources.files("faceforge.mpeg4").joinpath("data", name).read_text(encoding="utf-8")
    return list(csv.DictReader(text.splitlines()))


def _na(value: str) -> str | None:
    value = value.strip()
    return None if value in ("", "na") else value


def _parse_fdps(group: str, subgroup: str) -> tuple[str, ...]:
    """FDP ids from the table's group/subgroup columns.

    ``"2", "1"`` -> ``("2.1",)``; ``"6", "3 and 4"`` -> ``("6.3", "6.4")``;
    ``"3", "na (3.5 pupil ...)"`` -> ``("3.5",)``; ``"na", "na"`` -> ``()``.
    """
    subgroup = subgroup.strip()
    hinted = re.search(r"\((\d+\.\d+)", subgroup)
    if hinted:
        return (hinted.group(1),)
    if _na(group) is None or _na(subgroup) is None:
        return ()
    return tuple(f"{group.strip()}.{index}" for index in re.findall(r"\d+", subgroup))


def _load_fap_table() -> tuple[FapRecord, ...]:
    records = []
    for row in _read_csv("fap_table.csv"):
        uni_bi = _na(row["uni_bi"])
        records.append(
            FapRecord(
                id=int(row["fap"]),
                name=row["name"].strip(),
                description=row["description"].strip(),
                unit=_na(row["units"]),
                bidirectional=None if uni_bi is None else uni_bi == "B",
                direction=_na(row["positive_motion"]),
                fdps=_parse_fdps(row["fdp_group"], row["fdp_subgroup"]),
                quant_step=float(row["quant_step"]),
            )
        )
    if [r.id for r in records] != list(range(1, N_FAPS + 1)):
        raise RuntimeError("faceforge/mpeg4/data/fap_table.csv: FAP ids are not 1..68 in order")
    return tuple(records)


def _load_fdp_table() -> tuple[FdpRecord, ...]:
    records = []
    for row in _read_csv("fdp_feature_points.csv"):
        records.append(
            FdpRecord(
                id=row["fdp"].strip(),
                group=row["group"].strip(),
                description=row["description"].strip(),
                moved_by=tuple(int(x) for x in re.findall(r"\d+", row["moved_by_faps"])),
                fapu=tuple(row["used_for_fapu"].split()),
            )
        )
    return tuple(records)


def _load_fapu_formulas() -> dict[str, str]:
    return {row["fapu"].strip(): row["fdp_formula"].strip() for row in _read_csv("fapu.csv")}


#: the 68 FAPs, ``FAP_TABLE[fap_id - 1]``
FAP_TABLE: tuple[FapRecord, ...] = _load_fap_table()
#: FAP name -> record
FAP_BY_NAME: dict[str, FapRecord] = {r.name: r for r in FAP_TABLE}
#: the 84 feature points in the standard's order
FDP_TABLE: tuple[FdpRecord, ...] = _load_fdp_table()
#: FDP id -> record
FDP_BY_ID: dict[str, FdpRecord] = {r.id: r for r in FDP_TABLE}
#: every valid FDP id (84), in the standard's order
FDP_IDS: tuple[str, ...] = tuple(r.id for r in FDP_TABLE)
#: (subject-left FDP, subject-right FDP) mirror pairs of the standard
LEFT_RIGHT_PAIRS = (
    ("2.4", "2.5"), ("2.6", "2.7"), ("2.8", "2.9"), ("2.11", "2.12"), ("2.13", "2.14"),
    ("3.1", "3.2"), ("3.3", "3.4"), ("3.5", "3.6"), ("3.7", "3.12"), ("3.11", "3.8"),
    ("3.9", "3.10"), ("3.13", "3.14"), ("4.1", "4.2"), ("4.3", "4.4"), ("4.5", "4.6"),
    ("5.1", "5.2"), ("5.3", "5.4"), ("6.3", "6.4"), ("8.3", "8.4"), ("8.5", "8.6"),
    ("8.7", "8.8"), ("8.10", "8.9"), ("9.1", "9.2"), ("9.5", "9.4"), ("9.7", "9.6"),
    ("9.13", "9.14"), ("10.1", "10.2"), ("10.3", "10.4"), ("10.5", "10.6"),
    ("10.7", "10.8"), ("10.9", "10.10"), ("11.3", "11.2"),
)

#: FAPU name -> the standard's formula on FDPs, e.g. ``"ES0 = 3.5.x - 3.6.x"``
FAPU_FORMULAS: dict[str, str] = _load_fapu_formulas()

#: ``(10, 2) int64``: FAP ids (inner, outer) of the lip FAPs that describe the same
#: motion of the inner and outer lip contour (4 <-> 51, ..., 13 <-> 60)
LIP_PAIRS = np.stack([np.arange(4, 14), np.arange(51, 61)], axis=1).astype(np.int64)

#: ``(68,) <U5``: each FAP's unit name, ``""`` for FAPs 1 and 2
FAP_UNITS = np.array([r.unit or "" for r in FAP_TABLE])

#: ``(68, 3) float64``: unit vector of each FAP's positive motion; NaN rows for FAPs
#: that are not translations (high-level, rotations, pupil dilation, tongue roll)
FAP_DIRECTIONS = np.array(
    [DIRECTION_VECTORS[r.direction] if r.is_translation else (np.nan,) * 3 for r in FAP_TABLE],
    dtype=np.float64,
)


def fap_record(fap: int | str) -> FapRecord:
    """The table row of a FAP given by id (1..68) or name.

    Raises
    ------
    KeyError
        For an unknown id or name (the message lists the valid range).
    """
    if isinstance(fap, str):
        try:
            return FAP_BY_NAME[fap]
        except KeyError:
            raise KeyError(f"unknown FAP name {fap!r}; names are those of faceforge.mpeg4.FAP_TABLE") from None
    fap_id = int(fap)
    if not 1 <= fap_id <= N_FAPS:
        raise KeyError(f"FAP id {fap!r} out of range 1..{N_FAPS}")
    return FAP_TABLE[fap_id - 1]
