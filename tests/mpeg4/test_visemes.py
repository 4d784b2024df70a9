"""FAP 1 viseme tracks: codes, cross-fades, the .fap round trip, errors."""

import numpy as np
import pytest

from faceforge.animation.fap_mapping import viseme_weights
from faceforge.exceptions import FapError
from faceforge.mpeg4 import VISEME_CODES, VISEMES, read_fap, viseme_track, write_fap


def test_the_codes_are_the_standards_one_to_fourteen():
    assert [VISEME_CODES[n] for n in VISEMES] == list(range(1, 15))


def test_each_viseme_is_held_whole_and_the_fades_sum_to_one():
    fps, each, blend, ramp = 50.0, 0.2, 0.08, 0.1
    names = ["p_b_m", "a", "u", "s_z"]
    track = viseme_track(names, fps=fps, each=each, blend=blend, ramp=ramp)
    w = viseme_weights(track.viseme)
    assert track.n_frames == round((2 * ramp + len(names) * each) * fps) + 1
    assert np.all(track.mask[:, 0]) and not track.mask[:, 1:].any()
    assert not w[0].any() and not w[-1].any()             # starts and ends at rest
    assert np.all(w.sum(axis=1) <= 1.0 + 1e-12)
    for i, name in enumerate(names):
        start = ramp + i * each
        hold = (np.arange(track.n_frames) / fps > start + blend + 1e-9) & \
               (np.arange(track.n_frames) / fps < start + each - 1e-9)
        assert hold.any()
        assert np.all(w[hold, VISEME_CODES[name] - 1] == 1.0), name
        if i:   # inside a cross-fade the two visemes share the mouth
            fading = (np.arange(track.n_frames) / fps > start + 1e-9) & \
                     (np.arange(track.n_frames) / fps < start + blend - 1e-9)
            pair = w[fading][:, [VISEME_CODES[names[i - 1]] - 1, VISEME_CODES[name] - 1]]
            assert np.allclose(pair.sum(axis=1), 1.0) and np.all(np.diff(pair[:, 1]) > 0)


@pytest.mark.parametrize("names", [["f_v", "none", "o"], list(VISEMES) * 4])
def test_a_viseme_track_survives_the_fap_file(tmp_path, names):
    track = viseme_track(names, fps=25)
    write_fap(tmp_path / "v.fap", track)
    back = read_fap(tmp_path / "v.fap")
    assert np.array_equal(back.viseme, track.viseme)
    assert np.array_equal(back.mask, track.mask)
    assert back.name == track.name and len(track.name) <= 64     # a long sequence's name is cut


@pytest.mark.parametrize("kwargs, needle", [
    ({"names": ["a", "schwa"]}, "unknown viseme 'schwa'; valid: none, p_b_m"),
    ({"names": []}, "at least one viseme"),
    ({"names": ["a"], "fps": 0}, "fps must be > 0"),
    ({"names": ["a"], "each": 0.1, "blend": 0.2}, "blend must be in [0, each = 0.1]"),
    ({"names": ["a"], "ramp": float("nan")}, "ramp must be >= 0"),
])
def test_bad_arguments_say_what_is_wrong(kwargs, needle):
    with pytest.raises(FapError) as err:
        viseme_track(**kwargs)
    assert needle in str(err.value)
