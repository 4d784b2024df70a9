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


def test_eyeballs_are_drawn_behind_a_hole_sclera_light_pupil_dark():
    # a square wall at z = 0 with a square hole, an eyeball of radius 1 behind it looking at the
    # camera (+Z): through the hole the pupil is black at the centre and the iris/sclera around it;
    # without the eyeball the hole shows the background; where the wall is in front it hides the eye
    g = np.linspace(-4.0, 4.0, 17)
    xx, yy = np.meshgrid(g, g)
    v = np.stack([xx.ravel(), yy.ravel(), np.zeros(xx.size)], axis=1)
    f = []
    for i in range(16):
        for j in range(16):
            if 6 <= i < 10 and 6 <= j < 10:
                continue                               # the hole, |x|, |y| < 1
            a = i * 17 + j
            f += [[a, a + 1, a + 18], [a, a + 18, a + 17]]
    f = np.array(f)
    eyes = bs.eyeballs(np.array([[0.0, 0.0, -0.5]]), np.array([1.0]), np.array([[0.0, 0.0, 1.0]]))
    assert eyes[0].shape[1] == 3 and eyes[2].max() == pytest.approx(1.0)
    view = bs.face_view(v, 0.0, size=160, share=0.9)
    centre = tuple(int(round(c)) for c in view.project(np.zeros((1, 3)))[0, [1, 0]])
    wall = tuple(int(round(c)) for c in view.project(np.array([[2.5, 2.5, 0.0]]))[0, [1, 0]])
    rim = tuple(int(round(c)) for c in view.project(np.array([[0.0, 0.85, 0.0]]))[0, [1, 0]])
    plain, drawn = bs.grey_render(v, f, view), bs.grey_render(v, f, view, eyes)
    assert plain[centre][0] == 0 and drawn[centre][0] == bs.PUPIL_GREY
    assert drawn[rim][0] == bs.SCLERA_GREY
    assert drawn[wall][0] == plain[wall][0] > 0
