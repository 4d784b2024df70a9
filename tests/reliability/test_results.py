"""Bad results must not pass as good (issue 28): FAP values past the standard's range, a
frame folding many edges, a second head in the mesh, failed fit checks."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from faceforge.animation.checks import FrameReport, fold_limit
from faceforge.animation.head_parts import detached_vertices
from faceforge.exceptions import ChecksFailed, FapError, StageError
from faceforge.mpeg4 import FapWarning, parse_fap
from faceforge.mpeg4.fap_range import LIMITS, MAX_ANGLE_UNITS, MAX_LENGTH_UNITS
from faceforge.pipeline.fit_checks import enforce_checks, failed_checks


def mask_line(*faps):
    bits = ["0"] * 68
    for f in faps:
        bits[f - 1] = "1"
    return " ".join(bits)


def test_fap_values_past_the_range_are_clamped_with_a_warning():
    text = (f"2.1 t 25 2\n{mask_line(3, 49)}\n0 1e9 1e300\n{mask_line(3, 49)}\n1 -500 -2000\n")
    with pytest.warns(FapWarning, match=r"FAP 3 open_jaw up to 1e\+09 MNS in 1 frame .*FAP 49 head_yaw up to "
                                        r"1e\+300 AU"):
        track = parse_fap(text, "t.fap")
    assert track.fap(3).tolist() == [MAX_LENGTH_UNITS, -500.0]
    assert track.fap(49).tolist() == [MAX_ANGLE_UNITS, -2000.0]
    assert np.degrees(MAX_ANGLE_UNITS * 1e-5) == pytest.approx(90.0, abs=1e-3)
    with pytest.raises(FapError, match="past the standard's range"):
        parse_fap(text, "t.fap", strict=True)


def test_values_inside_the_range_are_untouched():
    text = f"2.1 t 25 1\n{mask_line(3, 19, 48)}\n0 3072 -1024 157079\n"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        track = parse_fap(text)
    assert track.fap(3)[0] == 3072 and track.fap(19)[0] == -1024 and track.fap(48)[0] == 157079
    assert np.isinf(LIMITS[:2]).all() and np.isfinite(LIMITS[2:]).all()


def test_a_frame_folding_hundreds_of_edges_is_not_ok():
    base = dict(frames=10, non_finite=0, inverted_triangles=0, skin_inside_skull=0, max_displacement=0.1)
    assert FrameReport(**base, folded_edges=12, folded_max_per_frame=12, fold_limit=fold_limit(1400)).ok
    bad = FrameReport(**base, folded_edges=408, folded_max_per_frame=408, fold_limit=fold_limit(1400))
    assert not bad.ok and bad.as_dict()["ok"] is False and bad.as_dict()["fold_limit"] == 32
    assert fold_limit(12_000) == 60


def _quad(offset):
    v = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]) + offset
    return v, np.array([[0, 1, 2], [0, 2, 3]])


def test_a_second_head_without_landmarks_is_detached_and_an_inner_piece_is_not():
    head, hf = _quad(0.0)
    eye, ef = _quad(0.0)
    eye = 0.5 + 0.1 * (eye - 0.5)                        # inside the head's box: an eyeball
    eye[:, 2] = 0.0
    other, of = _quad(np.array([3.0, 0.0, 0.0]))         # beside it: another head
    v = np.vstack([head, eye, other, [[9.0, 9.0, 9.0]]])  # and a stray vertex far away
    f = np.vstack([hf, ef + 4, of + 8])
    out = detached_vertices(v, f, landmark_vertices=[0, 2])
    assert out.tolist() == [False] * 8 + [True] * 5
    assert not detached_vertices(v, f, []).any()


REPORT = {"checks": {"landmarks_within_1pct": True, "skull_inside_98pct": False, "muscles_inside_98pct": True,
                     "muscles_poke_below_1pct": False},
          "landmarks": {"max_residual": 0.0}, "skull": {"inside_fraction": 0.0},
          "muscles": {"inside_fraction": 0.99, "max_outside_rel": 0.051}}


def test_a_failed_fit_check_is_an_error_naming_the_check_and_the_figure():
    assert failed_checks(REPORT) == [
        "skull_inside_98pct (skull 0.0% inside the skin, needs 98%)",
        "muscles_poke_below_1pct (muscles poke 5.1% of the diagonal out of the skin, needs <= 1%)"]
    with pytest.raises(ChecksFailed, match=r"^head.obj: the fit failed its checks: skull_inside_98pct "
                                         r"\(skull 0.0% inside.*fit.allow_failed_checks=true"):
        enforce_checks(REPORT, False, "head.obj")
    seen = []
    enforce_checks(REPORT, True, "head.obj", seen.append)
    assert len(seen) == 2 and all("kept" in s for s in seen)
    enforce_checks({"checks": {"a": True}}, False, "head.obj")
