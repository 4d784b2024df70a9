"""ARKit weight tracks: Live Link Face CSV / JSON in, bad input named by file:line, NNLS out."""

from __future__ import annotations

import json

import numpy as np
import pytest

from faceforge.blendshapes.arkit import ARKIT_NAMES, load_arkit_mapping, default_mapping_path, mirror_name
from faceforge.blendshapes.curves import (LIVE_LINK_EXTRA, mix_shapes, near_duplicates, read_weights, reproduction_error,
                                         solve_weights, write_weights)
from faceforge.exceptions import FapError, TemplateError

LIVE_LINK_HEADER = ("Timecode,BlendShapeCount," + ",".join(n[0].upper() + n[1:] for n in ARKIT_NAMES)
                    + "," + ",".join(LIVE_LINK_EXTRA))


def _live_link_row(frame: int, weights: dict) -> str:
    vals = [f"{weights.get(n, 0.0):.6f}" for n in ARKIT_NAMES] + ["0.1", "-0.2", "0", "0", "0", "0", "0", "0", "0"]
    return f"12:00:01:{frame:02d}.{frame * 7 % 1000:03d},61," + ",".join(vals)


def test_live_link_csv_is_read_with_its_rate(tmp_path):
    p = tmp_path / "take.csv"
    rows = [_live_link_row(2 * k, {"jawOpen": k / 40, "eyeBlinkLeft": 1.0}) for k in range(40)]
    # a 60 Hz timecode stepping by 2 frames over 1.3 s: 30 fps
    rows = [f"12:00:{1 + 2 * k // 60:02d}:{2 * k % 60:02d}.000" + r[r.index(","):] for k, r in enumerate(rows)]
    p.write_text(LIVE_LINK_HEADER + "\n" + "\n".join(rows) + "\n")
    names, w, fps = read_weights(p)
    assert names == list(ARKIT_NAMES)
    assert fps == pytest.approx(30.0)
    assert np.allclose(w[:, names.index("jawOpen")], np.arange(40) / 40)
    assert np.all(w[:, names.index("eyeBlinkLeft")] == 1.0)


@pytest.mark.parametrize("suffix", [".csv", ".json"])
def test_write_then_read_is_the_identity(tmp_path, suffix):
    rng = np.random.default_rng(0)
    names = ["jawOpen", "mouthSmileLeft", "browInnerUp"]
    w = rng.uniform(0, 1, size=(40, 3))
    p = write_weights(tmp_path / f"c{suffix}", names, w, fps=25.0)
    got_names, got, fps = read_weights(p)
    assert fps == pytest.approx(25.0)
    full = np.zeros((40, len(got_names)))
    for j, n in enumerate(names):
        full[:, got_names.index(n)] = w[:, j]
    assert np.abs(got - full).max() <= 5e-7      # six decimals


def test_plain_csv_and_json_frames(tmp_path):
    p = tmp_path / "plain.csv"
    p.write_text("frame,JawOpen,mouthPucker\n0,0.5,0\n1,1,0.25\n")
    names, w, _ = read_weights(p)
    assert names == ["jawOpen", "mouthPucker"] and np.allclose(w, [[0.5, 0], [1, 0.25]])
    j = tmp_path / "t.json"
    j.write_text(json.dumps({"fps": 30, "frames": [{"jawOpen": 0.2}, {"eyeBlinkRight": 1.0}]}))
    names, w, fps = read_weights(j)
    assert fps == 30 and names == ["jawOpen", "eyeBlinkRight"] and np.allclose(w, [[0.2, 0], [0, 1]])


@pytest.mark.parametrize("body, line, words", [
    ("frame,JawOpen,mouthGrin\n0,0.5,0\n", 1, "unknown blendshape name 'mouthGrin'"),
    ("frame,JawOpen\n0,0.5\n1,1.5\n", 3, "jawOpen = 1.5 is outside [0, 1]"),
    ("frame,JawOpen\n0,0.5\n1\n", 3, "1 fields, the header has 2"),
    ("frame,JawOpen\n0,abc\n", 2, "not a number"),
    ("frame,JawOpen\n0,-0.2\n", 2, "outside [0, 1]"),
    ("frame,JawOpen\n0,0.5\n1,NaN\n", 3, "jawOpen = nan is outside [0, 1]"),
    ("frame,JawOpen\n0,0.5\n1,\n", 3, "not a number"),
    ("frame,JawOpen\n0,0.5,0.1\n", 2, "3 fields, the header has 2"),
    ("", 1, "empty file"),
    ("frame,JawOpen\n", 2, "no frames"),
    # a header of no shape at all: was read as a take of no weights and played (the stages ran)
    ("Timecode,BlendShapeCount\n00:00:00:00.000,0\n", 1, "no blendshape column"),
    ('{"frames": [{}, {}]}', 0, "no blendshape column"),
    # a quote left open on the last row: was read as if closed
    ('frame,JawOpen\n0,0.5\n1,"0.3\n', 3, "not a CSV file"),
    # not UTF-8 (a UTF-16 export): was named without a line
    (b"frame,JawOpen\n0,0.5\n1,0.\xff\n", 3, "not UTF-8 text"),
])
def test_bad_csv_names_the_line(tmp_path, body, line, words):
    text = isinstance(body, str)
    p = tmp_path / ("bad.json" if text and body.startswith("{") else "bad.csv")
    p.write_bytes(body.encode() if text else body)
    with pytest.raises(FapError) as exc:
        read_weights(p)
    where = f"{p.name}:{line}" if line else p.name
    assert where in str(exc.value) and words in str(exc.value)


