"""Expression presets (FAP 2) and their weights."""

from __future__ import annotations

import numpy as np
import pytest

from faceforge.exceptions import FapError
from faceforge.mpeg4 import EXPRESSIONS, expression_track, expression_weights, format_fap, parse_fap
from faceforge.mpeg4.expressions import EXPRESSION_CODES, ramp_envelope


def test_codes_follow_the_standard():
    assert EXPRESSION_CODES == {"joy": 1, "sadness": 2, "anger": 3, "fear": 4, "disgust": 5, "surprise": 6}


@pytest.mark.parametrize("name", EXPRESSIONS)
def test_preset_ramps_in_holds_and_out(name):
    track = expression_track(name, intensity=0.7, fps=25, seconds=2.0, ramp=0.4)
    assert track.n_frames == 51 and track.fps == 25
    assert track.mask[:, 1].all() and not track.mask[:, 2:].any()
    assert np.all(track.values[:, 2:] == 0)  # no low-level FAP: neutral
    assert np.all(track.expression[:, 0] == EXPRESSION_CODES[name])
    assert np.all(track.expression[:, 2:] == 0)
    intensity = track.expression[:, 1]
    assert intensity[0] == 0 and intensity[-1] == 0
    assert intensity.max() == pytest.approx(0.7 * 63)
    ramp_frames = 10  # 0.4 s at 25 fps
    assert np.all(np.diff(intensity[: ramp_frames + 1]) > 0)
    assert np.all(np.diff(intensity[-ramp_frames - 1 :]) < 0)
    np.testing.assert_allclose(intensity[ramp_frames:-ramp_frames], 0.7 * 63)
    np.testing.assert_allclose(intensity, intensity[::-1], atol=1e-12)  # symmetric in and out
    weights = expression_weights(track.expression)
    k = EXPRESSIONS.index(name)
    np.testing.assert_allclose(weights[:, k], intensity / 63)
    assert np.all(np.delete(weights, k, axis=1) == 0)
    assert parse_fap(format_fap(track)) == track


def test_ramp_longer_than_half_becomes_a_peak():
    env = ramp_envelope(11, 10.0, ramp=5.0)
    assert env[0] == env[-1] == 0 and env[5] == 1.0 and np.argmax(env) == 5
    assert np.all(ramp_envelope(5, 10.0, ramp=0.0) == 1.0)


def test_weights_add_both_slots_and_clip():
    expression = np.array([[1, 63, 1, 63, 0, 0], [3, 31.5, 6, 63, 0, 0], [0, 63, 9, 63, 0, 0]], dtype=float)
    w = expression_weights(expression)
    np.testing.assert_allclose(w[0], [1, 0, 0, 0, 0, 0])  # 2.0 clipped
    np.testing.assert_allclose(w[1], [0, 0, 0.5, 0, 0, 1])
    np.testing.assert_allclose(w[2], 0)  # neutral and unknown codes


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"name": "smug"}, "valid: joy, sadness, anger, fear, disgust, surprise"),
        ({"name": "joy", "intensity": 1.5}, "intensity"),
        ({"name": "joy", "fps": 0}, "fps"),
        ({"name": "joy", "seconds": float("nan")}, "seconds"),
        ({"name": "joy", "ramp": -1}, "ramp"),
    ],
)
def test_bad_arguments_are_user_errors(kwargs, match):
    with pytest.raises(FapError, match=match):
        expression_track(**kwargs)
