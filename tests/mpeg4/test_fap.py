"""The .fap reader and writer: real files, the fill rules, repairs, errors, round trips."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from faceforge.exceptions import FapError
from faceforge.mpeg4 import LIP_PAIRS, FapTrack, FapWarning, format_fap, parse_fap, read_fap, write_fap
from faceforge.mpeg4.fap_range import LIMITS
from faceforge.mpeg4.fap import FPS_RANGE, complete_values

SAMPLES = sorted((Path(__file__).resolve().parents[2] / "samples" / "fap").glob("*.fap"))


def mask_line(faps) -> str:
    bits = ["0"] * 68
    for f in faps:
        bits[f - 1] = "1"
    return " ".join(bits)


def fap_text(frames, header="2.1 test 25 {n}", newline="\n") -> str:
    """frames: list of (dict fap -> value or list of values, frame number)."""
    lines = [header.format(n=len(frames))]
    for number, (values) in enumerate(frames):
        lines.append(mask_line(values))
        items = [str(number)]
        for fap in sorted(values):
            v = values[fap]
            items.extend(str(x) for x in (v if isinstance(v, list) else [v]))
        lines.append(" ".join(items))
    return newline.join(lines) + newline


# ----------------------------------------------------------------- real files


def test_eight_sample_files_are_present():
    assert [p.stem for p in SAMPLES] == ["anger", "beg", "disgust", "fear", "happy-for", "hate", "joy", "pride"]


@pytest.mark.parametrize("path", SAMPLES, ids=lambda p: p.stem)
def test_real_file_parses_and_round_trips(path, tmp_path):
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the real files need no repair
        track = read_fap(path, strict=True)
    lines = path.read_text().splitlines()
    header = lines[0].split()
    assert track.version == "2.1" and track.fps == 25.0 and track.n_frames == int(header[-1])
    assert np.array_equal(track.frame_numbers, np.arange(track.n_frames))
    # the file's own values sit where its mask says (first frame checked token by token)
    bits = np.array(lines[1].split()) == "1"
    values = [float(x) for x in lines[2].split()[1:]]
    assert np.array_equal(track.mask[0], bits)
    assert np.array_equal(track.values[0, bits], values)
    assert np.all(np.isnan(track.values[:, :2])) and np.all(np.isfinite(track.values[:, 2:]))
    out = write_fap(tmp_path / path.name, track, newline="\r\n")
    assert read_fap(out, strict=True) == track
    assert format_fap(read_fap(out)) == format_fap(track)  # writer is deterministic


@pytest.mark.parametrize("path", SAMPLES, ids=lambda p: p.stem)
def test_real_files_give_both_lip_contours_and_keep_them_apart(path):
    """The Xface files give inner and outer lips in every frame, with different values for
    the mid-lip FAPs: nothing may be copied across a pair then."""
    track = read_fap(path)
    assert track.mask[:, LIP_PAIRS - 1].all()
    differing = [int(i) for i, o in LIP_PAIRS if not np.array_equal(track.fap(int(i)), track.fap(int(o)))]
    assert {4, 5, 8, 9, 10, 11} <= set(differing)


# ----------------------------------------------------------------- fill rules


def slow_complete(mask, given):
    """Plain-Python twin of complete_values: frame by frame, FAP by FAP."""
    n = len(mask)
    pairs = {int(i): int(o) for i, o in LIP_PAIRS} | {int(o): int(i) for i, o in LIP_PAIRS}
    out = np.full((n, 68), np.nan)
    previous = [0.0] * 68
    for t in range(n):
        for col in range(2, 68):
            fap = col + 1
            partner = pairs.get(fap)
            if mask[t, col]:
                value = given[t, col]
            elif partner is not None and mask[t, partner - 1]:
                value = given[t, partner - 1]
            else:
                value = previous[col]
            out[t, col] = previous[col] = value
    return out


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 6), st.integers(0, 2**32 - 1))
def test_fill_rules_match_the_slow_twin(n, seed):
    rng = np.random.default_rng(seed)
    mask = rng.random((n, 68)) < 0.4
    given_values = rng.integers(-500, 500, size=(n, 68)).astype(float)
    np.testing.assert_array_equal(complete_values(mask, given_values), slow_complete(mask, given_values))


def test_absent_faps_hold_and_lip_sets_copy():
    text = fap_text([{3: 100, 51: -20, 4: 7}, {5: 30}, {52: 40, 60: 9}, {}])
    track = parse_fap(text)
    assert track.fap(3).tolist() == [100, 100, 100, 100]  # held
    assert track.fap(51).tolist() == [-20, -20, -20, -20]
    assert track.fap(4).tolist() == [7, 7, 7, 7]  # given itself in frame 0, then held
    assert track.fap(5).tolist() == [0, 30, 40, 40]  # inner 5 copied from outer 52 in frame 2
    assert track.fap(52).tolist() == [0, 30, 40, 40]  # outer 52 copied from inner 5 in frame 1
    assert track.fap(13).tolist() == [0, 0, 9, 9]  # inner 13 from outer 60
    assert track.fap(40).tolist() == [0, 0, 0, 0]  # never given: neutral
    assert track.mask[1].sum() == 1 and track.mask[3].sum() == 0


def test_viseme_and_expression_take_4_and_6_values_and_hold():
    text = fap_text([{1: [3, 5, 40, 0], 2: [1, 63, 0, 0, 1, 0], 3: 10}, {3: 11}, {2: [6, 20, 2, 10, 0, 0]}])
    track = parse_fap(text)
    np.testing.assert_array_equal(track.viseme, [[3, 5, 40, 0]] * 3)
    np.testing.assert_array_equal(track.expression, [[1, 63, 0, 0, 1, 0], [1, 63, 0, 0, 1, 0], [6, 20, 2, 10, 0, 0]])
    assert track.fap(3).tolist() == [10, 11, 11]
    assert parse_fap(format_fap(track)) == track


def test_separators_line_ends_comments_and_float_values():
    plain = fap_text([{3: 1.5, 48: -2}, {19: 1e3}])
    assert parse_fap(plain) == parse_fap(plain.replace("\n", "\r\n"))
    assert parse_fap(plain) == parse_fap(plain.replace("\n", "\r"))
    assert parse_fap(plain) == parse_fap(plain.replace(" ", "\t"))
    commented = "# a comment\n\n" + plain.replace("\n", "\n# between frames\n", 2)
    assert parse_fap(commented) == parse_fap(plain)
    spaced_name = parse_fap(fap_text([{3: 1}], header="2.0 my long name 29.97 {n}"))
    assert spaced_name.name == "my long name" and spaced_name.version == "2.0" and spaced_name.fps == 29.97


# ----------------------------------------------------------------- repairs and errors


def test_infinite_values_are_held_with_a_warning_listing_lines():
    text = fap_text([{3: 10, 4: 5}, {3: "inf", 4: 6}, {3: "-inf", 51: 8, 4: "nan"}])
    with pytest.warns(FapWarning, match=r"lines 5, 7"):
        track = parse_fap(text, "x.fap")
    assert track.fap(3).tolist() == [10, 10, 10]  # held from the last finite value
    assert track.fap(4).tolist() == [5, 6, 8]  # absent in frame 2: copied from outer 51
    assert not track.mask[1, 2] and track.mask[1, 3]
    assert parse_fap(format_fap(track)) == track
    with pytest.raises(FapError, match=r"^x\.fap:5: non-finite"):
        parse_fap(text, "x.fap", strict=True)


def test_frame_count_disagreeing_with_header():
    text = fap_text([{3: 1}, {3: 2}], header="2.1 t 25 5")
    with pytest.warns(FapWarning, match="header says 5 frames but the file has 2"):
        assert parse_fap(text, "c.fap").n_frames == 2
    with pytest.raises(FapError, match=r"^c\.fap:1: header says 5"):
        parse_fap(text, "c.fap", strict=True)


GOOD = fap_text([{3: 1, 4: 2}, {3: 5}])


@pytest.mark.parametrize(
    "text, line, match",
    [
        ("", None, "empty"),
        ("# only a comment\n", None, "empty"),
        ("3.0 t 25 1\n" + GOOD.split("\n", 1)[1], 1, "unsupported FAP file version"),
        ("2.1 t 0 2\n" + GOOD.split("\n", 1)[1], 1, "fps must be a number in"),
        ("2.1 t 25 two\n" + GOOD.split("\n", 1)[1], 1, "not a number"),
        ("2.1 25\n", 1, "header must be"),
        ("2.1 t 25 0\n", 1, "no frames"),
        (GOOD.replace(mask_line([3, 4]), mask_line([3, 4]) + " 0"), 2, "69"),
        (GOOD.replace(mask_line([3, 4]), mask_line([3, 4])[:-2]), 2, "67"),
        (GOOD.replace(mask_line([3]), mask_line([3]).replace("0", "2", 1)), 4, "0 or 1"),
        (GOOD.replace("0 1 2", "0 1 two"), 3, "'two' is not a number"),
        (GOOD.replace("0 1 2", "0 1 2 3"), 3, "2 values .* got 3"),
        (GOOD.replace("0 1 2", "0 1"), 3, "got 1"),
        (GOOD.replace("1 5", "0 5"), 5, "does not increase"),
        (GOOD.replace("1 5", "1.5 5"), 5, "not an integer"),
        (GOOD.rsplit("\n", 2)[0] + "\n", 4, "truncated"),
        (GOOD[:-3], 5, "got 0"),
    ],
)
def test_bad_files_name_file_and_line(text, line, match):
    with pytest.raises(FapError, match=match) as err:
        parse_fap(text, "bad.fap")
    prefix = "bad.fap:" + (f"{line}: " if line else " ")
    assert str(err.value).startswith(prefix.rstrip(" ") if not line else prefix)


def test_missing_file_is_a_fap_error(tmp_path):
    with pytest.raises(FapError, match="cannot read"):
        read_fap(tmp_path / "nope.fap")


def test_non_utf8_name_is_read(tmp_path):
    path = tmp_path / "latin.fap"
    path.write_bytes(fap_text([{3: 1}], header="2.1 caf\xe9 25 {n}").encode("latin-1"))
    assert read_fap(path).name == "caf\xe9"


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.data())
def test_mangled_real_file_never_crashes(data):
    """Cut, delete or replace anything in a real file: a track or a FapError, nothing else."""
    text = "\n".join(SAMPLES[0].read_text().splitlines()[:9]).replace("108", "4", 1) + "\n"
    start = data.draw(st.integers(0, len(text)))
    stop = data.draw(st.integers(start, min(len(text), start + 40)))
    insert = data.draw(st.sampled_from(["", "x", " ", "\n", "inf", "-1e999", "nan", "1", "\t#", "2.1", "0 0"]))
    mangled = text[:start] + insert + text[stop:]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FapWarning)
        try:
            track = parse_fap(mangled, "m.fap")
        except FapError as exc:
            assert str(exc).startswith("m.fap")
            return
    assert np.all(np.isfinite(track.values[:, 2:]))


# ----------------------------------------------------------------- writer round trip

names = st.lists(st.text("abcXYZ019_-.\\:", min_size=1, max_size=6), max_size=3).map(" ".join)
finite = st.floats(allow_nan=False, allow_infinity=False, width=64)


@st.composite
def tracks(draw):
    """Random tracks: numpy draws the bulk (cheap), hypothesis the structure and edge floats."""
    n = draw(st.integers(1, 6))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    mask = rng.random((n, 68)) < draw(st.sampled_from([0.0, 0.3, 0.9, 1.0]))
    values = np.where(
        rng.random((n, 68)) < 0.5,
        rng.integers(-2000, 2000, (n, 68)).astype(float),
        rng.standard_normal((n, 68)) * 10.0 ** rng.integers(-300, 300, (n, 68)),
    )
    edge = draw(st.lists(finite, max_size=8))
    values.flat[rng.integers(0, values.size, len(edge))] = edge
    values = np.clip(values, -LIMITS, LIMITS)        # past the range the reader clamps (test_fap_range)
    viseme = rng.integers(0, 15, (n, 4)).astype(float)
    expression = np.concatenate([rng.integers(0, 7, (n, 1)), rng.random((n, 5)) * 63], axis=1)
    numbers = np.array(sorted(draw(st.sets(st.integers(-5, 10**6), min_size=n, max_size=n))), dtype=np.int64)
    fps = draw(st.one_of(st.sampled_from([25.0, 30.0, 29.97]), st.floats(*FPS_RANGE)))
    return FapTrack.from_given(
        fps, mask, values, viseme, expression, frame_numbers=numbers,
        name=draw(names), version=draw(st.sampled_from(["2.0", "2.1"])),
    )


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(tracks(), st.sampled_from(["\n", "\r\n"]))
def test_write_parse_is_the_identity(track, newline):
    again = parse_fap(format_fap(track, newline=newline), strict=True)
    assert again == track
    assert format_fap(again) == format_fap(track)


def test_from_given_is_a_fixed_point_of_the_fill_rules():
    track = read_fap(SAMPLES[3])
    rebuilt = FapTrack.from_given(
        track.fps, track.mask, track.values, track.viseme, track.expression,
        frame_numbers=track.frame_numbers, name=track.name, version=track.version,
    )
    assert rebuilt == track


def test_writer_rejects_unwritable_names():
    track = parse_fap(fap_text([{3: 1}]))
    track.name = "two  spaces"
    with pytest.raises(ValueError, match="single-spaced"):
        format_fap(track)


def test_write_is_atomic(tmp_path):
    path = tmp_path / "t.fap"
    path.write_text("old")
    track = parse_fap(fap_text([{3: 1}]))
    write_fap(path, track)
    assert read_fap(path) == track and [p.name for p in tmp_path.iterdir()] == ["t.fap"]