def test_solve_weights_recovers_mixes_within_bounds():
    rng = np.random.default_rng(3)
    neutral = rng.normal(size=(50, 3))
    shapes = neutral + rng.normal(size=(4, 50, 3))
    shapes[3] = neutral                                   # a shape not made: zero delta, weight 0
    truth = np.array([[0.0, 0.5, 1.0, 0.0], [0.2, 0.0, 0.7, 0.0]])
    frames = mix_shapes(neutral, shapes, truth)
    assert np.allclose(solve_weights(frames, neutral, shapes), truth, atol=1e-9)
    over = neutral + 3.0 * (shapes[0] - neutral)          # beyond full weight: clipped to 1
    w = solve_weights(over[None], neutral, shapes)
    assert w[0, 0] == pytest.approx(1.0) and np.all((w >= 0) & (w <= 1))
    assert reproduction_error(frames, neutral, shapes, truth) == pytest.approx((0.0, 0.0), abs=1e-12)
    rel, peak = reproduction_error(over[None], neutral, shapes, np.eye(4)[:1])   # 3x a shape, mixed at 1: 2/3 missing
    assert rel == pytest.approx(2 / 3) and peak == pytest.approx(2 * np.linalg.norm(shapes[0] - neutral, axis=1).max())


def test_the_template_covers_all_52_and_mirrors():
    specs = load_arkit_mapping(default_mapping_path())
    assert list(specs) == list(ARKIT_NAMES) and len(specs) == 52
    right = specs["mouthSmileRight"]
    assert right.mirror_of == "mouthSmileLeft" and set(right.controls) == {"zygomaticus_major_R", "risorius_R"}
    assert specs["jawRight"].faps == {15: -specs["jawLeft"].faps[15]}
    assert specs["eyeBlinkRight"].lids == {20: 900.0, 22: 124.0}
    assert {n for n, s in specs.items() if not s.made} == {"cheekPuff", "tongueOut"}
    assert specs["eyeLookInLeft"].eye["side"] == "L" and specs["eyeLookInLeft"].eye["yaw"] < 0   # towards -X
    assert specs["eyeLookInRight"].eye == {"side": "R", "yaw": -specs["eyeLookInLeft"].eye["yaw"], "pitch": 0.0}
    assert mirror_name("eyeBlinkLeft") == "eyeBlinkRight" and mirror_name("jawOpen") == "jawOpen"


def test_eye_wide_raises_the_lids_as_far_as_surprise():
    # ARKit's eyeWide is AU5 at full weight; the surprise preset (AU 1+2+5B+26) raises the upper
    # lids as far as the lid model allows a preset (read17): the shape must not widen the eye less
    # than the expression does (it asked -250 IRISD, 1.24x the opening, against surprise's -350)
    from faceforge.animation.fap_mapping import load_fap_mapping

    surprise = load_fap_mapping(default_mapping_path().parent / "fap_mapping.yaml").expressions["surprise"]
    specs = load_arkit_mapping(default_mapping_path())
    assert specs["eyeWideLeft"].lids == {19: surprise[19 - 1]}
    assert specs["eyeWideRight"].lids == {20: surprise[20 - 1]}


def test_a_bad_template_is_named(tmp_path):
    p = tmp_path / "m.yaml"
    p.write_text("shapes:\n  jawOpen: {faps: {3: 100}}\n")
    with pytest.raises(TemplateError, match="m.yaml"):
        load_arkit_mapping(p, names=("jawOpen",))
    p.write_text("shapes:\n  jawOpn: {lids: {19: 10}}\n")
    with pytest.raises(TemplateError, match="unknown name 'jawOpn'"):
        load_arkit_mapping(p, names=("jawOpen",))


def test_a_30_hz_timecode_is_told_from_a_60_hz_one(tmp_path):
    from faceforge.blendshapes.curves import timecode_rate

    assert timecode_rate([0.0, 12.5, 29.9]) == 30.0 and timecode_rate([0.0, 59.2]) == 60.0
    p = tmp_path / "t30.csv"
    rows = [f"00:00:{k // 30:02d}:{k % 30:02d}.000,61," + ",".join(["0"] * 61) for k in range(0, 90, 1)]
    p.write_text(LIVE_LINK_HEADER + "\n" + "\n".join(rows) + "\n")
    assert read_weights(p)[2] == pytest.approx(30.0)


