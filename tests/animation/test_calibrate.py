"""Calibration on a synthetic head whose response is known and nonlinear."""

import numpy as np
import pytest

from faceforge.animation.calibrate import (Probe, calibrate_mapping, invert_monotone, measure,
                                         measure_coupling, summarize)
from faceforge.animation.fap_mapping import JawLevers, fap_controls, mapping_from_dict

FAPU = {k: v / 1024 for k, v in {"MNS": 0.2, "MW": 0.5, "ENS": 0.45, "ES": 0.6, "IRISD": 0.1}.items()}
FAPU["AU"] = 1e-5
LEVERS = JawLevers(1.0, 1.0)
UP, LEFT, DOWN = np.array([0.0, 1.0, 0.0]), np.array([1.0, 0.0, 0.0]), np.array([0.0, -1.0, 0.0])

MAPPING = {
    "jaw_limits": {"pitch": [-0.02, 0.45], "yaw": [-0.1, 0.1], "protrusion": [-0.04, 0.1]},
    "entries": [
        {"fap": 3, "name": "open_jaw", "fapu": "MNS", "jaw": {"dof": "pitch", "gain": 1.0}},
        {"fap": [59, 12], "name": "raise_l_cornerlip", "fapu": "MNS",
         "positive": {"zyg": 0.002}, "negative": {"dep": 0.004}},
        {"fap": 31, "name": "raise_l_i_eyebrow", "fapu": "ENS", "positive": {"front": 0.001}},
        {"fap": [52, 5], "name": "raise_b_midlip", "fapu": "MNS", "coupling": {3: -0.5},
         "negative": {"dep": 0.001}},
    ],
}
MUSCLES = ["zyg", "dep", "front"]


def synthetic_head(mapping, faps):
    """Five probe vertices moved by saturating (tanh) functions of the controls.

    v0: lip corner, up by 0.05 tanh(3 zyg) - 0.03 tanh(2 dep); v1/v2: brow, up by 0.12
    tanh(2 front) (v2 also carries some of it: a relative probe); v3: upper lip (fixed);
    v4: lower lip, down by 0.8 x jaw arc + 0.04 dep (heads are ~2 units, MNS0 = 0.2).
    """
    c, jaw = fap_controls(mapping, faps, MUSCLES, FAPU, LEVERS)
    k = len(faps)
    skin = np.zeros((k, 5, 3))
    skin[:, 0, 1] = 0.05 * np.tanh(3 * c[:, 0]) - 0.03 * np.tanh(2 * c[:, 1])
    skin[:, 1, 1] = 0.12 * np.tanh(2 * c[:, 2])
    skin[:, 2, 1] = 0.3 * skin[:, 1, 1]
    skin[:, 4, 1] = -0.8 * np.sin(jaw[:, 0]) * LEVERS.pitch - 0.04 * c[:, 1]
    return skin


PROBES = {
    59: Probe(59, 0, -1, UP, FAPU["MNS"]), 12: Probe(12, 0, -1, UP, FAPU["MNS"]),
    31: Probe(31, 1, 2, UP, FAPU["ENS"]),
    3: Probe(3, 4, 3, DOWN, FAPU["MNS"]),
    52: Probe(52, 4, -1, UP, FAPU["MNS"]),
}
REQUESTED = {59: [-60.0, 60.0, 150.0], 31: [50.0, 150.0], 3: [100.0, 300.0], 52: [-100.0]}


def twin_invert(drives, achieved, requested):
    """Plain twin of invert_monotone for one sign: bisection on the interpolated curve."""
    out = []
    for r in requested:
        s = np.sign(r)
        d = np.concatenate([[0.0], drives[np.sign(drives) == np.sign(drives[0])]])
        a = np.concatenate([[0.0], achieved[np.sign(drives) == np.sign(drives[0])]])
        o = np.argsort(np.abs(d))
        d, a = d[o], np.maximum.accumulate(np.maximum(s * a[o], 0))
        lo, hi = 0.0, abs(d[-1])
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            if np.interp(mid, np.abs(d), a) < abs(r):
                lo = mid
            else:
                hi = mid
        out.append(np.sign(d[-1]) * hi)
    return np.array(out)


