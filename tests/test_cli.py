"""The faceforge CLI through click's CliRunner (and one subprocess for the import check)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from faceforge.pipeline import Stage


def statuses(output: str) -> dict[str, str]:
    """``faceforge status`` output -> {stage: state}."""
    rows = [line.split(None, 1) for line in output.splitlines() if line.strip()]
    return {row[0]: row[1].strip() for row in rows}


@pytest.fixture
def echo_stage(stage_registry):
    """A dummy stage ``t_echo`` copying its ``src`` input; ``t_echo_down`` reads it."""
    seen = []

    def run(ctx):
        seen.append(dict(ctx.params))
        total = 0
        for i in ctx.progress(range(3), total=3, desc="counting"):
            total += i
        ctx.log(f"counted {total}")
        (ctx.out_dir / "out.txt").write_text(Path(ctx.params["src"]).read_text())

    def run_down(ctx):
        (ctx.out_dir / "down.txt").write_text((ctx.input("t_echo") / "out.txt").read_text() * 2)

    stage_registry.register_stage(Stage("t_echo", run, config_keys=("solver.iterations",), inputs=("src",),
                                        outputs=("out.txt",), description="copies src"))
    stage_registry.register_stage(Stage("t_echo_down", run_down, deps=("t_echo",), outputs=("down.txt",)))
    return seen


def test_help_imports_nothing_heavy(subprocess_env):
    code = ("import sys\nfrom faceforge.cli import main\n"
            "try:\n    main(['--help'])\nexcept SystemExit as e:\n    assert e.code == 0, e.code\n"
            "heavy = [m for m in ('numpy', 'numba', 'trimesh', 'scipy', 'meshio', 'tqdm') if m in sys.modules]\n"
            "print('HEAVY', heavy)\n")
    out = subprocess.run([sys.executable, "-c", code], env=subprocess_env, capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert "Usage: faceforge" in out.stdout
    assert out.stdout.strip().splitlines()[-1] == "HEAVY []"


def test_help_lists_builtin_and_registered_commands(invoke, stage_registry):
    import click

    @click.command("t_hello", help="A test command.")
    def hello():
        click.echo("hi")

    stage_registry.register_command(hello)
    result = invoke("--help")
    assert result.exit_code == 0
    for name in ("status", "run", "clean", "config", "t_hello"):
        assert f"  {name} " in result.output
    assert invoke("t_hello").output == "hi\n"


def test_run_status_and_up_to_date(invoke, echo_stage, tmp_path):
    src = tmp_path / "src.txt"
    src.write_text("hello")
    work = tmp_path / "w"
    first = invoke("--workdir", work, "run", "t_echo_down", "--param", f"src={src}")
    assert first.exit_code == 0, first.stderr
    assert "t_echo: running (never run)" in first.stderr and "t_echo: counted 3" in first.stderr
    assert (work / "t_echo_down" / "down.txt").read_text() == "hellohello"
    status = statuses(invoke("--workdir", work, "status").output)
    assert status["t_echo"] == "up to date" and status["t_echo_down"] == "up to date"
    again = invoke("--workdir", work, "run", "t_echo_down")
    assert "t_echo: up to date" in again.stderr and "t_echo_down: up to date" in again.stderr
    assert len(echo_stage) == 1


def test_params_are_remembered_as_absolute_paths(invoke, echo_stage, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    Path("src.txt").write_text("x")
    assert invoke("--workdir", "w", "run", "t_echo", "--param", "src=src.txt").exit_code == 0
    remembered = yaml.safe_load((tmp_path / "w" / "faceforge.yaml").read_text())
    assert remembered == {"params": {"src": str(tmp_path / "src.txt")}}
    Path("src.txt").write_text("y")  # continue without repeating the path: input change detected
    result = invoke("--workdir", "w", "run", "t_echo")
    assert "t_echo: running (input src.txt changed)" in result.stderr
    assert echo_stage[-1]["src"] == str(tmp_path / "src.txt")


def test_overrides_are_remembered_shown_and_reset(invoke, echo_stage, tmp_path):
    src = tmp_path / "src.txt"
    src.write_text("x")
    work = tmp_path / "w"
    assert invoke("-w", work, "--set", "solver.iterations=4", "run", "t_echo", "--param", f"src={src}").exit_code == 0
    shown = invoke("-w", work, "config", "show").output
    assert "  iterations: 4  # from " + str(work / "config.yaml") in shown
    assert statuses(invoke("-w", work, "status").output)["t_echo"] == "up to date"
    assert invoke("-w", work, "config", "reset").exit_code == 0
    status = statuses(invoke("-w", work, "status").output)
    assert status["t_echo"] == "stale: `solver.iterations` changed"
    assert status["t_echo_down"] == "stale: never run"


def test_config_show_is_valid_yaml_of_the_merged_config(invoke, tmp_path):
    result = invoke("-w", tmp_path, "--set", "skin.stiffness.bending=0.5", "config", "show", "--no-origins")
    assert result.exit_code == 0
    assert yaml.safe_load(result.output)["skin"]["stiffness"]["bending"] == 0.5


def test_config_validate_reports_every_error_with_lines(invoke, tmp_path):
    good = tmp_path / "good.yaml"
    good.write_text("solver:\n  iterations: 3\n")
    assert invoke("-w", tmp_path, "config", "validate", good).exit_code == 0
    bad = tmp_path / "my.yaml"
    bad.write_text("solver:\n  iterations: 3\nskin:\n  stiffness:\n    bending: high\n    aera: 0.5\n")
    result = invoke("-w", tmp_path, "config", "validate", bad)
    assert result.exit_code == 2
    assert result.stderr.splitlines() == [
        f"faceforge: error: {bad}:5: skin.stiffness.bending: expected a number in [0, 1], got 'high'",
        f"faceforge: error: {bad}:6: skin.stiffness.aera: unknown key (did you mean skin.stiffness.area?)",
    ]


def test_invalid_config_stops_before_any_work(invoke, echo_stage, tmp_path):
    bad = tmp_path / "my.yaml"
    bad.write_text("solver:\n  iterations: many\n")
    result = invoke("-w", tmp_path / "w", "--config", bad, "run", "t_echo")
    assert result.exit_code == 2
    assert result.stderr == f"faceforge: error: {bad}:2: solver.iterations: expected an integer in [1, 1000], got 'many'\n"
    assert echo_stage == [] and not (tmp_path / "w").exists()
    result = invoke("-w", tmp_path, "--set", "skin.stiffness.bending=2", "status")
    assert result.exit_code == 2
    assert result.stderr == "faceforge: error: --set: skin.stiffness.bending: expected a number in [0, 1], got 2\n"


def test_errors_are_one_line_and_traceback_only_with_verbose(invoke, tmp_path):
    quiet = invoke("-w", tmp_path, "--config", tmp_path / "nope.yaml", "status")
    assert quiet.exit_code == 2
    assert quiet.stderr == f"faceforge: error: {tmp_path / 'nope.yaml'}: config file not found\n"
    loud = invoke("-v", "-w", tmp_path, "--config", tmp_path / "nope.yaml", "status")
    assert loud.exit_code == 2 and "Traceback" in loud.stderr
    assert loud.stderr.rstrip().splitlines()[-1] == quiet.stderr.rstrip()


def test_unknown_stage_and_missing_input(invoke, echo_stage, tmp_path):
    result = invoke("-w", tmp_path, "run", "nosuch")
    assert result.exit_code == 2 and "unknown stage 'nosuch' (stages: " in result.stderr and "t_echo" in result.stderr
    result = invoke("-w", tmp_path / "w", "run", "t_echo")
    assert result.exit_code == 2
    assert result.stderr == f"faceforge: error: {tmp_path / 'w'}: stage t_echo needs input src\n"
    result = invoke("-w", tmp_path / "w", "run", "t_echo_down")     # the missing input is upstream's
    assert result.exit_code == 2
    assert result.stderr == (f"faceforge: error: {tmp_path / 'w'}: stage t_echo needs input src; "
                             "run `faceforge run t_echo` first\n")


def test_quiet_silences_logs_and_progress_can_be_forced(invoke, echo_stage, tmp_path):
    src = tmp_path / "src.txt"
    src.write_text("x")
    quiet = invoke("-q", "-w", tmp_path / "q", "run", "t_echo", "--param", f"src={src}")
    assert quiet.exit_code == 0 and quiet.stderr == ""
    plain = invoke("-w", tmp_path / "p", "run", "t_echo", "--param", f"src={src}")
    assert "counting" not in plain.stderr  # not a terminal: no bar
    forced = invoke("--progress", "-w", tmp_path / "f", "run", "t_echo", "--param", f"src={src}")
    assert "t_echo: counting:" in forced.stderr and "0/3" in forced.stderr


def test_clean_removes_stage_folders_only(invoke, echo_stage, tmp_path):
    src = tmp_path / "src.txt"
    src.write_text("x")
    work = tmp_path / "w"
    assert invoke("-w", work, "run", "t_echo_down", "--param", f"src={src}").exit_code == 0
    (work / "notes.txt").write_text("mine")
    result = invoke("-w", work, "clean", "t_echo_down")
    assert result.exit_code == 0 and not (work / "t_echo_down").exists() and (work / "t_echo").exists()
    (work / "t_echo_down").mkdir()  # a user folder with a stage's name but no stage.json
    result = invoke("-w", work, "clean")
    assert "kept" in result.stderr and (work / "t_echo_down").is_dir()
    assert not (work / "t_echo").exists()
    assert (work / "notes.txt").read_text() == "mine" and (work / "faceforge.yaml").exists()
    assert invoke("-w", work, "clean", "--forget").exit_code == 0
    assert not (work / "faceforge.yaml").exists() and (work / "notes.txt").exists()


def test_app_run_stage_updates_and_forgets_params(echo_stage, tmp_path):
    from faceforge.cli import App

    src = tmp_path / "src.txt"
    src.write_text("x")
    app = App(str(tmp_path / "w"), None, (), -1, False)
    app.run_stage("t_echo", {"src": str(src), "note": "kept as given"})
    assert app.workspace.load_params() == {}            # remembered once the command succeeded
    app.commit_remembered()
    assert app.workspace.load_params() == {"src": str(src), "note": "kept as given"}
    app.run_stage("t_echo", {"note": None})
    app.commit_remembered()
    assert app.workspace.load_params() == {"src": str(src)}


def test_workdir_from_the_environment(invoke, echo_stage, tmp_path):
    src = tmp_path / "src.txt"
    src.write_text("x")
    result = invoke("run", "t_echo", "--param", f"src={src}", auto_envvar_prefix="FACEFORGE",
                    env={"FACEFORGE_WORKDIR": str(tmp_path / "envwork")})
    assert result.exit_code == 0, result.stderr
    assert (tmp_path / "envwork" / "t_echo" / "stage.json").exists()


@pytest.mark.parametrize("command", ["expressions", "visemes"])
def test_a_sheet_command_wants_a_png(invoke, tmp_path, command):
    result = invoke("-w", tmp_path / "w", command, "-o", tmp_path / "sheet.txt")
    assert result.exit_code == 2
    assert result.stderr == f"faceforge: error: {tmp_path / 'sheet.txt'}: the sheet is a PNG: give -o a .png path\n"
    assert not (tmp_path / "w").exists() or not any((tmp_path / "w").iterdir())


def test_animate_visemes_are_checked_before_any_work(invoke, tmp_path):
    result = invoke("-w", tmp_path / "w", "animate", "--visemes", "p_b_m, a,schwa")
    assert result.exit_code == 2
    assert result.stderr.splitlines() == [
        "faceforge: error: --visemes: unknown viseme 'schwa'; valid: none, p_b_m, f_v, th, t_d, k_g, "
        "ch_j_sh, s_z, n_l, r, a, e, i, o, u"]
    assert not (tmp_path / "w" / "inputs").exists()
    result = invoke("-w", tmp_path / "w", "animate", "--visemes", "a", "--expression", "joy")
    assert result.exit_code == 2
    assert "give exactly one of --fap FILE, --expression NAME or --visemes" in result.stderr


def test_animate_visemes_write_the_track_they_name(tmp_path):
    from types import SimpleNamespace

    from faceforge.animation.fap_mapping import viseme_weights
    from faceforge.mpeg4 import VISEME_CODES
    from faceforge.io.config import load_config
    from faceforge.mpeg4 import read_fap
    from faceforge.pipeline.stages.animate import _viseme_file

    app = SimpleNamespace(config=load_config(), workspace=SimpleNamespace(root=tmp_path))
    path = _viseme_file(app, "p_b_m, a u")
    assert path.parent == tmp_path / "inputs"
    w = viseme_weights(read_fap(path).viseme)
    said = [k + 1 for k in np.argmax(w, axis=1)[w.max(axis=1) == 1.0]]
    assert [k for i, k in enumerate(said) if i == 0 or said[i - 1] != k] == \
        [VISEME_CODES["p_b_m"], VISEME_CODES["a"], VISEME_CODES["u"]]
    assert _viseme_file(app, "p_b_m a,u") == path        # the same visemes, the same file
