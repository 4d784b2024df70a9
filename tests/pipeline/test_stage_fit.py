"""`faceforge fit` through the CLI: stage files, cache, clean errors."""

from __future__ import annotations

import json
import shutil

from tests.fit.heads import SAMPLES


def test_fit_command_writes_the_stage_and_reuses_it(invoke, tmp_path, template):
    mesh = SAMPLES["mediapipe"]
    work = tmp_path / "w"
    first = invoke("-w", work, "--no-progress", "fit", mesh)
    assert first.exit_code == 0, (first.stderr, first.exception)
    for name in ("fit.npz", "report.json", "fit.png", "muscle_map.yaml", "stage.json"):
        assert (work / "fit" / name).is_file()
    report = json.loads((work / "fit" / "report.json").read_text())
    assert report["mesh"]["n_vertices"] == 478 and report["landmarks"]["count"] == 46
    again = invoke("-w", work, "--no-progress", "fit", mesh)
    assert again.exit_code == 0 and "up to date" in again.stderr
    assert "fit: wrote" in first.stderr and "fit: wrote" not in again.stderr   # it wrote nothing


def test_landmark_problems_are_one_line_errors(invoke, tmp_path, template):
    mesh = tmp_path / "head.obj"
    shutil.copy(SAMPLES["mediapipe"], mesh)
    text = SAMPLES["mediapipe"].with_name("face_model_with_iris.fdp.yaml").read_text()
    bad = tmp_path / "head.fdp.yaml"
    bad.write_text(text.replace('"9.3":', '"9.33":'))
    result = invoke("-w", tmp_path / "w", "--no-progress", "fit", mesh)
    assert result.exit_code == 2
    line = result.stderr.strip().splitlines()[-1]
    assert line.startswith("faceforge: error: ") and "head.fdp.yaml" in line and "9.33" in line
    assert "Traceback" not in result.stderr


def test_broken_mesh_is_a_one_line_error(invoke, tmp_path):
    mesh = tmp_path / "fin.obj"
    mesh.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nv 1 1 1\n"
                    "f 1 2 3\nf 1 2 4\nf 1 2 5\n")
    (tmp_path / "fin.fdp.yaml").write_text('landmarks:\n  "2.1": {vertex: 0}\n')
    result = invoke("-w", tmp_path / "w", "--no-progress", "fit", mesh)
    assert result.exit_code == 2
    assert "fin.obj" in result.stderr and "non-manifold" in result.stderr
