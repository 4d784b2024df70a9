"""The batch with the real fit, bind and animate stages: the MediaPipe head (478 v) and a
garbage OBJ, a 0.12 s expression; the good head completes with the real reports'
metrics, the broken one fails alone, a rerun is all cache hits."""

from __future__ import annotations

import json

import numpy as np
import pytest

from faceforge.pipeline import batch


@pytest.mark.slow
def test_real_stages_one_good_head_one_broken(invoke, tmp_path, heads_dir):
    out = tmp_path / "out"
    args = ("--no-progress", "batch", heads_dir / "anna.obj", heads_dir / "broken.obj", "--expression", "joy",
            "--seconds", 0.12, "--out", out, "--jobs", 1, "-o", ".pc2")
    first = invoke(*args)
    assert first.exit_code == 1, (first.stderr, first.exception)
    report = json.loads((out / batch.REPORT_NAME).read_text())
    anna, broken = report["results"]
    assert broken["status"] == "failed" and broken["error"].startswith(str(heads_dir / "broken.obj"))
    assert anna["status"] == "ok", anna["error"]
    assert sorted(anna["stages"]) == ["animate", "bind", "calibrate", "fit", "landmarks"]
    assert [s["state"] for s in anna["stages"].values()] == ["ran"] * 5
    assert anna["metrics"]["fit"]["mesh.n_vertices"] == 478
    assert 0 <= anna["metrics"]["fit"]["landmarks.max_residual"] < 0.05
    assert anna["metrics"]["bind"]["regions.face_front.fraction.bound"] > 0.5
    assert anna["metrics"]["animate"]["checks.ok"] is True

    from faceforge.io.export import read_pc2
    from faceforge.io.stagefiles import load_npz

    frames, _, _ = read_pc2(anna["outputs"]["export"])
    animation = load_npz(out / "anna" / "animate" / "animation.npz")["frames"]
    assert frames.shape == animation.shape and frames.shape[1] == 478
    np.testing.assert_array_equal(frames, animation)

    second = invoke(*args)
    assert second.exit_code == 1
    again = json.loads((out / batch.REPORT_NAME).read_text())["results"][0]
    assert [s["state"] for s in again["stages"].values()] == ["cached"] * 5
