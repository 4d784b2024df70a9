"""The face-reading check (landmarks/blendshapes.py): the classification rule, the camera, and the
blendshape model on the MakeHuman sample with two of MakeHuman's own expression units."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from faceforge.landmarks import blendshapes as bs

ROOT = Path(__file__).resolve().parents[2]
NAMES = sorted({n for names in bs.AU_BLENDSHAPES.values() for n in names})


def shapes(**values):
    out = {n: 0.1 for n in NAMES}
    out.update(values)
    return out


def test_the_expression_whose_action_units_rise_most_over_neutral_is_the_one_read():
    neutral = shapes(browDownLeft=0.8, browDownRight=0.8)
    smile = shapes(browDownLeft=0.8, browDownRight=0.8, mouthSmileLeft=0.7, mouthSmileRight=0.5,
                   cheekSquintLeft=0.3, cheekSquintRight=0.3)
    scores = bs.expression_scores(smile, neutral)
    assert scores["joy"] == pytest.approx(((0.3 - 0.1) + (0.6 - 0.1)) / 2)
    assert bs.recognised(scores) == "joy"
    # a score already high at neutral counts only by what it adds: brows as low as at neutral
    # with the jaw dropped and the brows raised read as surprise, not anger
    wide = shapes(browDownLeft=0.8, browDownRight=0.8, jawOpen=0.6, browInnerUp=0.5,
                  browOuterUpLeft=0.5, browOuterUpRight=0.5, eyeWideLeft=0.3, eyeWideRight=0.3)
    assert bs.recognised(bs.expression_scores(wide, neutral)) == "surprise"
    assert bs.expression_scores(neutral, neutral) == {e: 0.0 for e in bs.EXPRESSIONS_ORDER}


def test_face_view_frames_the_box_and_turns_the_left_cheek_to_the_camera():
    box = np.array([[-1.0, -2.0, 0.0], [1.0, 2.0, 1.0]])
    front = bs.face_view(box, 0.0, size=400, share=0.5)
    p = front.project(box)
    assert abs(p[1, 1] - p[0, 1]) == pytest.approx(200.0)
    assert np.allclose(front.direction, [0, 0, -1])
    turned = bs.face_view(box, 20.0)
    left_cheek = np.array([[1.0, 0.0, 0.0]])
    assert turned.project(left_cheek)[0, 2] < front.project(left_cheek)[0, 2]   # nearer the camera


@pytest.fixture(scope="module")
def makehuman():
    from faceforge.io.mesh import load_mesh

    v, f, _ = load_mesh(ROOT / "samples" / "makehuman" / "mh_head_default.obj")
    units = np.load(ROOT / "tests" / "data" / "mh_head_expression_units_caucasian.npz")
    names = [str(n) for n in units["names"]]
    return v, np.asarray(f), {n: units["deltas"][names.index(n)] for n in ("mouth-corner-puller", "mouth-open")}


def test_the_model_reads_makehumans_corner_puller_as_a_smile_and_mouth_open_as_a_jaw_drop(makehuman):
    v, f, units = makehuman
    head = v[:, 1] > np.percentile(v[:, 1], 25)
    view = bs.face_view(v[head], 0.0)
    with bs.BlendshapeScorer() as scorer:
        rest = scorer.score(bs.grey_render(v, f, view))
        smile = scorer.score(bs.grey_render(v + units["mouth-corner-puller"], f, view))
        opened = scorer.score(bs.grey_render(v + units["mouth-open"], f, view))
        assert scorer.score(np.zeros((256, 256, 3), np.uint8)) is None
    assert rest is not None and len(rest) == 52
    au = {k: bs.au_scores(s) for k, s in (("rest", rest), ("smile", smile), ("open", opened))}
    assert au["smile"][12] - au["rest"][12] > 0.3
    assert au["open"][26] - au["rest"][26] > 0.15
    assert au["smile"][26] - au["rest"][26] < 0.1 and au["open"][12] - au["rest"][12] < 0.1
    assert bs.recognised(bs.expression_scores(smile, rest)) == "joy"
