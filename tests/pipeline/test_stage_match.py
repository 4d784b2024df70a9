"""The match stage on the synthetic fitted + bound head (tests/animation/synthetic.py): a pose
settled from known controls is given back as a posed mesh, and the stage finds those controls."""

from __future__ import annotations

import hashlib
import json

import numpy as np
import pytest

from tests.animation import synthetic as S
from tests.pipeline.test_stage_animate import SETS, patched, run_stage, undeclared_reads, workdir  # noqa: F401
from tests.pipeline.test_user_files import remembered  # noqa: F401

#: the known pose: the synthetic head's one muscle and the jaw
CONTRACTION, PITCH = 0.6, 0.12


@pytest.fixture(scope="module")
def posed(workdir, patched, tmp_path_factory):  # noqa: F811
    """The synthetic head settled at the known pose, written as an OBJ in the user's order."""
    from faceforge.animation.rig import BoundHead
    from faceforge.animation.statics import SettleSettings, settle
    from faceforge.io.config import load_config
    from faceforge.io.mesh import save_mesh

    config = load_config(None, SETS)
    head = BoundHead(workdir / "fit", workdir / "bind", config)
    c = np.zeros((1, len(head.controls)))
    c[0, list(head.controls).index("zygomaticus_major_L")] = CONTRACTION
    frame = settle(head.rig, c, np.array([[PITCH, 0.0, 0.0]]), float(config.get("animate.fps")),
                   SettleSettings.from_config(config))
    path = tmp_path_factory.mktemp("match") / "posed.obj"
    save_mesh(path, head.to_user(frame)[0], S.skin_mesh()[1])
    return path


MATCH_READ = []


@pytest.fixture(scope="module")
def matched(workdir, posed):  # noqa: F811
    sets = (*SETS, f"animate.fap_mapping={workdir / 'mapping.yaml'}")
    return run_stage("match", workdir, {"match_target": str(posed)}, sets=sets, reads=MATCH_READ)


def test_match_finds_the_controls_that_made_the_pose(matched):
    report = json.loads((matched / "report.json").read_text())
    agreement = report["agreement"]
    assert agreement["cosine"] > 0.97 and 0.9 < agreement["ratio"] < 1.1 and agreement["within"]["met"]
    assert report["controls"]["zygomaticus_major_L"] == pytest.approx(CONTRACTION, abs=0.1)
    assert report["controls"]["jaw.pitch"] == pytest.approx(np.degrees(PITCH), abs=1.5)   # degrees
    assert report["checks"]["ok"] and report["residuals"][-1] < 0.1
    d = np.load(matched / "match.npz")
    rest = S.skin_mesh()[0]
    motion, miss = d["target"] - rest, d["matched"] - d["target"]
    assert np.linalg.norm(miss) < 0.25 * np.linalg.norm(motion)        # the settled pose, not a copy
    assert np.abs(motion).max() > 0.01 * np.ptp(rest, axis=0).max()   # the pose moved the skin
    assert (matched / "match.png").stat().st_size > 10_000


def test_a_closed_lid_is_matched_by_the_lids(workdir, patched, tmp_path):  # noqa: F811
    """A target whose left upper lid is half closed (FAP 19 at 500 IRISD, laid over the rest face as
    playback lays it) is matched by the lid control, not by the muscles (without the lids among the
    controls the lid's motion stayed in the residual)."""
    from faceforge.animation.rig import BoundHead
    from faceforge.io.config import load_config
    from faceforge.io.mesh import save_mesh

    config = load_config(None, SETS)
    head = BoundHead(workdir / "fit", workdir / "bind", config)
    lids = head.eyelids(config)
    assert lids is not None and 19 in lids.faps
    f68 = np.zeros((1, 68))
    f68[0, 18] = 500.0
    frame = lids.apply(head.rest[None], f68, np.zeros((1, 3)))
    path = tmp_path / "blink.obj"
    save_mesh(path, head.to_user(frame)[0], S.skin_mesh()[1])
    sets = (*SETS, f"animate.fap_mapping={workdir / 'mapping.yaml'}")
    out = run_stage("match", workdir, {"match_target": str(path)}, sets=sets)
    report = json.loads((out / "report.json").read_text())
    assert report["agreement"]["cosine"] > 0.95 and report["agreement"]["within"]["met"]
    assert report["controls"]["lid.19"] == pytest.approx(500.0, rel=0.1)
    assert max([0.0, *(abs(v) for n, v in report["controls"].items() if not n.startswith("lid."))]) < 0.05