def test_invert_monotone_matches_bisection_twin():
    drives = np.array([50.0, 100.0, 150.0, 200.0])
    achieved = 80 * np.tanh(drives / 120)
    req = np.array([10.0, 30.0, 55.0])
    assert np.allclose(invert_monotone(drives, achieved, req), twin_invert(drives, achieved, req),
                       atol=1e-6)


def test_invert_monotone_wrong_sense_is_nan_and_plateaus_are_skipped():
    drives = np.array([1.0, 2.0, 3.0])
    assert np.isnan(invert_monotone(drives, -drives, np.array([1.0]))).all()
    r = invert_monotone(drives, np.array([1.0, 1.0, 2.0]), np.array([1.0, 1.5]))
    assert np.allclose(r, [1.0, 2.0])   # (2, 1) is on the plateau: (1, 1) -> (3, 2)


def test_measure_relative_probe():
    rest = np.zeros((3, 3))
    moved = rest.copy()
    moved[1, 1], moved[2, 1] = 0.5, 0.2
    assert measure(rest, moved, Probe(1, 1, 2, UP, 0.1)) == pytest.approx(3.0)


def test_calibration_makes_requested_equal_achieved():
    m = mapping_from_dict(MAPPING)
    rest = np.zeros((5, 3))
    calibrated, rows = calibrate_mapping(m, synthetic_head, rest, PROBES, REQUESTED, refine=3)
    s = summarize(rows)
    assert s["all_uncalibrated"]["median_relative_error"] > 0.2      # the guess was off
    assert s["all"]["median_relative_error"] < 0.01
    assert max(r.error for r in rows) < 0.03
    # both twins of the corner entry were reported, each on its own probe
    assert {r.fap for r in rows} >= {59, 12, 31, 3, 52}
    # requested values the mapping can never reach (saturating tanh) stay honest
    m2, rows2 = calibrate_mapping(m, synthetic_head, rest, PROBES, {31: [2000.0]})
    assert rows2[0].achieved < 2000.0 * 0.9
    # an FDP the mapping cannot move at all: drive NaN, reported as null (JSON-safe)
    import json

    m3, rows3 = calibrate_mapping(m, synthetic_head, rest, {31: Probe(31, 3, -1, UP, FAPU["ENS"])},
                                  {31: [50.0]})
    assert np.isnan(rows3[0].drive) and json.dumps(rows3[0].as_dict(), allow_nan=False)


def test_coupling_is_measured_from_open_jaw():
    m = mapping_from_dict(MAPPING)
    m2 = measure_coupling(m, synthetic_head, np.zeros((5, 3)), PROBES, value=200.0)
    ratio = m2.entry_of(52).coupling[3]
    expected = -0.8 * np.sin(np.arctan2(200 * FAPU["MNS"], 1.0)) / (200 * FAPU["MNS"])
    assert ratio == pytest.approx(expected, rel=1e-9)


def test_calibrated_knots_are_always_a_loadable_monotone_curve():
    from faceforge.animation.calibrate import _monotone_knots
    from faceforge.animation.fap_mapping import mapping_from_dict, mapping_to_dict, with_entry

    rng = np.random.default_rng(3)
    m = mapping_from_dict(MAPPING)
    for _ in range(200):
        req = np.array([-100.0, -50.0, 50.0, 100.0])
        knots = _monotone_knots(np.column_stack([req, rng.normal(0, 80, 4)]))
        d = knots[:, 1]
        assert np.all(np.diff(d) >= 0) or np.all(np.diff(d) <= 0)
        assert np.all(np.sign(d[knots[:, 0] > 0]) * np.sign(d[knots[:, 0] < 0]) <= 0)
        back = mapping_from_dict(mapping_to_dict(with_entry(m, 1, response=knots)))   # loader accepts it
        assert np.allclose(back.entries[1].response, knots)


def test_inversion_holds_at_a_saturation_knee():
    drives = np.array([50.0, 100.0, 150.0])
    linear = invert_monotone(drives, 0.5 * drives, np.array([150.0]))
    assert linear[0] == pytest.approx(300.0)                 # straight line: extrapolated
    flat = invert_monotone(drives, np.array([40.0, 44.0, 45.0]), np.array([150.0]))
    assert flat[0] == pytest.approx(150.0)                   # saturated: held at the last sample


