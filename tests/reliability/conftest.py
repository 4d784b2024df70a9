"""Fixtures of the reliability suite (issue 28): one fitted and bound MediaPipe workdir per
session, copies of it per test, and a check that a command left a workdir byte for byte as
it was (stage files and remembered inputs)."""

from __future__ import annotations

import hashlib
import shutil
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
MEDIAPIPE = ROOT / "samples" / "mediapipe"


def cli_run(*args, **kwargs):
    """``faceforge ARGS`` in-process; click's Result with ``stderr`` apart."""
    from click.testing import CliRunner

    from faceforge.cli import cli

    try:
        runner = CliRunner(mix_stderr=False)
    except TypeError:  # click >= 8.2
        runner = CliRunner()
    return runner.invoke(cli, [str(a) for a in args], prog_name="faceforge", **kwargs)


def snapshot(folder: Path) -> dict:
    """{relative path: sha256} of every file under ``folder`` (and the folders, as None)."""
    out = {}
    for p in sorted(Path(folder).rglob("*")):
        rel = str(p.relative_to(folder))
        out[rel] = hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() else None
    return out


@pytest.fixture(scope="session")
def fitted_master(tmp_path_factory) -> Path:
    """A workdir with fit and bind of the MediaPipe head (the fastest sample), built once
    per session; a remembered override in config.yaml, so both remembered files exist."""
    base = tmp_path_factory.mktemp("reliab")
    for name in ("face_model_with_iris.obj", "face_model_with_iris.fdp.yaml"):
        shutil.copyfile(MEDIAPIPE / name, base / name)
    work = base / "work"
    r = cli_run("-w", work, "--set", "solver.iterations=10", "fit", base / "face_model_with_iris.obj")
    assert r.exit_code == 0, r.stderr
    r = cli_run("-w", work, "bind")
    assert r.exit_code == 0, r.stderr
    assert (work / "faceforge.yaml").exists() and (work / "config.yaml").exists()
    return work


@pytest.fixture
def fitted(fitted_master, tmp_path) -> Path:
    """A private copy of the fitted workdir (the mesh and landmarks stay where fit read them)."""
    work = tmp_path / "work"
    shutil.copytree(fitted_master, work)
    return work
