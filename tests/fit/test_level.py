"""fit.level: a soft-tissue origin moved along up until the fitted line makes the template's angle."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from faceforge.fit.level import frontal_angle, level_origins, point_rows


def _spec(origin, fibre_a, insertion):
    return SimpleNamespace(origin=np.asarray(origin, float), fibre_a=np.asarray(fibre_a, float).reshape(-1, 3),
                           fibre_b=np.zeros((0, 3)), insertion=np.asarray(insertion, float),
                           inner=None, outer=None)


def test_the_origin_is_turned_back_to_the_templates_angle():
    # the template's risorius: level, 4 degrees down (origin lateral and back of the corner)
    t = _spec([[5.6, -1.4, 4.8], [5.6, -2.8, 4.8]], [[4.0, -1.8, 6.8]], [[2.4, -1.5, 8.85], [2.4, -2.45, 8.8]])
    rows = point_rows(t)
    assert rows["origin"] == slice(0, 2) and rows["fibre_a"] == slice(2, 3) and rows["insertion"] == slice(3, 5)
    tp = np.vstack([t.origin, t.fibre_a, t.insertion])
    fitted = tp * 1.3 + [0.0, 0.2, 0.0]
    fitted[rows["origin"]] += [0.0, 2.5, 0.0]                 # the warp lifts the origin: the line tilts up
    fitted[rows["fibre_a"]] += [0.0, 1.2, 0.0]
    before = frontal_angle(fitted[rows["origin"]], fitted[rows["insertion"]])
    assert np.degrees(before) > 25
    out = level_origins(fitted, tp, rows)
    want = frontal_angle(tp[rows["origin"]], tp[rows["insertion"]])
    assert abs(frontal_angle(out[rows["origin"]], out[rows["insertion"]]) - want) < 1e-12
    assert np.array_equal(out[rows["insertion"]], fitted[rows["insertion"]])    # the insertion stays
    moved = out - fitted
    assert np.allclose(moved[:, [0, 2]], 0.0)                                    # only along up
    step = moved[0, 1]
    assert step < 0 and np.allclose(moved[rows["origin"], 1], step)
    assert step < moved[2, 1] < 0                                                # the fibre's point: part of it


def test_a_line_already_at_the_templates_angle_does_not_move():
    t = _spec([[5.0, 1.0, 5.0], [5.0, 0.0, 5.0]], np.zeros((0, 3)), [[2.0, -0.5, 9.0], [2.0, -1.0, 9.0]])
    rows = point_rows(t)
    tp = np.vstack([t.origin, t.insertion])
    assert np.allclose(level_origins(2.0 * tp, tp, rows), 2.0 * tp)
    mirrored = tp * [-1.0, 1.0, 1.0]                                             # a right muscle: the same angle
    assert np.allclose(level_origins(mirrored, tp, rows), mirrored)


def test_the_risorius_is_levelled_by_default():
    """fit.level_muscles is on for the risorius in the shipped config (ris23): after the fit its line
    pulled the corner up 24-49 degrees on the samples, a second smile (docs/notes/recog22.md)."""
    from faceforge.io.config import load_config

    assert "risorius" in list(load_config().get("fit.level_muscles"))