def test_lip_twins_driven_together_are_fitted_to_their_mean():
    """An entry drives its outer and inner FAP with one control. When the inner FDP moves
    only 0.8 x the outer one, the fit favours neither: the outer overshoots and the inner
    falls short by the same relative error, (1 - 0.8) / (1 + 0.8) = 11.1 %."""
    def head(mapping, faps):
        skin = synthetic_head(mapping, faps)
        return np.concatenate([skin, skin[:, :1] * 0.8], axis=1)    # v5: the inner twin of v0

    probes = {59: Probe(59, 0, -1, UP, FAPU["MNS"]), 12: Probe(12, 5, -1, UP, FAPU["MNS"])}
    m = mapping_from_dict(MAPPING)
    _, rows = calibrate_mapping(m, head, np.zeros((6, 3)), probes, {59: [60.0]}, refine=3,
                                tolerance=1e-4)
    err = {r.fap: (r.achieved - r.requested) / r.requested for r in rows}
    assert err[59] == pytest.approx(1 / 9, abs=0.005) and err[12] == pytest.approx(-1 / 9, abs=0.005)


def test_refinement_runs_until_met_and_stops_where_held():
    """A value refines until it is within ``tolerance`` of its request (a strongly concave
    response, as lip separation under open_jaw, needs more than two secant steps), and no
    further: a met value and a saturated one (drive held at the knee) cost no more poses."""
    calls = []

    def head(mapping, faps):
        calls.append(len(faps))
        return synthetic_head(mapping, faps)

    m = mapping_from_dict(MAPPING)
    probes = {31: PROBES[31]}
    # the brow's tanh response: 150 ENS sits far up the curve, above the sampled drives
    _, two = calibrate_mapping(m, head, np.zeros((5, 3)), probes, {31: [150.0]}, refine=2,
                               tolerance=1e-4)
    calls.clear()
    _, rows = calibrate_mapping(m, head, np.zeros((5, 3)), probes, {31: [150.0]}, refine=8,
                                tolerance=1e-4)
    assert abs(two[0].error) > 1e-4 and rows[0].error <= 1e-4
    assert 1 + 3 < len(calls) < 1 + 9 + 1        # sampling, more than two steps, verification
    calls.clear()
    _, sat = calibrate_mapping(m, head, np.zeros((5, 3)), probes, {31: [2000.0]}, refine=8)
    assert sat[0].error > 0.1 and len(calls) <= 4  # sampling, one trial, held, verification


def test_saturated_rows_are_those_whose_muscles_are_all_at_full_contraction():
    from faceforge.animation.calibrate import CalibrationRow, saturated

    m = mapping_from_dict(MAPPING)
    corner, jaw = m.entry_of(59), m.entry_of(3)        # zyg 0.002 up, dep 0.004 down
    assert saturated(corner, 500.0, 1.0) and not saturated(corner, 499.0, 1.0)
    assert saturated(corner, -250.0, 1.0) and not saturated(corner, -200.0, 1.0)
    assert not saturated(corner, float("nan"), 1.0) and not saturated(jaw, 1e9, 1.0)
    rows = [CalibrationRow(59, "c", "lip", 100.0, 0.0, 100.0 * f, 1.0, s)
            for f, s in ((1.0, False), (0.95, False), (0.5, True))]
    summary = summarize(rows)["all"]
    assert (summary["within_10_percent"], summary["saturated"]) == (2, 1)


def test_a_side_that_moves_the_fdp_the_wrong_way_gets_zero_drive():
    """Both signs of the entry contract ``dep``, which lowers the corner: negative requests are
    met, positive ones are unreachable and must leave the skin at rest (drive 0), not take the
    negative side's slope through (0, 0) and lower the corner they were to raise."""
    from faceforge.animation.fap_mapping import response_curve

    m = mapping_from_dict({**MAPPING, "entries": [
        {"fap": [59, 12], "name": "raise_l_cornerlip", "fapu": "MNS",
         "positive": {"dep": 0.004}, "negative": {"dep": 0.004}}]})
    cal, rows = calibrate_mapping(m, synthetic_head, np.zeros((5, 3)), PROBES, {59: [-60.0, 60.0]})
    by_req = {r.requested: r for r in rows if r.fap == 59}
    assert by_req[-60.0].error < 0.01
    assert np.isnan(by_req[60.0].drive) and by_req[60.0].achieved == pytest.approx(0.0, abs=1e-9)
    assert response_curve(cal.entries[0].response, np.array([30.0, 60.0, 120.0])) == pytest.approx(0.0)