def test_a_ridge_keeps_two_nearly_collinear_shapes_from_trading_weight():
    """Two shapes 0.999 alike (MakeHuman's mouthPressLeft / Right are): a frame half of each, moved
    by 1 % of a shape along their difference, swings the plain solve's weights by most of [0, 1];
    with ``ridge`` (curves.ridge) they move a little and the mix still fits the frame."""
    rng = np.random.default_rng(3)
    neutral = rng.normal(size=(200, 3))
    a = rng.normal(size=(200, 3))
    b = a + 0.045 * rng.normal(size=(200, 3))                # cosine with a ~0.999
    shapes = neutral + np.stack([a, b])
    base = neutral + 0.5 * a + 0.5 * b
    nudge = 0.01 * np.linalg.norm(a) * (b - a) / np.linalg.norm(b - a)
    frames = np.stack([base, base + nudge])
    plain = solve_weights(frames, neutral, shapes)
    ridged = solve_weights(frames, neutral, shapes, ridge=1e-2)
    assert np.abs(plain[1] - plain[0]).max() > 0.15
    assert np.abs(ridged[1] - ridged[0]).max() < 0.25 * np.abs(plain[1] - plain[0]).max()
    err, _ = reproduction_error(frames, neutral, shapes, ridged)
    assert err < 0.02
    assert np.allclose(solve_weights(frames, neutral, shapes, ridge=0.0), plain)


def _collinear_pair(seed=3):
    rng = np.random.default_rng(seed)
    neutral = rng.normal(size=(200, 3))
    a = rng.normal(size=(200, 3))
    b = a + 0.045 * rng.normal(size=(200, 3))                # cosine with a ~0.999
    return neutral, a, b


def test_smoothness_keeps_a_collinear_pair_from_flipping_between_frames():
    """A take of 12 frames half of each of two 0.999-alike shapes, every other frame nudged 1 % of a
    shape along their difference: the plain solve flips weight from frame to frame; with
    ``smooth`` (curves.smooth) consecutive frames stay close and the mix still fits."""
    neutral, a, b = _collinear_pair()
    shapes = neutral + np.stack([a, b])
    base = neutral + 0.5 * a + 0.5 * b
    nudge = 0.01 * np.linalg.norm(a) * (b - a) / np.linalg.norm(b - a)
    frames = np.stack([base + (i % 2) * nudge for i in range(12)])
    plain = solve_weights(frames, neutral, shapes)
    smooth = solve_weights(frames, neutral, shapes, smooth=1.0)
    assert np.abs(np.diff(plain, axis=0)).max() > 0.15
    assert np.abs(np.diff(smooth, axis=0)).max() < 0.25 * np.abs(np.diff(plain, axis=0)).max()
    assert reproduction_error(frames, neutral, shapes, smooth)[0] < 0.02
    assert np.allclose(solve_weights(frames, neutral, shapes, smooth=0.0), plain)


def test_smoothness_sweeps_reach_the_joint_bounded_optimum():
    """Twin: the block Gauss-Seidel sweeps of ``solve_weights(..., smooth=s)`` against one bounded
    least squares over all frames at once (scipy on the stacked system)."""
    from scipy.optimize import lsq_linear

    rng = np.random.default_rng(5)
    neutral = rng.normal(size=(30, 3))
    shapes = neutral + rng.normal(size=(3, 30, 3))
    w_true = np.clip(rng.uniform(-0.3, 1.3, size=(6, 3)), 0, 1)
    frames = mix_shapes(neutral, shapes, w_true) + 0.3 * rng.normal(size=(6, 30, 3))
    s = 0.5
    got = solve_weights(frames, neutral, shapes, smooth=s, sweeps=400)
    D = (shapes - neutral).reshape(3, -1).T
    scale = np.linalg.norm(D, axis=0).mean()
    F, k = w_true.shape
    M = np.kron(np.eye(F), D)
    diff = np.kron(np.diff(np.eye(F), axis=0), np.eye(k))
    A = np.vstack([M, np.sqrt(s) * scale * diff])
    y = np.concatenate([(frames - neutral).reshape(F, -1).ravel(), np.zeros(len(diff))])
    want = lsq_linear(A, y, bounds=(0, 1), method="bvls").x.reshape(F, k)
    assert np.abs(got - want).max() < 1e-4
    assert np.abs(np.diff(got, axis=0)).sum() < np.abs(np.diff(solve_weights(frames, neutral, shapes), axis=0)).sum()


def test_near_duplicates_names_the_alike_and_opposite_pairs_only():
    neutral, a, b = _collinear_pair()
    c = np.random.default_rng(9).normal(size=(200, 3))
    shapes = neutral + np.stack([a, b, -a, c, 0 * a])
    pairs = near_duplicates(neutral, shapes, ["a", "b", "minus_a", "c", "flat"])
    assert {(x, y) for x, y, _ in pairs} == {("a", "minus_a"), ("a", "b"), ("b", "minus_a")}
    assert pairs[0][:2] == ("a", "minus_a")                  # the most alike first
    cos = {(x, y): c for x, y, c in pairs}
    assert cos[("a", "minus_a")] == pytest.approx(-1.0)
    assert 0.99 < cos[("a", "b")] < 1.0
    assert near_duplicates(neutral, shapes[[0, 3]], ["a", "c"]) == []
