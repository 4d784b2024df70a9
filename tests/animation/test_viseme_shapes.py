"""Are the fourteen visemes of the template mapping distinct mouth shapes (issue 25)?

Template level, in seconds: each viseme's row of FAPs is read as the standard defines it (each
lip FAP moves its FDP along its direction by value x FAPU; open_jaw carries the lower lip down
as the mapping's coupling says, lower-lip FAPs then being absolute), on the FAPU of the MakeHuman
sample, in mm. What the rig makes of those rows on the three sample heads is measured by
``benchmarks/bench_visemes.py`` (too slow for a test: each head needs its calibration).
"""

from pathlib import Path

import numpy as np
import pytest
import yaml

ROOT = Path(__file__).resolve().parents[2]
LANDMARKS = ROOT / "samples" / "makehuman" / "mh_head_default.fdp.yaml"
#: the lip FDPs whose motion is a mouth shape (as bench_visemes.SHAPE_FDPS)
LIP_FDPS = ("2.2", "2.3", "2.4", "2.5", "2.6", "2.7", "2.8", "2.9",
            "8.1", "8.2", "8.3", "8.4", "8.5", "8.6", "8.7", "8.8")
#: a pair of visemes closer than this (RMS over the lip FDPs) is one mouth shape to the eye
MIN_PAIR_MM = 1.0
#: a viseme closer than this to the rest mouth looks neutral
MIN_FROM_NEUTRAL_MM = 1.2


def intended_shapes(mapping, names, fapu_mm: dict) -> np.ndarray:
    """(k, len(LIP_FDPS), 3) mm: the lip FDPs' motion each viseme row asks for."""
    from faceforge.mpeg4.tables import FAP_TABLE, DIRECTION_VECTORS

    coupled = {f: (e.coupling.get(3, 0.0)) for e in mapping.entries for f in e.faps}
    out = np.zeros((len(names), len(LIP_FDPS), 3))
    for k, name in enumerate(names):
        row = mapping.visemes[name]
        jaw = row[2]
        for rec in FAP_TABLE:
            if rec.fdp not in LIP_FDPS or rec.direction not in DIRECTION_VECTORS:
                continue
            v = row[rec.id - 1]
            carried = coupled.get(rec.id, 0.0) * jaw        # FAPU the jaw already moves it (<= 0)
            if carried and np.sign(v) == np.sign(carried):
                v = np.sign(v) * max(abs(v) - abs(carried), 0.0)
            vec = np.asarray(DIRECTION_VECTORS[rec.direction])
            out[k, LIP_FDPS.index(rec.fdp)] += (v + carried) * fapu_mm[rec.unit] * vec
    return out


@pytest.fixture(scope="module")
def shapes():
    from faceforge.animation.fap_mapping import load_fap_mapping
    from faceforge.mpeg4 import fapu_from_landmarks
    from faceforge.mpeg4.visemes import VISEMES

    lm = yaml.safe_load(LANDMARKS.read_text())["landmarks"]
    pos = {k: np.array(v["position"]) for k, v in lm.items() if v.get("position") is not None}
    fapu = fapu_from_landmarks(pos)
    # the head's size in mm: its mouth width MW0 taken as 50 mm (an adult's, Fromkin 1964)
    mm = fapu.unit("MW") * 1024 / 50.0
    fapu_mm = {u: fapu.unit(u) / mm for u in ("MNS", "MW", "ENS", "ES", "IRISD")}
    m = load_fap_mapping(ROOT / "templates" / "fap_mapping.yaml")
    names = [n for n in VISEMES if n in m.visemes]
    return names, intended_shapes(m, names, fapu_mm)


def test_the_table_has_all_fourteen_visemes(shapes):
    names, _ = shapes
    assert len(names) == 14


def test_no_viseme_is_a_neutral_mouth(shapes):
    names, s = shapes
    rms = np.sqrt((s ** 2).sum(-1).mean(-1))
    low = {n: round(float(r), 2) for n, r in zip(names, rms) if r < MIN_FROM_NEUTRAL_MM}
    assert not low, low


def test_every_two_visemes_are_different_mouth_shapes(shapes):
    names, s = shapes
    d = np.sqrt(((s[:, None] - s[None]) ** 2).sum(-1).mean(-1))
    close = [(names[i], names[j], round(float(d[i, j]), 2)) for i in range(len(names))
             for j in range(i + 1, len(names)) if d[i, j] < MIN_PAIR_MM]
    assert not close, close


def test_the_shapes_follow_the_phonetics(shapes):
    # the open vowel opens widest, the rounded ones narrow the mouth, the spread ones widen it,
    # the bilabial closes the lips (inner lip gap: FDP 2.2 y - 2.3 y change; width: 8.4 - 8.3 x)
    names, s = shapes
    k22, k23, k83, k84 = (LIP_FDPS.index(f) for f in ("2.2", "2.3", "8.3", "8.4"))
    opening = {n: s[k, k22, 1] - s[k, k23, 1] for k, n in enumerate(names)}
    width = {n: s[k, k83, 0] - s[k, k84, 0] for k, n in enumerate(names)}
    assert max(opening, key=opening.get) == "a"                             # the widest opening
    assert opening["p_b_m"] <= 0.0                                          # lips closed (pressed)
    assert all(width[n] < -3.0 for n in ("u", "o", "ch_j_sh", "r"))         # rounded
    assert all(width[n] > 3.0 for n in ("i", "e", "s_z"))                   # spread
    assert opening["k_g"] > opening["t_d"] and opening["a"] > opening["e"] > opening["i"]
