"""Running a batch with the fake stages: a bad head fails alone, reruns hit the cache,
per-head overrides key only their head, exports round trip, process pool = in-process."""

from __future__ import annotations

import json
import textwrap

import numpy as np
import pytest

from faceforge.pipeline import batch

from .conftest import GOOD


def _stage_mtimes(out, names=GOOD):
    return {(h, s): (out / h / s / "stage.json").stat().st_mtime_ns
            for h in names for s in batch.DEFAULT_TARGETS if (out / h / s / "stage.json").exists()}


def _report(out):
    return json.loads((out / batch.REPORT_NAME).read_text())


@pytest.fixture
def batch_cli(invoke, fake_stages, heads_dir, short_fap):
    def run(out, *extra, heads=None):
        heads = heads if heads is not None else [heads_dir / f"{n}.obj" for n in GOOD + ("broken",)]
        return invoke("--no-progress", "batch", *heads, "--fap", short_fap, "--plugin", fake_stages,
                      "--out", out, "--jobs", 1, *extra)
    return run


def test_a_broken_head_fails_alone_and_reruns_hit_the_cache(batch_cli, tmp_path, heads_dir, short_fap):
    out = tmp_path / "out"
    first = batch_cli(out, "-o", ".pc2")
    assert first.exit_code == 1, first.output + first.stderr
    report = _report(out)
    by_name = {r["name"]: r for r in report["results"]}
    assert (report["heads"], report["ok"], report["failed"]) == (4, 3, 1)
    bad = by_name["broken"]
    assert bad["status"] == "failed" and "\n" not in bad["error"]
    assert bad["mesh"] == str(heads_dir / "broken.obj")
    assert bad["error"].startswith(str(heads_dir / "broken.obj")) and "OBJ" in bad["error"]
    assert bad["stages"]["fit"]["state"] == "failed"
    assert bad["stages"]["bind"]["state"] == bad["stages"]["animate"]["state"] == "not run"
    assert f"broken: {bad['error']}" in first.stdout            # the summary names the cause
    for name in GOOD:
        r = by_name[name]
        assert r["status"] == "ok" and r["error"] is None
        assert [s["state"] for s in r["stages"].values()] == ["ran"] * 3
        assert r["metrics"]["fit"]["mesh.vertices"] == 478
        assert r["metrics"]["bind"]["regions.face_front.fraction.bound"] == 1.0
        assert str(out / name / "animate" / "animation.npz") in r["outputs"]["animate"]
    # the export holds exactly the animate stage's frames
    from faceforge.io.export import read_pc2
    from faceforge.io.stagefiles import load_npz

    frames, _, _ = read_pc2(by_name["anna"]["outputs"]["export"])
    np.testing.assert_array_equal(frames, load_npz(out / "anna" / "animate" / "animation.npz")["frames"])

    before = _stage_mtimes(out)
    second = batch_cli(out, "-o", ".pc2")
    assert second.exit_code == 1
    assert _stage_mtimes(out) == before                         # nothing rewritten
    for r in _report(out)["results"]:
        if r["name"] != "broken":
            assert [s["state"] for s in r["stages"].values()] == ["cached"] * 3
    assert not list(out.glob("*/.tmp-*"))


def test_all_good_heads_exit_0(batch_cli, tmp_path, heads_dir):
    result = batch_cli(tmp_path / "out", heads=[heads_dir / "anna.obj", heads_dir / "ben.obj"])
    assert result.exit_code == 0, result.stderr
    assert "2 of 2 heads ok" in result.stdout


def test_a_per_head_override_reruns_only_that_head(invoke, fake_stages, tmp_path, heads_dir, short_fap):
    out = tmp_path / "out"

    def manifest(refit_b: bool):
        path = tmp_path / "m.yaml"
        path.write_text(textwrap.dedent(f"""\
            fap: {short_fap}
            heads:
              - mesh: {heads_dir / 'anna.obj'}
              - mesh: {heads_dir / 'ben.obj'}
                set: {{fit.refit: {str(refit_b).lower()}}}
            """))
        return invoke("--no-progress", "batch", path, "--plugin", fake_stages, "--out", out, "--jobs", 1)

    assert manifest(True).exit_code == 0
    before = _stage_mtimes(out, ("anna", "ben"))
    assert manifest(False).exit_code == 0
    after = _stage_mtimes(out, ("anna", "ben"))
    states = {r["name"]: [s["state"] for s in r["stages"].values()] for r in _report(out)["results"]}
    # ben's fit reran; it wrote the same files (the fake fit does not read fit.refit), so its
    # downstream stages, keyed by what their upstream wrote, stay cached
    assert states == {"anna": ["cached"] * 3, "ben": ["cached", "cached", "ran"]}   # animate, bind, fit
    assert all(after[k] == before[k] for k in before if k != ("ben", "fit"))
    assert after[("ben", "fit")] != before[("ben", "fit")]
    # the head's workdir remembers its overrides: the single-head commands agree with the batch
    status = invoke("--workdir", out / "ben", "status")
    lines = {line.split()[0]: line for line in status.stdout.splitlines() if line.strip()}
    assert all("up to date" in lines[name] for name in batch.DEFAULT_TARGETS), status.stdout


def test_run_head_never_raises_and_records_the_failing_stage(fake_stages, tmp_path, heads_dir, short_fap):
    shared = batch.SharedOptions(fap=str(short_fap), plugins=(fake_stages,))
    bad = batch.run_head(batch.make_job(heads_dir / "broken.obj", tmp_path, shared))
    good = batch.run_head(batch.make_job(heads_dir / "anna.obj", tmp_path, shared))
    assert not bad.ok and bad.stages["fit"]["state"] == "failed" and bad.outputs == {}
    assert good.ok and set(good.outputs) == set(batch.DEFAULT_TARGETS)
    log = (tmp_path / "broken" / batch.HEAD_LOG).read_text()
    assert "batch: failed in fit:" in log


