"""Soft-tissue depth at FDP landmarks, for moving skin targets onto the bone (§7).

The depths are the published means of Rhine & Campbell (1980) / Rhine (1983) for
normal-weight adults as tabulated by Taylor (2001), *Forensic Art and Illustration*
(shared asset ``tissue-depth/rhine1983_sw_native_american_normal_female_via_taylor2001.csv``):
millimetres of skin, fat and muscle between a craniofacial landmark and the bone
beneath it. They are facts, copied as numbers.

Each FDP with a bony counterpart is mapped to the nearest craniofacial landmark of
that table; FDPs over cartilage or soft parts only (nose tip, lips, pupils, ears)
have no depth and are not used as skull targets. The lips are left out on purpose:
their outer contour lies over the teeth's crowns, a centimetre below prosthion and
above infradentale, so "depth along the skin normal" would pull the jaws' front up or
down; the ear-face contact points lie over cartilage, not over the supraglenoid point. The depths are
scaled to the head: ``units_per_mm = ES0 / 63 mm`` (ES0 = pupil distance of the head,
63 mm is the adult average), so a decimetre, centimetre or millimetre head, a child
or an adult all get proportionate depths.
"""

from __future__ import annotations

import numpy as np

#: Rhine (1983) via Taylor (2001), mm: code -> depth
DEPTH_MM = {
    "sg": 4.5, "g": 4.5, "n": 7.0, "rhi": 2.5, "mp": 10.0, "pr": 11.0, "id": 12.25, "sm": 10.0,
    "pg": 13.0, "me": 8.0, "fe": 4.0, "mso": 8.5, "or": 6.25, "im": 12.0, "lo": 11.5, "zy": 7.0,
    "sgl": 6.25, "go": 10.5, "ecm2_sup": 18.0, "mm": 17.5, "ecm2_inf": 17.0,
}

#: FDP -> the table's landmark lying beneath it (bilateral codes serve both sides)
FDP_TISSUE_CODE = {
    "2.1": "me",        # bottom of the chin -> menton
    "2.10": "pg",       # chin boss -> pogonion
    "2.11": "pg", "2.12": "pg",         # chin corners -> mental eminence
    "2.13": "go", "2.14": "go",         # jaw angles -> gonion
    "3.7": "lo", "3.12": "lo",          # outer eye corners -> lateral orbital margin
    "3.8": "n", "3.11": "n",            # inner eye corners -> medial orbit, nasion depth
    "4.1": "g", "4.2": "g",             # inner brow ends -> glabella
    "4.3": "mso", "4.4": "mso",         # brow tops -> supraorbital rim
    "4.5": "mso", "4.6": "mso",         # outer brow ends -> supraorbital rim (lateral)
    "5.1": "ecm2_sup", "5.2": "ecm2_sup",   # cheek centres -> over the maxilla's buccal side
    "5.3": "lo", "5.4": "lo",           # cheek bones -> zygomatic body below the orbit
    "8.3": "ecm2_sup", "8.4": "ecm2_sup",   # mouth corners -> buccal alveolar margin (deep)
    "9.6": "n", "9.7": "n",             # upper nose bone edges -> nasion
    "9.12": "rhi",      # nose bump -> rhinion
    "9.15": "mp",       # nose base -> mid-philtrum / anterior nasal spine
    "11.1": "sg",       # hairline, midline -> supraglabella (frontal bone)
    "11.2": "fe", "11.3": "fe",         # hairline, sides -> frontal eminence
    "11.4": "fe", "11.6": "fe",         # top and back of the skull: scalp, taken as thick as at
                                        # the frontal eminence (the table has no vault points)
}

#: adult mean interpupillary distance ES0, mm
AVERAGE_ES0_MM = 63.0


def es0(landmarks: dict) -> float:
    """The head's eye separation ES0 in its own units.

    Pupils 3.5/3.6 when present, else the midpoints of the eye corners (3.7, 3.11) and
    (3.12, 3.8). ``landmarks``: ``{fdp: (3,) float}``.
    """
    if "3.5" in landmarks and "3.6" in landmarks:
        return float(np.linalg.norm(np.subtract(landmarks["3.5"], landmarks["3.6"])))
    left = (np.asarray(landmarks["3.7"]) + landmarks["3.11"]) / 2
    right = (np.asarray(landmarks["3.12"]) + landmarks["3.8"]) / 2
    return float(np.linalg.norm(left - right))


def units_per_mm(landmarks: dict) -> float:
    """Head units per millimetre of an average adult: ``ES0 / 63 mm``."""
    return es0(landmarks) / AVERAGE_ES0_MM


def tissue_depths(fdps, scale: float) -> np.ndarray:
    """Depth (n,) float64 in head units for each FDP id; NaN where no bone lies beneath."""
    return np.array([DEPTH_MM[FDP_TISSUE_CODE[f]] * scale if f in FDP_TISSUE_CODE else np.nan
                     for f in fdps], dtype=np.float64)


def depth_field(query: np.ndarray, sites: np.ndarray, depths: np.ndarray, power: float = 2.0) -> np.ndarray:
    """Smooth depth (k,) at ``query`` (k, 3) by inverse-distance weighting of ``depths`` (n,)
    known at ``sites`` (n, 3) (Shepard interpolation; exact at the sites)."""
    d = np.linalg.norm(query[:, None, :] - sites[None, :, :], axis=2)
    hit = d < 1e-12
    w = 1.0 / np.maximum(d, 1e-12) ** power
    w[hit.any(axis=1)] = hit[hit.any(axis=1)]
    return (w @ depths) / w.sum(axis=1)
