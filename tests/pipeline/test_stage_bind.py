"""The bind stage on a synthetic fitted head (a fit.npz written by hand)."""

import json

import numpy as np
import pytest

from faceforge.skin.binding import CRANIUM, MUSCLE, UNBOUND, Binding
from faceforge.skin.regions import bind_report, face_front_mask
from faceforge.exceptions import StageError
from tests.skin.synthetic import sphere


def _fake_fit(path):
    v, f = sphere(1.0, 3)
    cv, cf = sphere(0.85, 3)
    mv, mf = sphere(0.92, 3)
    keep = (mv[mf][:, :, 2] > 0.5).all(axis=1)
    used, local = np.unique(mf[keep], return_inverse=True)
    mv, mf = mv[used], local.reshape(-1, 3)
    lm = {"2.1": [0, -0.8, 0.6], "10.9": [0.95, 0.1, 0.0], "10.10": [-0.95, 0.1, 0.0],
          "11.1": [0, 0.8, 0.6], "11.2": [-0.5, 0.75, 0.4], "11.3": [0.5, 0.75, 0.4],
          "11.6": [0, 0.0, -1.0]}
    from faceforge.io.stagefiles import save_npz

    save_npz(path / "fit.npz", skin_vertices=v, skin_faces=f, cranium_vertices=cv, cranium_faces=cf,
             mandible_vertices=np.zeros((0, 3)), mandible_faces=np.zeros((0, 3), np.int64),
             skin_landmark_ids=np.array(list(lm)), skin_landmark_positions=np.array(list(lm.values()), float),
             muscle_names=np.array(["frontalis"]), muscle_vertex_start=np.array([0, len(mv)]),
             muscle_vertices=mv, muscle_face_start=np.array([0, len(mf)]), muscle_faces=mf)
    return v, f, lm


@pytest.fixture()
def ctx(tmp_path):
    from faceforge.io.config import load_config
    from faceforge.pipeline import StageContext

    (tmp_path / "fit").mkdir()
    out = tmp_path / "bind.tmp"
    out.mkdir()
    return StageContext(name="bind", config=load_config(), params={}, out_dir=out, workdir=tmp_path,
                        deps=("fit",))


def test_stage_writes_bind_npz_report_and_png(ctx):
    from faceforge.io.stagefiles import load_npz
    from faceforge.pipeline.stages.bind import run

    v, f, _ = _fake_fit(ctx.workdir / "fit")
    run(ctx)
    for name in ("bind.npz", "report.json", "influence.png"):
        assert (ctx.out_dir / name).stat().st_size > 0
    d = load_npz(ctx.out_dir / "bind.npz")
    b = Binding.from_arrays(d)
    assert int(d["n_user"]) == len(v)
    np.testing.assert_array_equal(d["vertices"][: len(v)], v)
    assert b.body_names == ("frontalis", "cranium")
    assert np.all(b.status != UNBOUND)  # every ray meets the skull at 0.15 < 0.15 * diagonal
    assert np.all(b.status[v[:, 2] > 0.75] == MUSCLE)  # under the (jagged-edged) cap
    report = json.loads((ctx.out_dir / "report.json").read_text())
    front = report["regions"]["face_front"]
    assert front["fraction"]["bound"] == 1.0 and front["vertices"] > 0
    assert report["mouth"]["case"] == "no_landmarks"
    w = d["influence"]
    assert np.all(w[b.status == MUSCLE] == 1.0) and w.min() == 0.0


def test_stage_without_fit_names_the_missing_file(ctx):
    from faceforge.pipeline.stages.bind import run

    with pytest.raises(StageError, match="fit.npz"):
        run(ctx)


def test_face_front_mask_rules():
    v = np.array([[0, 0, 1.0], [0, 0, -1.0], [0, 2.0, 1.0], [0, -2.0, 1.0], [1.0, 0.79, 0.5]])
    lm = {"2.1": [0, -1.0, 0.8], "10.9": [0.9, 0, 0.0], "11.1": [0, 1.0, 0.8],
          "11.2": [-0.5, 0.8, 0.6], "11.3": [0.5, 0.8, 0.6]}
    mask, rule = face_front_mask(v, lm)
    # front; behind the ears; above the hairline; below the chin; temple under the hairline end
    np.testing.assert_array_equal(mask, [True, False, False, False, True])
    assert "10.x" in rule["ears"]["rule"] and "11.2" in rule["hairline"]["rule"]
    mask2, rule2 = face_front_mask(v, {"2.1": [0, -1.0, 0.8], "3.7": [0.3, 0.2, 0.9]})
    assert "no 10.x" in rule2["ears"]["rule"] and "no 11.x" in rule2["hairline"]["rule"]


def test_report_fractions_add_up():
    status = np.array([MUSCLE, CRANIUM, UNBOUND, MUSCLE], np.int8)
    b = Binding(("m", "cranium"), status, np.array([0, 1, 3]), np.array([0, 1, 0]),
                np.zeros(3, int), np.ones((3, 3)) / 3, np.zeros((3, 3)), np.ones(3),
                np.zeros(3, bool), np.zeros((4, 3)))
    r = bind_report(b, {"front": np.array([True, True, False, False])})
    assert r["regions"]["all"]["fraction"]["muscle"] == 0.5
    assert r["regions"]["front"]["fraction"]["bound"] == 1.0
    assert r["missed_rays"] == 1
    assert r["anchors_per_body"] == {"m": 2, "cranium": 1}
    assert abs(sum(r["regions"]["all"]["fraction"][k] for k in ("muscle", "cranium", "mandible", "none")) - 1) < 1e-12


def test_cli_bind_without_fit_is_a_one_line_error(invoke, tmp_path):
    result = invoke("--workdir", tmp_path, "bind")
    assert result.exit_code == 2
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert lines and lines[-1].startswith("faceforge: error:")
    assert "Traceback" not in result.stderr


def test_insertions_naming_no_muscle_of_the_map_are_reported_and_ignored(ctx):
    """The default ``bind.insertions`` names the template's brow depressors; a map without them
    (this fake fit has a frontalis only) binds as before and the log says which were ignored."""
    from faceforge.io.stagefiles import load_npz
    from faceforge.pipeline.stages.bind import run

    said = []
    ctx.log = said.append
    _fake_fit(ctx.workdir / "fit")
    run(ctx)
    d = load_npz(ctx.out_dir / "bind.npz")
    assert len(np.unique(d["anchor_vertex_ids"])) == len(d["anchor_vertex_ids"])   # no second anchors
    warned = [m for m in said if m.startswith("warning: bind.insertions")]
    assert len(warned) == 1 and "corrugator_supercilii" in warned[0] and "frontalis" in warned[0]


@pytest.mark.parametrize("key", ["bind.brow_muscles", "bind.brow_raisers", "bind.cheek_muscles"])
def test_a_misspelt_muscle_in_the_other_name_lists_is_reported(ctx, key):
    """A typo in bind.brow_muscles, brow_raisers or cheek_muscles binds nothing to it; the log
    names the key and the unknown name (it was silently ignored before)."""
    from faceforge.io.config import load_config
    from faceforge.pipeline.stages.bind import run

    said = []
    ctx.log = said.append
    ctx.config = load_config(sets=[f"{key}=[frontalis, frontalsi]"])
    _fake_fit(ctx.workdir / "fit")
    run(ctx)
    warned = [m for m in said if m.startswith(f"warning: {key}:")]
    assert len(warned) == 1 and "frontalsi" in warned[0]
    assert "no muscle frontalis," not in warned[0]   # the known name is not reported
