"""Shared inputs of the batch tests: copies of the smallest sample head, a garbage OBJ,
a short FAP clip, and the fake-stage plugin (restored registries after each test)."""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PLUGIN = Path(__file__).with_name("fake_stages.py")
MEDIAPIPE = ROOT / "samples" / "mediapipe" / "face_model_with_iris.obj"
GOOD = ("anna", "ben", "carl")


@pytest.fixture(scope="session")
def heads_dir(tmp_path_factory) -> Path:
    """Three copies of the MediaPipe head (478 v) with landmarks, and ``broken.obj`` (garbage)."""
    folder = tmp_path_factory.mktemp("heads")
    for name in GOOD:
        shutil.copy(MEDIAPIPE, folder / f"{name}.obj")
        shutil.copy(MEDIAPIPE.with_name("face_model_with_iris.fdp.yaml"), folder / f"{name}.fdp.yaml")
    (folder / "broken.obj").write_text("v 0.1 0.2\nf 1 2 3\nthis is not an OBJ\n")
    shutil.copy(folder / "anna.fdp.yaml", folder / "broken.fdp.yaml")
    return folder


@pytest.fixture(scope="session")
def short_fap(tmp_path_factory) -> Path:
    """The first 6 frames of samples/fap/joy.fap."""
    from faceforge.mpeg4 import FapTrack, read_fap, write_fap

    t = read_fap(ROOT / "samples" / "fap" / "joy.fap")
    n = 6
    short = FapTrack(t.fps, t.values[:n], t.mask[:n], t.viseme[:n], t.expression[:n], t.frame_numbers[:n],
                     name="joy-short", version=t.version)
    path = tmp_path_factory.mktemp("fap") / "joy_short.fap"
    write_fap(path, short)
    return path


@pytest.fixture
def fake_stages():
    """Load the fake stages for this test (in this process); the real registry comes back after it."""
    from faceforge.pipeline import batch
    from faceforge.pipeline import stage as registry

    registry.discover()
    stages, commands = dict(registry.STAGES), dict(registry.COMMANDS)
    batch.import_plugins([str(PLUGIN)])
    yield str(PLUGIN)
    for name in [m for m in sys.modules if m.startswith("faceforge_plugin_")]:
        del sys.modules[name]
    registry.STAGES.clear()
    registry.STAGES.update(stages)
    registry.COMMANDS.clear()
    registry.COMMANDS.update(commands)
