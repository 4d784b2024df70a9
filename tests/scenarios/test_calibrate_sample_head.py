"""Scenario on a real sample head: the MediaPipe face, fitted and bound once per session
through the CLI, then played with short clips (the full eight-file x three-head sweep is
``python benchmarks/bench_animate.py --sweep``)."""

from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
MESH = ROOT / "samples" / "mediapipe" / "face_model_with_iris.obj"
XFACE = ROOT / "samples" / "fap"

pytestmark = pytest.mark.slow


def cli(*args):
    from click.testing import CliRunner

    from faceforge.cli import cli as group

    result = CliRunner().invoke(group, [str(a) for a in args], catch_exceptions=False)
    assert result.exit_code == 0, result.output
    return result


@pytest.fixture(scope="session")
def head_workdir(tmp_path_factory):
    wd = tmp_path_factory.mktemp("mediapipe")
    cli("-q", "-w", wd, "fit", MESH)
    cli("-q", "-w", wd, "bind")
    return wd


def clip(src: Path, dst: Path, frames: int) -> Path:
    from faceforge.mpeg4 import FapTrack, read_fap, write_fap

    t = read_fap(src)
    write_fap(dst, FapTrack(t.fps, t.values[:frames], t.mask[:frames], t.viseme[:frames],
                            t.expression[:frames], t.frame_numbers[:frames], t.name, t.version))
    return dst


@pytest.mark.parametrize("name", ["anger"])
def test_xface_clip_plays_clean_and_exports_in_input_order(head_workdir, tmp_path, name):
    import json

    from faceforge.io.export import read_mdd
    from faceforge.io.mesh import load_mesh

    fap = clip(XFACE / f"{name}.fap", tmp_path / f"{name}.fap", 25)
    out = tmp_path / f"{name}.mdd"
    cli("-q", "-w", head_workdir, "animate", "--fap", fap, "-o", out)
    report = json.loads((head_workdir / "animate" / "report.json").read_text())
    checks = report["checks"]
    assert checks["non_finite"] == 0 and checks["inverted_triangles"] == 0
    assert checks["skin_inside_skull"] == 0
    frames = read_mdd(out)[0]
    v, _, _ = load_mesh(MESH)
    assert frames.shape == (25, len(v), 3)
    # same vertex order as the input: every vertex starts where the user's mesh has it
    diag = np.linalg.norm(np.ptp(v, axis=0))
    assert np.abs(frames[0] - v).max() < 0.02 * diag
    assert np.abs(frames - v).max() > 0.002 * diag            # and the face moved


def test_open_jaw_parts_the_lips_by_the_requested_amount(head_workdir):
    """Calibrate open_jaw alone (a short one) and check the lip separation within 15 %."""
    from faceforge.animation.playback import static_poses
    from faceforge.animation.calibrate import calibrate_mapping
    from faceforge.animation.calibrate_head import calibration_probes, lip_opening
    from faceforge.animation.fap_mapping import load_fap_mapping
    from faceforge.io.config import load_config
    from faceforge.animation.controls import controls
    from faceforge.animation.rig import BoundHead

    config = load_config()
    head = BoundHead(head_workdir / "fit", head_workdir / "bind", config)
    mapping = load_fap_mapping(ROOT / "templates" / "fap_mapping.yaml")

    def simulate(m, faps):
        c, jaw = controls(m, faps, head)
        return static_poses(head.rig, c, jaw, 25.0, settle=20)

    probes = calibration_probes(mapping, head)
    calibrated, rows = calibrate_mapping(mapping, simulate, head.rest, {3: probes[3]}, {3: [300.0]},
                                         refine=1, sample_scale=(0.5, 1.0))
    lips = lip_opening(calibrated, simulate, head, 300.0)
    assert lips["achieved"] > 0.0                             # the lips part
    assert lips["relative_error"] <= 0.15, lips


def test_visemes_shape_the_mouth_of_a_real_head(head_workdir):
    """``animate --visemes`` on the MediaPipe face (template mapping): the checks pass, the open
    vowel parts the lips more than the rest pose, the bilabial does not part them, and the
    rounded vowel brings the mouth corners closer together than the spread one."""
    import json

    import yaml

    from faceforge.io.stagefiles import load_npz

    said = ["p_b_m", "a", "u", "i"]
    cli("-q", "-w", head_workdir, "animate", "--visemes", ",".join(said))
    report = json.loads((head_workdir / "animate" / "report.json").read_text())
    assert report["visemes"] == ["p_b_m", "a", "i", "u"] and 1 not in report["unmapped_faps"]
    checks = report["checks"]
    assert checks["non_finite"] == 0 and checks["inverted_triangles"] == 0
    assert checks["skin_inside_skull"] == 0
    frames = load_npz(head_workdir / "animate" / "animation.npz")["frames"].astype(np.float64)
    marks = yaml.safe_load(MESH.with_suffix(".fdp.yaml").read_text())["landmarks"]
    vid = {k: marks[k]["vertex"] for k in ("2.2", "2.3", "8.3", "8.4")}
    # each viseme's hold: viseme_track's defaults (0.15 s of rest, 0.2 s each, 0.08 s fades)
    hold = {name: round(25 * (0.15 + 0.2 * i + 0.14)) for i, name in enumerate(said)}

    def parting(f):
        return frames[f, vid["2.2"], 1] - frames[f, vid["2.3"], 1]

    def width(f):
        return frames[f, vid["8.3"], 0] - frames[f, vid["8.4"], 0]

    assert parting(hold["a"]) > parting(0) + 0.02 * width(0)       # the jaw drops for A:
    assert parting(hold["p_b_m"]) <= parting(0) + 1e-6             # lips together for p, b, m
    assert width(hold["u"]) < width(0) < width(hold["i"])          # rounded < rest < spread
