"""The FAP / FDP / FAPU tables: complete, cross-consistent and mirror-symmetric."""

from __future__ import annotations

import numpy as np
import pytest

from faceforge.mpeg4 import tables
from faceforge.mpeg4.tables import (
    DIRECTION_VECTORS,
    FAP_BY_NAME,
    FAP_DIRECTIONS,
    FAP_TABLE,
    FAPU_FORMULAS,
    FDP_BY_ID,
    FDP_TABLE,
    LIP_PAIRS,
    fap_record,
)


def test_sizes_and_ids():
    assert [r.id for r in FAP_TABLE] == list(range(1, 69))
    assert len(FDP_TABLE) == 84 and len(FDP_BY_ID) == 84  # ids unique
    assert len(FAP_BY_NAME) == 68  # names unique
    assert set(FAPU_FORMULAS) == set(tables.FAPU_NAMES)


def test_high_level_faps_have_no_unit_or_point():
    for fap in FAP_TABLE[:2]:
        assert fap.unit is None and fap.direction is None and fap.fdp is None and not fap.is_translation
    assert all(r.unit in tables.FAPU_NAMES for r in FAP_TABLE[2:])


def test_every_fap_point_lists_the_fap_and_back():
    for fap in FAP_TABLE[2:]:
        assert fap.fdps, fap.name
        for fdp in fap.fdps:
            assert fap.id in FDP_BY_ID[fdp].moved_by, (fap.name, fdp)
    for fdp in FDP_TABLE:
        for fap_id in fdp.moved_by:
            assert fdp.id in fap_record(fap_id).fdps, (fdp.id, fap_id)


def test_fapu_points_appear_in_their_formulas():
    """Every FDP the point table marks for a FAPU is in that FAPU's formula (or its mirror
    twin is: the table marks both pupils for ENS0, whose formula names 3.5)."""
    twin = {"3.6": "3.5"}
    for fdp in FDP_TABLE:
        for fapu in fdp.fapu:
            formula = FAPU_FORMULAS[fapu.rstrip("0")]
            assert f"{fdp.id}." in formula or f"{twin.get(fdp.id)}." in formula, (fdp.id, fapu)


def test_lip_pairs_describe_the_same_motion():
    assert LIP_PAIRS.shape == (10, 2)
    for inner, outer in LIP_PAIRS:
        a, b = fap_record(int(inner)), fap_record(int(outer))
        assert b.name == a.name + "_o"
        assert (a.unit, a.direction, a.bidirectional) == (b.unit, b.direction, b.bidirectional)
        assert a.fdp.startswith("2.") and b.fdp.startswith("8.")


def _mirror_name(name: str) -> str | None:
    for left, right in (("_l_", "_r_"), ("_lm", "_rm")):
        if left in name:
            return name.replace(left, right)
    return None


def test_left_right_twins_mirror_in_x():
    twins = 0
    for fap in FAP_TABLE:
        other = _mirror_name(fap.name)
        if other is None or not fap.is_translation:
            continue
        twin = FAP_BY_NAME[other]
        twins += 1
        assert twin.unit == fap.unit
        a, b = FAP_DIRECTIONS[fap.id - 1], FAP_DIRECTIONS[twin.id - 1]
        np.testing.assert_array_equal(b, a * np.array([-1.0, 1.0, 1.0]))
    assert twins >= 20


def test_direction_vectors_are_unit_and_only_for_translations():
    for fap in FAP_TABLE:
        row = FAP_DIRECTIONS[fap.id - 1]
        if fap.is_translation:
            assert np.linalg.norm(row) == 1.0
            assert tuple(row) == DIRECTION_VECTORS[fap.direction]
        else:
            assert np.all(np.isnan(row))
    # named physical facts of the standard
    assert fap_record("open_jaw").direction == "down" and fap_record("open_jaw").fdp == "2.1"
    assert fap_record("raise_l_i_eyebrow").fdp == "4.1" and fap_record("raise_l_i_eyebrow").unit == "ENS"
    assert fap_record(47).fdps == ("6.3", "6.4")


@pytest.mark.parametrize("bad", [0, 69, "no_such_fap"])
def test_fap_record_rejects_unknown(bad):
    with pytest.raises(KeyError):
        fap_record(bad)