def test_match_reads_only_the_config_keys_it_declares(matched):
    assert "animate.statics.tolerance" in MATCH_READ or any(k.startswith("animate.statics") for k in MATCH_READ)
    assert not undeclared_reads("match", MATCH_READ)


def test_a_target_that_is_not_the_head_posed_is_one_line(tmp_path):
    """Another vertex count, another vertex order or scale, the head at rest: each a StageError
    naming the file, before any simulation."""
    from faceforge.exceptions import StageError
    from faceforge.io.mesh import save_mesh
    from faceforge.pipeline.stages.match import read_target

    v, f = S.skin_mesh()
    cases = {"fewer.obj": (v[:-3], f[(f < len(v) - 3).all(axis=1)], "vertices"),
             "shuffled.obj": (v[np.random.default_rng(0).permutation(len(v))], f, "not the head posed"),
             "rest.obj": (v, f, "at rest")}
    for name, (verts, faces, words) in cases.items():
        save_mesh(tmp_path / name, verts, faces)
        with pytest.raises(StageError, match=words) as err:
            read_target(tmp_path / name, v)
        assert name in str(err.value.path)


def test_rigid_takes_the_targets_head_motion_out(tmp_path):
    """A posed head that also turned 20 deg and moved: without --rigid it is refused with the hint,
    with it the displacement is the pose's alone and the motion is reported."""
    from scipy.spatial.transform import Rotation

    from faceforge.exceptions import StageError
    from faceforge.io.mesh import save_mesh
    from faceforge.pipeline.stages.match import read_target

    v, f = S.skin_mesh()
    pose = np.zeros_like(v)
    low = v[:, 1] < np.quantile(v[:, 1], 0.3)
    pose[low, 1] = -0.05 * np.ptp(v[:, 1])                    # the lower third drops: a jaw, say
    R = Rotation.from_euler("xyz", [5.0, 20.0, -3.0], degrees=True).as_matrix()
    t = np.array([0.3, -0.2, 0.5]) * np.ptp(v, axis=0)
    save_mesh(tmp_path / "turned.obj", (v + pose) @ R.T + t, f)
    with pytest.raises(StageError, match="give --rigid"):
        read_target(tmp_path / "turned.obj", v)
    delta, motion = read_target(tmp_path / "turned.obj", v, rigid=True)
    assert np.allclose(motion[:3, :3], R, atol=1e-6) and np.allclose(delta, pose, atol=1e-6 * np.ptp(v))


def test_match_never_writes_over_the_users_files(invoke, remembered, tmp_path):  # noqa: F811
    work, mesh, _ = remembered
    target = tmp_path / "smile.obj"
    target.write_text("v 0 0 0\n")
    before = {p: hashlib.sha256(p.read_bytes()).hexdigest() for p in (mesh, target)}
    for out, words in ((target, "is your target"), (mesh.with_suffix(".obj"), None)):
        if words is None:   # the user's mesh under an exportable name
            mesh_obj = mesh.with_suffix(".obj")
            mesh_obj.write_text("v 0 0 0\n")
            from faceforge.pipeline.runner import Workspace
            Workspace(work).save_params({"mesh": str(mesh_obj)})
            words = "is your mesh"
        result = invoke("--workdir", work, "match", target, "-o", out)
        assert result.exit_code == 2, result.stderr
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("faceforge: error: ") and words in lines[0]
    assert {p: hashlib.sha256(p.read_bytes()).hexdigest() for p in (mesh, target)} == before
    assert not (work / "match").exists()