def test_drive_cap_reaches_full_contraction():
    from faceforge.animation.calibrate import drive_cap

    e = mapping_from_dict({**MAPPING, "entries": [
        {"fap": 39, "name": "puff_l_cheek", "fapu": "ES", "positive": {"zyg": 0.001, "front": 0.0005},
         "negative": {"dep": 0.01}}]}).entries[0]
    cap = drive_cap(e, np.array([-80.0, -40.0, 40.0, 80.0]), 20.0, 1.0)
    # positive: 1 / 0.0005 = 2000 > 20 x 80; negative: 20 x |request| > 1 / 0.01
    assert cap == pytest.approx([1600.0, 800.0, 2000.0, 2000.0])


def test_best_sampled_keeps_the_peak_of_a_curve_that_turns_back():
    from faceforge.animation.calibrate import best_sampled

    drives = np.array([-50.0, 100.0, 300.0, 600.0, 1200.0, 1500.0, 1500.0])
    achieved = np.array([-20.0, 20.0, 40.0, 30.0, 10.0, 10.0, 10.0])   # peaks at 300, then falls
    out = best_sampled(drives, achieved, np.array([75.0, 150.0, -100.0]),
                       np.array([1500.0, 1500.0, -80.0]))
    assert out == pytest.approx([300.0, 300.0, -50.0])
    # a saturated plateau: the least drive among (near-)equal results
    assert best_sampled(np.array([500.0, 900.0, 1000.0]), np.array([60.0, 60.0, 60.0]),
                        np.array([75.0]), np.array([1000.0])) == pytest.approx([500.0])


def test_an_unreachable_request_is_held_at_the_knee():
    """A request past what the muscles can do (400 ENS; the brow reaches 183 at full contraction)
    keeps a knot at the drive that puts them at full contraction (``front``: 1 / 0.001), not
    past it where the secant ran on to the cap (20 x 400: the same pose): playback of half the
    request then contracts the muscle half-way, not fully."""
    m = mapping_from_dict(MAPPING)
    cal, rows = calibrate_mapping(m, synthetic_head, np.zeros((5, 3)), {31: PROBES[31]},
                                  {31: [400.0]}, refine=8)
    assert rows[0].saturated and rows[0].drive == pytest.approx(1000.0)
    assert rows[0].achieved == pytest.approx(0.12 * 0.7 * np.tanh(2.0) / FAPU["ENS"])
    faps = np.zeros((1, 68))
    faps[0, 30] = 200.0
    c, _ = fap_controls(cal, faps, MUSCLES, FAPU, LEVERS)
    assert c[0, MUSCLES.index("front")] == pytest.approx(0.5)


def test_muscle_reach_is_fitted_so_the_lip_alone_lands_with_the_jaw():
    from faceforge.animation.calibrate_jaw import fit_muscle_reach
    from faceforge.animation.fap_mapping import with_entry

    m = measure_coupling(mapping_from_dict(MAPPING), synthetic_head, np.zeros((5, 3)), PROBES, value=200.0)
    k = [e.name for e in m.entries].index("raise_b_midlip")
    # the depressor moves the lip 205 MNS at most (0.04 units); a response that meets it linearly
    m = with_entry(m, k, response=np.array([[-205.0, -1000.0]]), muscle_reach=400.0)
    rest = np.zeros((5, 3))
    frame = np.zeros((1, 68))
    frame[0, [51, 4]] = -870.0
    before = measure(rest, synthetic_head(m, frame), PROBES[52])[0]
    fitted, report = fit_muscle_reach(m, synthetic_head, rest, PROBES, {52: [-870.0, 100.0]}, steps=3)
    after = measure(rest, synthetic_head(fitted, frame), PROBES[52])[0]
    assert before > -0.85 * 870.0                          # a reach too large: the jaw opened too little
    assert after == pytest.approx(-870.0, rel=0.02)       # alone: the jaw opens for the rest
    assert fitted.entries[k].muscle_reach == pytest.approx(report["raise_b_midlip"][0])
    assert 150.0 < fitted.entries[k].muscle_reach < 260.0   # about what the depressor gives