def test_process_pool_gives_the_in_process_results(fake_stages, tmp_path, heads_dir, short_fap):
    shared = batch.SharedOptions(fap=str(short_fap), plugins=(fake_stages,))
    names = ("anna", "broken", "ben")
    seen = []
    pooled = batch.run_local([batch.make_job(heads_dir / f"{n}.obj", tmp_path / "pool", shared) for n in names],
                             2, on_result=seen.append)
    alone = batch.run_local([batch.make_job(heads_dir / f"{n}.obj", tmp_path / "one", shared) for n in names], 1)
    assert [r.name for r in pooled] == list(names) and sorted(r.name for r in seen) == sorted(names)
    assert [r.status for r in pooled] == [r.status for r in alone] == ["ok", "failed", "ok"]
    assert pooled[1].error == alone[1].error
    assert [r.metrics for r in pooled] == [r.metrics for r in alone]
    from faceforge.io.stagefiles import load_npz

    for n in ("anna", "ben"):
        np.testing.assert_array_equal(load_npz(tmp_path / "pool" / n / "animate" / "animation.npz")["frames"],
                                      load_npz(tmp_path / "one" / n / "animate" / "animation.npz")["frames"])


def test_summary_lists_every_head_and_each_error(tmp_path):
    ok = batch.HeadResult("a", str(tmp_path / "a"), status="ok", seconds=2.0,
                          stages={"fit": {"state": "ran", "seconds": 1.5}, "bind": {"state": "cached", "seconds": 0.0}},
                          metrics={"fit": {"landmarks.max_residual": 0.0123}})
    bad = batch.HeadResult("b", str(tmp_path / "b"), error="b.obj:1: bad line",
                           stages={"fit": {"state": "failed", "seconds": 0.1}, "bind": {"state": "not run", "seconds": 0}})
    text = batch.format_summary([ok, bad])
    rows = text.splitlines()
    assert rows[0].split() == ["head", "status", "fit", "bind", "fit", "resid", "total"]
    assert rows[2].split()[:4] == ["a", "ok", "1.5s", "cached"] and "0.0123" in rows[2]
    assert rows[3].split()[:5] == ["b", "failed", "FAIL", "0.1s", "-"]
    assert "1 of 2 heads ok, 1 failed:" in text and "b: b.obj:1: bad line" in text
    report = batch.batch_report([ok, bad], tmp_path, 30.0, "processes x2")
    assert (report["ok"], report["failed"], report["heads_per_minute"]) == (1, 1, 4.0)
    assert json.loads(json.dumps(report))["results"][1]["error"] == "b.obj:1: bad line"


def test_a_head_that_kills_its_worker_fails_alone(fake_stages, tmp_path, heads_dir, short_fap, monkeypatch):
    monkeypatch.setenv("FACEFORGE_FAKE_CRASH", "ben")        # inherited by the spawned workers
    shared = batch.SharedOptions(fap=str(short_fap), plugins=(fake_stages,))
    names = ("anna", "ben", "carl", "broken")
    results = batch.run_local([batch.make_job(heads_dir / f"{n}.obj", tmp_path, shared) for n in names], 2)
    assert [r.status for r in results] == ["ok", "failed", "ok", "failed"]
    assert results[1].error.startswith("worker process died")
    assert "OBJ" in results[3].error


def test_progress_bar_over_heads_and_quiet(invoke, fake_stages, tmp_path, heads_dir, short_fap):
    heads = [heads_dir / "anna.obj", heads_dir / "broken.obj"]
    common = ("--fap", short_fap, "--plugin", fake_stages, "--jobs", 1)
    bar = invoke("--progress", "batch", *heads, "--out", tmp_path / "a", *common)
    assert bar.exit_code == 1 and "heads: 100%" in bar.stderr and "2/2" in bar.stderr
    quiet = invoke("-q", "batch", *heads, "--out", tmp_path / "b", *common)
    assert quiet.exit_code == 1 and quiet.stdout == ""
    (line,) = quiet.stderr.strip().splitlines()                   # only the failed head's error
    assert line.startswith("broken: failed in") and str(heads_dir / "broken.obj") in line
    assert "anna" not in quiet.stderr and "%" not in quiet.stderr


def test_an_obj_sequence_export_keeps_the_heads_own_polygons(batch_cli, tmp_path, heads_dir):
    """`batch -o folder` writes the user's quads back, as `faceforge animate -o` does."""
    from faceforge.io.export import read_obj_sequence
    from faceforge.io.mesh import load_mesh

    quad_head = tmp_path / "quad.obj"
    text = (heads_dir / "anna.obj").read_text()
    quad_head.write_text(text + "\nf 1 2 3 4\n")       # one quad among the triangles
    (tmp_path / "quad.fdp.yaml").write_text((heads_dir / "anna.fdp.yaml").read_text())
    out = tmp_path / "out"
    result = batch_cli(out, "-o", "/", heads=[quad_head])
    assert result.exit_code == 0, result.stdout + result.stderr
    export = _report(out)["results"][0]["outputs"]["export"]
    frames, polygons = read_obj_sequence(export)
    _, triangles, info = load_mesh(quad_head)
    assert len(polygons) == info.face_source.max() + 1 == len(triangles) - 1
    assert polygons[-1] == (0, 1, 2, 3)
