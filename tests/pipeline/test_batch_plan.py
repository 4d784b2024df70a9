"""Planning a batch: manifests and overrides are validated before any work, with file:line."""

from __future__ import annotations

import pickle
import textwrap
from pathlib import Path

import pytest

from faceforge.exceptions import ConfigError, FaceforgeError, StageError
from faceforge.pipeline import batch


def test_nest_flatten_round_trip():
    flat = {"a.b": 1, "a.c.d": [1, 2], "e": "x", "f.g": {}}
    assert batch.flatten(batch.nest(flat)) == flat
    tree = {"solver": {"iterations": 4, "damping": 0.1}, "fit": {"refit": False}}
    assert batch.nest(batch.flatten(tree)) == tree


def test_headjob_pickles_to_an_equal_job(heads_dir, short_fap):
    shared = batch.SharedOptions(fap=str(short_fap), overrides={"fit.refit": False}, output=".pc2")
    job = batch.make_job(heads_dir / "anna.obj", heads_dir / "out", shared)
    again = pickle.loads(pickle.dumps(job))
    assert again == job
    assert again.workdir == str(heads_dir / "out" / "anna") and again.output.endswith("anna/anna.pc2")


def _manifest(tmp_path, text: str):
    path = tmp_path / "m.yaml"
    path.write_text(textwrap.dedent(text))
    return path


def test_manifest_jobs_resolve_paths_and_merge_overrides(tmp_path, heads_dir, short_fap):
    path = _manifest(tmp_path, f"""\
        fap: {short_fap}
        output: .mdd
        set: {{solver.iterations: 7, fit.refit: true}}
        heads:
          - mesh: {heads_dir / 'anna.obj'}
            set: {{fit.refit: false}}
          - mesh: {heads_dir / 'ben.obj'}
            name: benjamin
            landmarks: {heads_dir / 'anna.fdp.yaml'}
        """)
    a, b = batch.load_manifest(path, tmp_path / "out", batch.SharedOptions())
    assert a.overrides == {"solver.iterations": 7, "fit.refit": False}
    assert b.overrides == {"solver.iterations": 7, "fit.refit": True}
    assert b.name == "benjamin" and b.workdir == str(tmp_path / "out" / "benjamin")
    assert b.landmarks == str(heads_dir / "anna.fdp.yaml") and a.landmarks is None
    assert a.fap == str(short_fap) and a.output.endswith("anna.mdd")


def test_command_line_options_win_over_the_manifest(tmp_path, heads_dir, short_fap):
    path = _manifest(tmp_path, f"""\
        fap: {short_fap}
        heads: [{{mesh: {heads_dir / 'anna.obj'}}}]
        """)
    cli = batch.SharedOptions(expression="joy", seconds=0.2)
    (job,) = batch.load_manifest(path, tmp_path, cli, cli_given=["expression", "seconds"])
    assert job.fap is None and job.expression == "joy" and job.seconds == 0.2


@pytest.mark.parametrize("body, line, words", [
    ("fap: {fap}\nheads:\n  - mesh: {mesh}\n    colour: red\n", 4, "colour: unknown key"),
    ("fap: {fap}\nheads:\n  - mesh: {mesh}\n  - mesh: nowhere.obj\n", 4, "file not found"),
    ("fap: {fap}\nheads:\n  - mesh: {mesh}\n    set:\n      fit.refit: maybe\n", 5, "fit.refit"),
    ("fap: {fap}\nheads:\n  - mesh: {mesh}\n    set:\n      solverr.iterations: 3\n", 5, "unknown key"),
    ("fap: {fap}\nheads:\n  - mesh: {mesh}\n  - mesh: {mesh}\n", None, "share the workdir"),
    ("fap: {fap}\nheads: []\n", 2, "non-empty list"),
    ("fap: {fap}\nexpression: joy\nheads:\n  - mesh: {mesh}\n", None, "exactly one"),
    ("fap: {fap}\nexpresion: joy\nheads:\n  - mesh: {mesh}\n", 2, "expresion: unknown key"),
    ("fap: {fap}\nheads:\n  - mesh: {mesh}\n    name: ../up\n", 4, "folder name"),
    ("heads:\n  - mesh: {mesh}\n    x: @bad\n", 3, "not valid YAML"),
])
def test_manifest_errors_name_the_file_and_line(tmp_path, heads_dir, short_fap, body, line, words):
    path = _manifest(tmp_path, body.format(fap=short_fap, mesh=heads_dir / "anna.obj"))
    with pytest.raises((StageError, ConfigError)) as info:
        batch.load_manifest(path, tmp_path / "out", batch.SharedOptions())
    err = info.value
    assert words in str(err) and err.path == str(path)
    if line is not None:
        assert err.line == line, str(err)
    assert "\n" not in str(err)
    assert not (tmp_path / "out").exists()


