"""animate never writes over the user's own files: ``-o`` or ``--preview`` naming the mesh the
head was fitted from (or its landmarks, or the FAP track) is a one-line error before any work,
and the file is left as it was."""

from __future__ import annotations

import hashlib
from pathlib import Path

import pytest

from faceforge.pipeline.runner import Workspace

ROOT = Path(__file__).resolve().parents[2]
FAP = ROOT / "samples" / "fap" / "joy.fap"


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture
def remembered(tmp_path):
    """A workdir remembering a mesh ``head.glb`` and its landmarks (no stage has run: the check
    must come before any)."""
    mesh = tmp_path / "head.glb"
    mesh.write_bytes(b"glTF user mesh bytes")
    landmarks = tmp_path / "head.fdp.yaml"
    landmarks.write_text("fdp: {}\n")
    work = tmp_path / "work"
    work.mkdir()
    Workspace(work).save_params({"mesh": str(mesh), "landmarks": str(landmarks)})
    return work, mesh, landmarks


@pytest.mark.parametrize("option, target, words", [
    ("-o", "head.glb", "is your mesh"),
    ("-o", ".", "holds your mesh"),       # an OBJ-sequence folder would replace the mesh's folder
    ("--preview", "head.fdp.yaml", "is your landmark file"),
])
def test_outputs_never_overwrite_the_users_inputs(invoke, remembered, option, target, words):
    work, mesh, landmarks = remembered
    before = {p: _digest(p) for p in (mesh, landmarks)}
    params_before = (work / "faceforge.yaml").read_bytes()
    result = invoke("--workdir", work, "animate", "--fap", FAP, option, mesh.parent / target)
    assert result.exit_code == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("faceforge: error: ")
    assert words in lines[0] and "never overwrites its inputs" in lines[0]
    assert not (work / "animate").exists() and not (work / "fit").exists()
    assert {p: _digest(p) for p in (mesh, landmarks)} == before
    assert (work / "faceforge.yaml").read_bytes() == params_before


def test_the_fap_track_is_an_input_too(invoke, remembered, tmp_path):
    work, _, _ = remembered
    fap = tmp_path / "take.glb"          # a FAP track with an output's suffix
    fap.write_bytes(FAP.read_bytes())
    result = invoke("--workdir", work, "animate", "--fap", fap, "-o", fap)
    assert result.exit_code == 2 and "is your FAP track" in result.stderr
    assert fap.read_bytes() == FAP.read_bytes()


def test_bake_never_writes_over_the_mesh(invoke, remembered):
    work, mesh, landmarks = remembered
    before = _digest(mesh)
    result = invoke("--workdir", work, "bake", "-o", mesh)
    assert result.exit_code == 2 and "is your mesh" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    assert _digest(mesh) == before and not (work / "bake").exists()
