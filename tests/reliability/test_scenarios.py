"""End-to-end reliability scenarios (issue 28) on real heads: each runs fit (and bind,
animate) for real, so they are marked slow."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from faceforge.skin.influence import influence_weights

from .conftest import MEDIAPIPE, cli_run

DATA = Path(__file__).resolve().parents[1] / "data" / "makehuman-identities"


def test_an_anchored_vertex_no_face_references_does_not_stop_bind():
    """``ValueError: a source vertex is referenced by no face`` after a fit of a mesh with a
    stray vertex near the face: it keeps its own weight and spreads nothing."""
    v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [0.5, 0.5, 0.01]])
    f = np.array([[0, 1, 2], [1, 3, 2]])
    w, d, scale = influence_weights(v, f, [0, 4])
    assert w[4] == 1.0 and w[0] == 1.0 and np.isfinite(d[:4]).all() and scale > 0
    w, _, _ = influence_weights(v, f, [4])
    assert w.tolist() == [0, 0, 0, 0, 1]


@pytest.mark.slow
def test_the_makehuman_identity_fits_cleanly_and_a_failed_check_stops_a_fit(tmp_path):
    """The identity head fit: a sphere around the head once (0 % inside), then 96 % with the
    enhancement flows stretching the bone out through the lids (issue 28); with their step
    limit (``fit.enhancement_max_step``) it passes every check. Without the limit it still
    fails, and a failed check is exit 3 naming it, unless the user keeps it."""
    mesh, lm = DATA / "mh_head_caucasian_female_young.obj", DATA / "mh_head_caucasian_female_young.fdp.yaml"
    r = cli_run("-w", tmp_path / "ok", "fit", mesh, "--landmarks", lm)
    assert r.exit_code == 0, r.stderr
    report = json.loads((tmp_path / "ok" / "fit" / "report.json").read_text())
    assert all(report["checks"].values()), report["checks"]
    assert report["skull"]["inside_fraction"] >= 0.98 and report["muscles"]["inside_fraction"] >= 0.98
    r = cli_run("-w", tmp_path / "w", "--set", "fit.enhancement_max_step=0", "fit", mesh, "--landmarks", lm)
    assert r.exit_code == 3
    line = r.stderr.splitlines()[-1]
    assert line.startswith(f"faceforge: error: {mesh}: the fit failed its checks: ")
    # the check that fails names its figure: without the step limit the skull was ~96 % inside
    # (0 % before that: a sphere around the head); on the symmetric rig (the default) the
    # muscles poke out instead
    assert re.search(r"(skull_inside_98pct \(skull 9\d\.\d% inside|muscles_poke_below_1pct \(muscles poke "
                     r"\d+\.\d% of the diagonal)", line), line
    assert not (tmp_path / "w" / "fit").exists() and not (tmp_path / "w" / "faceforge.yaml").exists()
    r = cli_run("-w", tmp_path / "w", "--set", "fit.enhancement_max_step=0", "--set", "fit.allow_failed_checks=true",
                "fit", mesh, "--landmarks", lm)
    assert r.exit_code == 0, r.stderr
    assert "check failed, kept" in r.stderr
    report = json.loads((tmp_path / "w" / "fit" / "report.json").read_text())
    assert report["skull"]["inside_fraction"] > 0.9 and report["muscles"]["inside_fraction"] > 0.85


@pytest.mark.slow
def test_fap_values_of_1e9_are_clamped_and_the_head_turns_at_most_90_degrees(fitted, tmp_path):
    bits = ["0"] * 68
    bits[2] = bits[48] = "1"                               # open_jaw, head_yaw
    mask = " ".join(bits)
    fap = tmp_path / "big.fap"
    fap.write_text("2.1 big 25 6\n" + "".join(f"{mask}\n{i} {0 if i < 2 else 1e9} {0 if i < 2 else 1e300}\n"
                                               for i in range(6)))
    # the clamp is the FAP reader's; the template mapping plays (calibration has its own tests)
    r = cli_run("-w", fitted, "--set", "animate.calibrate.enabled=false", "animate", "--fap", fap,
                "-o", tmp_path / "big.pc2")
    report = json.loads((fitted / "animate" / "report.json").read_text())
    checks = report["checks"]
    # a take that fails its checks is exit 3 and writes no -o (--keep-going accepts it)
    assert r.exit_code == (0 if checks["ok"] else 3), r.stderr
    assert (tmp_path / "big.pc2").exists() == checks["ok"]
    warn = [ln for ln in r.stderr.splitlines() if ln.startswith("faceforge: warning: ")]
    assert len(warn) == 1 and "clamped" in warn[0] and "FAP 49 head_yaw" in warn[0]
    assert max(report["max_head_rotation_deg"]) <= 90.0 + 1e-6
    assert checks["ok"] == (checks["non_finite"] == 0 and checks["inverted_triangles"] == 0
                            and checks["skin_inside_skull"] == 0
                            and checks["folded_max_per_frame"] <= checks["fold_limit"])


def _two_heads(folder: Path) -> Path:
    """The MediaPipe face and a copy of it 30 cm to its left, in one OBJ (the copy's ids follow)."""
    lines = (MEDIAPIPE / "face_model_with_iris.obj").read_text().splitlines()
    vs = [ln for ln in lines if ln.startswith("v ")]
    fs = [ln for ln in lines if ln.startswith("f ")]
    n = len(vs)
    moved = [f"v {float(p[1]) + 30.0} {p[2]} {p[3]}" for p in (ln.split() for ln in vs)]
    shifted = ["f " + " ".join(str(int(c.split("/")[0]) + n) for c in ln.split()[1:]) for ln in fs]
    path = folder / "two.obj"
    path.write_text("\n".join(vs + moved + [" ".join(c.split("/")[0] for c in ln.split()) for ln in fs]
                              + shifted) + "\n")
    return path


@pytest.mark.slow
def test_the_landmark_less_second_head_does_not_swing_with_the_head_turn(tmp_path):
    mesh = _two_heads(tmp_path)
    w = tmp_path / "w"
    r = cli_run("-w", w, "fit", mesh, "--landmarks", MEDIAPIPE / "face_model_with_iris.fdp.yaml")
    assert r.exit_code == 0, r.stderr
    assert "separate pieces" in r.stderr
    bits = ["0"] * 68
    bits[48] = "1"                                         # head_yaw only
    fap = tmp_path / "yaw.fap"
    fap.write_text("2.1 yaw 25 4\n" + "".join(f"{' '.join(bits)}\n{i} {i * 20000}\n" for i in range(4)))
    # head_yaw moves no muscle: the template mapping plays (calibration has its own tests)
    r = cli_run("-w", w, "--set", "animate.calibrate.enabled=false", "animate", "--fap", fap,
                "-o", tmp_path / "yaw.pc2")
    assert r.exit_code == 0, r.stderr
    from faceforge.io.export_cache import read_pc2

    frames = read_pc2(tmp_path / "yaw.pc2")[0]
    n = len(frames[0]) // 2
    first, second = frames[:, :n], frames[:, n:]
    assert np.linalg.norm(first[-1] - first[0], axis=1).max() > 1.0     # the head turned (cm)
    assert np.array_equal(second[-1], second[0])                        # the other one did not
    shutil.rmtree(w)