def test_bad_manifest_exits_2_before_any_work(invoke, tmp_path, heads_dir, short_fap):
    path = _manifest(tmp_path, f"fap: {short_fap}\nheads:\n  - mesh: {heads_dir / 'anna.obj'}\n"
                               f"    set: {{fit.refit: 3}}\n")
    result = invoke("--no-progress", "batch", path, "--out", tmp_path / "out", "--jobs", 1)
    assert result.exit_code == 2
    assert f"{path}:4: fit.refit" in result.stderr
    assert not (tmp_path / "out").exists()


def test_bad_invocations_exit_2(invoke, tmp_path, heads_dir, short_fap):
    out = tmp_path / "out"
    both = invoke("batch", heads_dir / "anna.obj", "--fap", short_fap, "--expression", "joy", "--out", out)
    missing = invoke("batch", heads_dir / "nobody.obj", "--fap", short_fap, "--out", out)
    suffix = invoke("batch", heads_dir / "anna.obj", "--fap", short_fap, "-o", ".xyz", "--out", out)
    assert (both.exit_code, missing.exit_code, suffix.exit_code) == (2, 2, 2)
    assert "exactly one" in both.stderr and "nobody.obj: head mesh not found" in missing.stderr
    assert ".xyz" in suffix.stderr
    assert not out.exists()


def test_overrides_are_checked_against_the_schema(tmp_path):
    assert batch.validate_overrides({"fit.refit": False}, "m.yaml", tmp_path) == {"fit.refit": False}
    with pytest.raises(FaceforgeError, match=r"m.yaml:9: fit.refitt: unknown key"):
        batch.validate_overrides({"fit.refitt": False}, "m.yaml", tmp_path, {"fit.refitt": 9})


@pytest.mark.parametrize("stem", ["..", ".", ".hidden"])
def test_a_mesh_stem_never_names_a_workdir_outside_out(tmp_path, heads_dir, short_fap, stem):
    """A mesh ``...obj`` (stem ``..``) made its workdir ``<out>/..``: faceforge then wrote its stage
    folders into the parent and replaced a ``config.yaml`` of the user's there."""
    mesh = tmp_path / f"{stem}.obj"
    mesh.write_bytes((heads_dir / "anna.obj").read_bytes())
    out = tmp_path / "runs"
    for job in (batch.make_job(mesh, out, batch.SharedOptions(fap=str(short_fap))),
                batch.jobs_from_meshes([mesh], out, batch.SharedOptions(fap=str(short_fap)))[0]):
        assert Path(job.workdir).parent == out
        assert job.name not in (".", "..") and not job.name.startswith(".")


def test_a_manifest_head_without_a_name_stays_inside_out(tmp_path, heads_dir, short_fap):
    (tmp_path / "...obj").write_bytes((heads_dir / "anna.obj").read_bytes())
    path = _manifest(tmp_path, f"""\
        fap: {short_fap}
        heads:
          - mesh: {tmp_path / '...obj'}
        """)
    (job,) = batch.load_manifest(path, tmp_path / "runs", batch.SharedOptions())
    assert job.workdir == str(tmp_path / "runs" / "head")


def test_a_manifest_reads_yaml_12_numbers_and_refuses_an_alias_bomb(tmp_path, heads_dir, short_fap):
    """The manifest is user YAML like a config file: ``5e-2`` is a number and a bomb is one line."""
    path = _manifest(tmp_path, f"""\
        fap: {short_fap}
        set: {{solver.damping: 5e-2}}
        heads:
          - mesh: {heads_dir / 'anna.obj'}
        """)
    (job,) = batch.load_manifest(path, tmp_path / "out", batch.SharedOptions())
    assert job.overrides["solver.damping"] == 0.05
    bomb = "a: &a [x, x, x, x, x, x, x, x, x, x]\n" + "".join(
        f"{c}: &{c} [{', '.join(['*' + p] * 10)}]\n" for p, c in zip("abcdefgh", "bcdefghi"))
    path = _manifest(tmp_path, bomb + "heads: []\n")
    with pytest.raises(StageError, match="alias bomb"):
        batch.load_manifest(path, tmp_path / "out", batch.SharedOptions())
