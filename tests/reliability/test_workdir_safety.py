"""What the user gave is not lost (issue 28): remembered inputs after failures, a foreign
config.yaml, a lock path that is a folder, leftovers of a killed OBJ-sequence export."""

from __future__ import annotations

import os
import shutil

import numpy as np

from faceforge.io.export_obj import clean_leftovers, write_obj_sequence

from .conftest import cli_run, snapshot

FOREIGN = "# my build settings\nsteps: [compile, link]\nsolver: gcc\n"


def test_a_foreign_config_yaml_in_the_current_folder_is_ignored_and_kept(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "config.yaml").write_text(FOREIGN)
    r = cli_run("status")
    assert r.exit_code == 0, r.stderr
    assert "is not a faceforge config" in r.stderr and "ignored" in r.stderr
    r = cli_run("--set", "solver.iterations=5", "config", "show")
    assert r.exit_code == 0, r.stderr
    assert "iterations: 5" in r.stdout
    for args in (("config", "reset"), ("clean", "--forget")):
        r = cli_run(*args)
        assert r.exit_code == 0, r.stderr
        assert "kept" in r.stderr
    assert (tmp_path / "config.yaml").read_text() == FOREIGN


def test_faceforge_own_config_yaml_is_still_read(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "config.yaml").write_text("solver:\n  iterations: 7\n")   # no header, but valid: ours
    r = cli_run("config", "show")
    assert r.exit_code == 0 and "iterations: 7" in r.stdout
    (tmp_path / "config.yaml").write_text("# config overrides remembered for this workdir\nsolver:\n  iterations: 0\n")
    r = cli_run("status")   # ours (the header) and broken: an error, not silently ignored
    assert r.exit_code == 2 and "solver.iterations" in r.stderr


def test_the_lock_path_being_a_folder_is_one_line(fitted):
    (fitted / ".faceforge.lock").unlink(missing_ok=True)
    (fitted / ".faceforge.lock").mkdir()
    before = snapshot(fitted)
    r = cli_run("-w", fitted, "bind", "--force")
    assert r.exit_code == 2
    assert r.stderr.splitlines() == [f"faceforge: error: {fitted / '.faceforge.lock'}: the workdir's lock file "
                                     "is a folder; remove it (faceforge writes a file there)"]
    assert snapshot(fitted) == before


def test_the_copied_workdir_is_up_to_date(fitted):
    r = cli_run("-w", fitted, "status")
    assert r.exit_code == 0
    assert "fit          up to date" in r.stdout and "bind         up to date" in r.stdout


def test_yaml_1_2_floats_are_numbers(tmp_path):
    r = cli_run("-w", tmp_path, "--set", "solver.damping=5e-2", "--set", "animate.fps=3E1", "config", "show")
    assert r.exit_code == 0, r.stderr
    assert "damping: 0.05" in r.stdout and "fps: 30.0" in r.stdout


def _sequence(folder, n=3):
    v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    write_obj_sequence(folder, np.stack([v + k for k in range(n)]), np.array([[0, 1, 2]]), 25.0)


def test_a_killed_obj_sequence_export_leaves_nothing_behind_the_next_run(tmp_path):
    out = tmp_path / "anim"
    _sequence(out)
    before = snapshot(out)
    # what a kill -9 leaves: a staging folder of a dead process, and the previous sequence
    # moved aside (".old") with the new one not yet in place
    dead = 2 ** 22 + 12345                      # above pid_max's default: no such process
    (tmp_path / f".anim.{dead}.abcd1234.tmp").mkdir()
    (tmp_path / f".anim.{dead}.abcd1234.tmp" / "anim_0001.obj").write_text("half")
    (tmp_path / ".anim.zz9x8y7w.tmp").mkdir()   # a leftover of a version without the pid
    old = tmp_path / f".anim.{dead}.efgh5678.old"
    old.mkdir()
    shutil.move(str(out), str(old / "anim"))
    alive = tmp_path / f".anim.{os.getpid()}.live0000.tmp"   # a running writer's: kept
    alive.mkdir()
    removed = clean_leftovers(out)
    assert len(removed) == 3 and out.is_dir() and snapshot(out) == before   # the user's sequence is back
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["anim", alive.name])
    alive.rmdir()
    _sequence(out, n=2)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["anim"]
    assert len(list(out.iterdir())) == 2
