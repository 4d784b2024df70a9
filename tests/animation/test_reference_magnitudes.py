"""Are the FAP magnitudes we calibrate for and the expression presets those of a real face?

Reference: the MakeHuman expression units (tests/data/mh_head_expression_units_caucasian.npz,
CC0, see tests/data/README.md): per-vertex offsets of full-strength facial actions on the MakeHuman head of
samples/makehuman/. Measured at the FAP's FDP along its direction, in the FAPU of that
head, each unit gives how far a real face goes for a comparable action.
"""

from pathlib import Path

import numpy as np
import pytest
import yaml

ROOT = Path(__file__).resolve().parents[2]
UNITS = ROOT / "tests" / "data" / "mh_head_expression_units_caucasian.npz"
LANDMARKS = ROOT / "samples" / "makehuman" / "mh_head_default.fdp.yaml"

#: (unit, FDP, axis, sign of the FAP's positive direction on that axis, FAPU, the FAPs it is
#: comparable to)
ACTIONS = [
    ("mouth-open", "2.1", 1, -1, "MNS", (3,)),                     # open_jaw: chin down
    ("mouth-corner-puller", "8.3", 1, +1, "MNS", (59, 12)),        # raise_l_cornerlip
    ("mouth-corner-puller", "8.3", 0, +1, "MW", (53, 6)),          # stretch_l_cornerlip
    ("eyebrows-left-up", "4.3", 1, +1, "ENS", (33,)),              # raise_l_m_eyebrow
    ("eyebrows-left-inner-up", "4.1", 1, +1, "ENS", (31,)),        # raise_l_i_eyebrow
    ("eyebrows-left-down", "4.1", 1, -1, "ENS", (31,)),            # raise_l_i_eyebrow (negative = down)
    ("mouth-elevation", "8.1", 1, -1, "MNS", (51, 4)),             # lower_t_midlip (negative = up)
    ("eye-left-opened-up", "3.1", 1, -1, "IRISD", (19, 20)),       # close_t_l_eyelid (negative = up)
    ("eye-left-slit", "3.3", 1, +1, "IRISD", (21, 22)),            # close_b_l_eyelid (up)
    ("mouth-protusion", "8.1", 2, +1, "MNS", (17,)),               # push_t_lip (forward)
    ("mouth-protusion", "8.2", 2, +1, "MNS", (16,)),               # push_b_lip (forward)
    ("mouth-pursing", "8.3", 0, -1, "MW", (53, 6)),                # stretch_l_cornerlip (inwards)
    ("mouth-depression-retraction", "8.2", 1, -1, "MNS", (52, 5)), # raise_b_midlip (down)
]


@pytest.fixture(scope="module")
def reference():
    from faceforge.mpeg4 import fapu_from_landmarks

    d = np.load(UNITS)
    names = [str(n) for n in d["names"]]
    lm = yaml.safe_load(LANDMARKS.read_text())["landmarks"]
    pos = {k: np.array(v["position"]) for k, v in lm.items() if v.get("position") is not None}
    vid = {k: v["vertex"] for k, v in lm.items() if v.get("vertex") is not None}
    fapu = fapu_from_landmarks(pos)
    out = {}
    for unit, fdp, axis, sign, fu, faps in ACTIONS:
        delta = d["deltas"][names.index(unit)][vid[fdp], axis]
        for fap in faps:
            out[fap] = max(out.get(fap, 0.0), abs(float(delta)) / fapu.unit(fu))
    return out


def test_reference_units_move_the_right_way(reference):
    # every reference action moves its FDP by a visible amount (tens to a thousand FAPU)
    assert all(20.0 < v < 2000.0 for v in reference.values()), reference


def test_calibration_magnitudes_are_within_a_real_face(reference):
    from faceforge.io.config import load_config

    cfg = load_config()
    mags = cfg.get("animate.calibrate.magnitude")
    asked = {3: cfg.get("animate.calibrate.jaw_magnitude"), 59: mags["MNS"], 12: mags["MNS"],
             53: mags["MW"], 6: mags["MW"], 33: mags["ENS"], 31: mags["ENS"], 51: mags["MNS"], 4: mags["MNS"],
             16: mags["MNS"], 17: mags["MNS"], 52: mags["MNS"], 5: mags["MNS"]}
    for fap, real in reference.items():
        if fap in (19, 20, 21, 22):   # the eyelids are kinematic: nothing to calibrate
            continue
        # what calibration asks of a FAP is a real action, not more than ~1.5x a full-strength one,
        # and not a token amount either
        assert 0.1 * real <= asked[fap] <= 1.5 * real, (fap, asked[fap], real)


@pytest.mark.parametrize("table", ["expressions", "visemes"])
def test_presets_stay_within_a_real_face(reference, table):
    from faceforge.animation.fap_mapping import load_fap_mapping

    m = load_fap_mapping(ROOT / "templates" / "fap_mapping.yaml")
    presets = getattr(m, table)
    assert presets
    for name, row in presets.items():
        for fap, real in reference.items():
            assert abs(row[fap - 1]) <= 1.5 * real, (name, fap, row[fap - 1], real)


def test_speech_moves_the_mouth_less_than_a_full_facial_action(reference):
    # every viseme's jaw and lip values stay under the full-strength unit of the same action
    from faceforge.animation.fap_mapping import load_fap_mapping

    m = load_fap_mapping(ROOT / "templates" / "fap_mapping.yaml")
    for name, row in m.visemes.items():
        for fap in (3, 16, 17, 53, 6, 52, 5):
            assert abs(row[fap - 1]) <= reference[fap], (name, fap, row[fap - 1], reference[fap])
