"""A workdir faceforge may not write in: one line, exit 2, before the stage's work, nothing left
behind; commands that only read (status, an up-to-date stage) still work."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest

from faceforge.pipeline import Stage

from .conftest import cli_run, snapshot


def _read_only(folder: Path):
    """Make ``folder`` read-only (chmod for a user, ``chattr +i`` for root, who ignores modes);
    returns the undo, or skips when neither works here."""
    if os.geteuid() != 0:
        folder.chmod(0o555)
        return lambda: folder.chmod(0o755)
    done = subprocess.run(["chattr", "+i", str(folder)], capture_output=True)
    if done.returncode != 0:
        pytest.skip("root without chattr: cannot make a folder read-only here")
    return lambda: subprocess.run(["chattr", "-i", str(folder)], check=True)


def test_a_read_only_workdir_is_one_line_before_the_work(stage_registry, tmp_path):
    runs = []

    def run(ctx):
        runs.append(1)
        (ctx.out_dir / "out.txt").write_text(Path(ctx.params["src"]).read_text())

    stage_registry.register_stage(Stage("t_ro", run, inputs=("src",), outputs=("out.txt",)))
    src, work = tmp_path / "src.txt", tmp_path / "w"
    src.write_text("a")
    assert cli_run("-w", work, "run", "t_ro", "--param", f"src={src}").exit_code == 0
    before = snapshot(work)
    undo = _read_only(work)
    try:
        assert cli_run("-w", work, "status").exit_code == 0
        assert cli_run("-w", work, "run", "t_ro").exit_code == 0           # up to date: nothing to write
        src.write_text("b")
        r = cli_run("-w", work, "run", "t_ro")
    finally:
        undo()
    assert r.exit_code == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert lines[-1].startswith(f"faceforge: error: {work}: cannot write in the workdir: ")
    assert "Traceback" not in r.stderr and runs == [1]
    assert snapshot(work) == before
