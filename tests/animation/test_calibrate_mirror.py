"""Calibration on a symmetric rig: right entries take their left twins' responses."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from faceforge.animation.calibrate_mirror import entry_twins, fap_twins, joint_requests, mirror_responses
from faceforge.animation.fap_mapping import load_fap_mapping, with_entry

TEMPLATE = Path(__file__).resolve().parents[2] / "templates" / "fap_mapping.yaml"


@pytest.fixture(scope="module")
def template():
    return load_fap_mapping(TEMPLATE)


def test_fap_twins_are_the_standards_left_right_pairs():
    t = fap_twins()
    assert {6: 7, 12: 13, 31: 32, 37: 38, 53: 54, 59: 60, 8: 9, 10: 11}.items() <= t.items()
    assert not set(t) & set(t.values())      # left numbers only as keys
    assert 3 not in t and 4 not in t         # midline FAPs have no twin


def test_every_left_right_entry_pair_of_the_template_is_found(template):
    twins = entry_twins(template)
    names = {template.entries[r].name: template.entries[l].name for r, l in twins.items()}
    assert names["raise_r_cornerlip"] == "raise_l_cornerlip"
    assert names["stretch_r_cornerlip"] == "stretch_l_cornerlip"
    assert names["squeeze_r_eyebrow"] == "squeeze_l_eyebrow"
    assert names["raise_b_lip_rm"] == "raise_b_lip_lm"
    assert len(twins) == 10
    for r, l in twins.items():                # the right entry moves the mirrored muscles
        right, left = template.entries[r], template.entries[l]
        assert {k.replace("_L", "_R") for k in left.positive} == set(right.positive)


def test_an_entry_that_is_not_the_mirror_image_is_not_a_twin(template):
    i = next(i for i, e in enumerate(template.entries) if e.name == "raise_r_cornerlip")
    gains = {k: 2 * v for k, v in template.entries[i].positive.items()}
    edited = with_entry(template, i, positive=gains)
    names = {edited.entries[r].name for r in entry_twins(edited)}
    assert "raise_r_cornerlip" not in names and "stretch_r_cornerlip" in names


def test_the_left_entry_is_asked_for_both_sides_values(template):
    twins = entry_twins(template)
    r, l = next((r, l) for r, l in twins.items() if template.entries[r].name == "raise_r_cornerlip")
    a, b = template.entries[l].faps[0], template.entries[r].faps[0]
    out = joint_requests(template, twins, {a: np.array([-50.0, 100.0]), b: np.array([-60.0, 100.0])})
    assert out[a].tolist() == [-60.0, -50.0, 100.0] and out[b].tolist() == [-60.0, 100.0]


def test_right_entries_play_their_left_twins_response(template):
    twins = entry_twins(template)
    knots = np.array([[-50.0, -40.0], [100.0, 130.0]])
    cal = template
    for l in set(twins.values()):
        cal = with_entry(cal, l, response=knots)
    cal = mirror_responses(cal, twins)
    for r in twins:
        np.testing.assert_array_equal(cal.entries[r].response, knots)
    untouched = [i for i in range(len(cal.entries)) if i not in twins and i not in twins.values()]
    assert all(cal.entries[i].response is template.entries[i].response for i in untouched)
    assert replace(cal.entries[untouched[0]]) == template.entries[untouched[0]]
