"""Fixtures shared by the whole suite: the repository root, an isolated stage registry,
and a helper that runs the ``faceforge`` CLI through click's CliRunner."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture
def repo_root() -> Path:
    return ROOT


@pytest.fixture
def stage_registry():
    """Empty stage and command registries for one test (the real ones are restored after it).

    Discovery has already run, so the project's own stage modules do not come back
    during the test: tests see only the dummy stages they register.
    """
    from faceforge.pipeline import stage as registry

    registry.discover()
    stages, commands = dict(registry.STAGES), dict(registry.COMMANDS)
    registry.STAGES.clear()
    registry.COMMANDS.clear()
    yield registry
    registry.STAGES.clear()
    registry.STAGES.update(stages)
    registry.COMMANDS.clear()
    registry.COMMANDS.update(commands)


@pytest.fixture
def invoke():
    """``invoke(*args)`` runs ``faceforge ARGS`` in-process; returns click's Result (stderr apart)."""
    from click.testing import CliRunner

    from faceforge.cli import cli

    def run(*args, **kwargs):
        try:
            runner = CliRunner(mix_stderr=False)
        except TypeError:  # click >= 8.2 always keeps stderr apart
            runner = CliRunner()
        return runner.invoke(cli, [str(a) for a in args], prog_name="faceforge", **kwargs)

    return run


@pytest.fixture
def subprocess_env() -> dict:
    """Environment for ``python`` subprocesses that must import this checkout's faceforge."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT)] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p])
    env["PYTHONDONTWRITEBYTECODE"] = "1"
    return env


PYTHON = sys.executable


# the sample heads fitted once per session, shared by the fit, io, pipeline and scenario tests
from tests.fit.heads import ellipsoid, fitted, template  # noqa: E402,F401  (fixtures)
