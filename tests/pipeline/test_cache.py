"""The stage cache: skip when up to date, rerun exactly the affected stages with reasons,
atomic stage folders (real kill -9), and the workdir lock (two real processes)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from faceforge.exceptions import StageError
from faceforge.io.config import load_config
from faceforge.pipeline import Stage
from faceforge.pipeline import runner
from faceforge.pipeline.cache import file_digest, record_key, stale_reasons


@pytest.fixture
def chain(stage_registry, tmp_path):
    """Three dummy stages t_a -> t_b -> t_c; ``calls`` lists each run in order."""
    calls: list[str] = []

    def run_a(ctx):
        calls.append("t_a")
        text = Path(ctx.params["src"]).read_text()
        (ctx.out_dir / "a.txt").write_text(text.upper() * ctx.config.get("solver.iterations"))

    def run_b(ctx):
        calls.append("t_b")
        a = (ctx.input("t_a") / "a.txt").read_text()
        (ctx.out_dir / "b.txt").write_text(f"{a}|{ctx.config.get('skin.stiffness.bending')}")

    def run_c(ctx):
        calls.append("t_c")
        (ctx.out_dir / "c.txt").write_text((ctx.input("t_b") / "b.txt").read_text() + "!")

    reg = stage_registry.register_stage
    reg(Stage("t_a", run_a, config_keys=("solver.iterations",), inputs=("src",), outputs=("a.txt",)))
    reg(Stage("t_b", run_b, deps=("t_a",), config_keys=("skin.stiffness",), outputs=("b.txt",)))
    reg(Stage("t_c", run_c, deps=("t_b",), config_keys=("animate",), outputs=("c.txt",)))
    src = tmp_path / "src.txt"
    src.write_text("face")
    return calls, runner.Workspace(tmp_path / "work"), {"src": str(src)}


def run_chain(workspace, params, sets=(), force=False, target="t_c"):
    lines: list[str] = []
    runner.run(workspace, load_config(sets=sets), params, [target], force=force, log=lines.append)
    return lines


def test_first_run_then_up_to_date_rerun_does_nothing(chain):
    calls, ws, params = chain
    assert run_chain(ws, params)[0] == "t_a: running (never run)"
    assert calls == ["t_a", "t_b", "t_c"]
    assert (ws.stage_dir("t_c") / "c.txt").read_text() == "FACE" * 10 + "|0.95!"
    mtimes = {p: p.stat().st_mtime_ns for p in ws.root.rglob("*") if p.is_file()}
    assert run_chain(ws, params) == ["t_a: up to date", "t_b: up to date", "t_c: up to date"]
    assert calls == ["t_a", "t_b", "t_c"]
    assert {p: p.stat().st_mtime_ns for p in ws.root.rglob("*") if p.is_file() and p.name != ".faceforge.lock"} \
        == {p: t for p, t in mtimes.items() if p.name != ".faceforge.lock"}


def test_changed_config_key_reruns_that_stage_and_downstream_only(chain):
    calls, ws, params = chain
    run_chain(ws, params)
    calls.clear()
    lines = run_chain(ws, params, sets=["skin.stiffness.bending=0.5"])
    assert calls == ["t_b", "t_c"]
    assert "t_a: up to date" in lines
    assert "t_b: running (`skin.stiffness.bending` changed)" in lines
    assert "t_c: running (upstream t_b changed)" in lines
    # a key no stage reads changes nothing
    calls.clear()
    run_chain(ws, params, sets=["skin.stiffness.bending=0.5", "fit.refit=false"])
    assert calls == []


def test_changed_input_content_reruns_all_but_a_moved_identical_input_does_not(chain, tmp_path):
    calls, ws, params = chain
    run_chain(ws, params)
    moved = tmp_path / "moved.txt"
    moved.write_text("face")
    calls.clear()
    run_chain(ws, {"src": str(moved)})
    assert calls == []
    moved.write_text("nose")
    lines = run_chain(ws, {"src": str(moved)})
    assert calls == ["t_a", "t_b", "t_c"]
    assert "t_a: running (input moved.txt changed)" in lines


def _as_if_written_before(ws, stage, drop):
    """Rewrite ``stage``'s stage.json as a faceforge that had no config ``drop`` (a dotted leaf
    under one of its config keys, or a whole config key) would have written it."""
    path = ws.stage_dir(stage) / "stage.json"
    record = json.loads(path.read_text())
    if drop in record["config"]:
        record["config"].pop(drop)
    else:
        top = next(k for k in record["config"] if drop.startswith(k + "."))
        tree = record["config"][top]
        keys = drop[len(top) + 1:].split(".")
        for k in keys[:-1]:
            tree = tree[k]
        tree.pop(keys[-1])
    record["key"] = record_key({k: record[k] for k in ("stage", "version", "config", "inputs", "upstream")})
    path.write_text(json.dumps(record))


def test_a_config_key_newer_than_the_workdir_at_its_default_reruns_nothing(chain):
    calls, ws, params = chain
    run_chain(ws, params)
    _as_if_written_before(ws, "t_b", "skin.stiffness.bending")     # a leaf a newer faceforge added
    _as_if_written_before(ws, "t_c", "animate")                    # a key a stage newly reads
    calls.clear()
    assert run_chain(ws, params) == ["t_a: up to date", "t_b: up to date", "t_c: up to date"]
    assert calls == []
    lines = run_chain(ws, params, sets=["skin.stiffness.bending=0.5"])   # set to anything else: it reruns
    assert calls == ["t_b", "t_c"] and "t_b: running (`skin.stiffness.bending` changed)" in lines
    calls.clear()
    assert run_chain(ws, params, sets=["skin.stiffness.bending=0.5"])[1] == "t_b: up to date"
    lines = run_chain(ws, params)                                  # back to the default: written with it now
    assert calls == ["t_b", "t_c"] and "t_b: running (`skin.stiffness.bending` changed)" in lines


def test_status_reasons_without_running(chain):
    calls, ws, params = chain
    run_chain(ws, params)
    statuses = runner.plan(ws, load_config(sets=["solver.iterations=3"]), params)
    reasons = {s.stage.name: s.reasons for s in statuses if s.stage.name.startswith("t_")}
    assert reasons == {"t_a": ["`solver.iterations` changed"], "t_b": ["upstream t_a changed"],
                       "t_c": ["upstream t_b changed"]}
    (ws.stage_dir("t_c") / "c.txt").unlink()
    statuses = runner.plan(ws, load_config(), params, ["t_c"])
    assert [s.reasons for s in statuses] == [[], [], ["output missing: c.txt"]]


def test_a_missing_input_is_said_as_the_last_stage_that_reads_it(stage_registry, tmp_path):
    """The mesh is read by the landmarks stage and then by fit: ``fit MISSING`` names fit with
    no hint (it is the user's own argument), ``bind`` in a new workdir says to run fit."""
    reg = stage_registry.register_stage
    reg(Stage("t_find", lambda ctx: None, inputs=("src",), outputs=()))
    reg(Stage("t_fit", lambda ctx: None, deps=("t_find",), inputs=("src",), outputs=()))
    reg(Stage("t_bind", lambda ctx: None, deps=("t_fit",), outputs=()))
    ws = runner.Workspace(tmp_path / "work")
    with pytest.raises(StageError, match=r"stage t_fit needs input src \(/nonexistent/x not found\)$"):
        runner.run(ws, load_config(), {"src": "/nonexistent/x"}, ["t_fit"], log=lambda line: None)
    with pytest.raises(StageError, match=r"stage t_fit needs input src; run `faceforge run t_fit` first$"):
        runner.run(ws, load_config(), {}, ["t_bind"], log=lambda line: None)


def test_force_reruns_the_target_only(chain):
    calls, ws, params = chain
    run_chain(ws, params)
    calls.clear()
    lines = run_chain(ws, params, force=True, target="t_b")
    assert calls == ["t_b"] and "t_b: running (--force)" in lines


def test_missing_input_is_a_stage_error(chain):
    calls, ws, _ = chain
    with pytest.raises(StageError, match=r"stage t_a needs input src; run `faceforge run t_a` first$"):
        run_chain(ws, {})
    with pytest.raises(StageError, match=r"needs input src \(/nonexistent/x.txt not found\)"):
        run_chain(ws, {"src": "/nonexistent/x.txt"})
    assert calls == []


def test_failing_stage_keeps_previous_folder_and_leaves_no_temp(chain, stage_registry):
    calls, ws, params = chain
    run_chain(ws, params)
    before = (ws.stage_dir("t_b") / "stage.json").read_text()

    def broken(ctx):
        (ctx.out_dir / "b.txt").write_text("half")
        raise RuntimeError("boom")

    old = stage_registry.STAGES["t_b"]
    stage_registry.register_stage(Stage("t_b", broken, deps=old.deps, config_keys=old.config_keys,
                                        outputs=old.outputs, version="2"), replace=True)
    with pytest.raises(RuntimeError, match="boom"):
        run_chain(ws, params)
    assert (ws.stage_dir("t_b") / "stage.json").read_text() == before
    assert (ws.stage_dir("t_b") / "b.txt").read_text() != "half"
    assert not [p for p in ws.root.iterdir() if p.name.startswith((".tmp-", ".trash-"))]


def test_stage_that_skips_a_declared_output_is_not_committed(stage_registry, tmp_path):
    stage_registry.register_stage(Stage("t_lazy", lambda ctx: None, outputs=("x.npz",)))
    ws = runner.Workspace(tmp_path / "w")
    with pytest.raises(StageError, match="stage t_lazy did not write x.npz"):
        runner.run(ws, load_config(), {}, ["t_lazy"])
    assert not ws.stage_dir("t_lazy").exists()


def test_record_key_hashes_content_not_paths(tmp_path):
    record = {"stage": "s", "version": "1", "config": {"a": {"b": 1}},
              "inputs": {"mesh": {"path": "/x/a.obj", "sha256": "00"}}, "upstream": {}}
    moved = dict(record, inputs={"mesh": {"path": "/y/b.obj", "sha256": "00"}})
    changed = dict(record, inputs={"mesh": {"path": "/x/a.obj", "sha256": "01"}})
    assert record_key(record) == record_key(moved) != record_key(changed)
    assert stale_reasons(record, dict(record, key=record_key(record))) == []
    assert stale_reasons(dict(record, config={"a": {"b": 2}}), dict(record, key=record_key(record))) \
        == ["`a.b` changed"]
    assert stale_reasons(record, None) == ["never run"]


def test_a_stage_may_digest_only_the_part_of_an_input_it_reads(tmp_path):
    from faceforge.pipeline.runner import current_record

    first_line = lambda path: Path(path).read_text().splitlines()[0]   # noqa: E731
    stage = Stage("t_part", lambda ctx: None, inputs=("src",), digests={"src": first_line})
    src = tmp_path / "src.txt"
    src.write_text("read\nignored\n")
    before = current_record(stage, load_config(), {"src": str(src)}, {})[0]
    src.write_text("read\nchanged, still ignored\n")
    assert current_record(stage, load_config(), {"src": str(src)}, {})[0] == before
    src.write_text("changed\n")
    assert current_record(stage, load_config(), {"src": str(src)}, {})[0] != before
    with pytest.raises(ValueError, match="digests names inputs"):
        Stage("t_bad", lambda ctx: None, inputs=("src",), digests={"mesh": first_line})


def test_folder_digest_depends_on_names_and_contents(tmp_path):
    d = tmp_path / "d"
    (d / "sub").mkdir(parents=True)
    (d / "sub" / "f.txt").write_text("1")
    first = file_digest(d)
    (d / "sub" / "f.txt").write_text("2")
    second = file_digest(d)
    (d / "sub" / "f.txt").rename(d / "sub" / "g.txt")
    assert len({first, second, file_digest(d)}) == 3


# ---------------------------------------------------------------------------
# real processes: kill -9 mid-stage, and two processes on one workdir

SCRIPT = '''
import os, sys, time
from pathlib import Path
from faceforge.pipeline import Stage, register_stage
from faceforge.cli import main

def slow(ctx):
    (ctx.out_dir / "part1.txt").write_text("written before the sleep")
    Path(os.environ["MARK"]).write_text(str(os.getpid()))
    time.sleep(float(os.environ.get("SLEEP", "0")))
    (ctx.out_dir / "part2.txt").write_text(os.environ.get("TAG", "done"))
    with open(os.environ["COUNTER"], "a") as fh:
        fh.write(os.environ.get("TAG", "done") + "\\n")

register_stage(Stage("t_slow", slow, config_keys=("solver",), outputs=("part1.txt", "part2.txt")))
main(sys.argv[1:])
'''


def _start(tmp_path, env, *args, sleep="0", tag="done"):
    script = tmp_path / "slow_stage.py"
    script.write_text(SCRIPT)
    env = dict(env, MARK=str(tmp_path / f"mark-{tag}"), SLEEP=sleep, TAG=tag, COUNTER=str(tmp_path / "counter"))
    return subprocess.Popen([sys.executable, str(script), "--workdir", str(tmp_path / "w"), *args, "run", "t_slow"],
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _wait_for(path: Path, proc, timeout=30.0):
    deadline = time.monotonic() + timeout
    while not path.exists():
        if proc.poll() is not None:
            raise AssertionError(f"process ended early: {proc.stderr.read()}")
        if time.monotonic() > deadline:
            raise AssertionError(f"{path} never appeared")
        time.sleep(0.02)


def _complete(stage_dir: Path) -> bool:
    return (stage_dir / "stage.json").exists()


def test_kill_9_mid_stage_never_leaves_a_complete_looking_stage(tmp_path, subprocess_env):
    work = tmp_path / "w"
    # 1. killed during the first run: no stage folder at all, only a temp folder
    proc = _start(tmp_path, subprocess_env, sleep="60", tag="first")
    _wait_for(tmp_path / "mark-first", proc)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait(timeout=10)
    assert not (work / "t_slow").exists()
    temps = [p for p in work.iterdir() if p.name.startswith(".tmp-t_slow-")]
    assert len(temps) == 1 and (temps[0] / "part1.txt").exists() and not (temps[0] / "stage.json").exists()

    # 2. the next run removes the leftover and completes the stage
    proc = _start(tmp_path, subprocess_env, tag="second")
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err
    assert "left by an interrupted run" in err
    assert _complete(work / "t_slow") and (work / "t_slow" / "part2.txt").read_text() == "second"
    assert not [p for p in work.iterdir() if p.name.startswith(".tmp-")]
    record = json.loads((work / "t_slow" / "stage.json").read_text())

    # 3. killed while rerunning over a complete stage: the old complete stage is intact
    proc = _start(tmp_path, subprocess_env, "--set", "solver.iterations=3", sleep="60", tag="third")
    _wait_for(tmp_path / "mark-third", proc)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait(timeout=10)
    assert json.loads((work / "t_slow" / "stage.json").read_text()) == record
    assert (work / "t_slow" / "part2.txt").read_text() == "second"
    assert (tmp_path / "counter").read_text().split() == ["second"]


def test_two_processes_on_one_workdir_are_serialized(tmp_path, subprocess_env):
    first = _start(tmp_path, subprocess_env, sleep="1.5", tag="first")
    _wait_for(tmp_path / "mark-first", first)
    second = _start(tmp_path, subprocess_env, tag="second")
    _, err2 = second.communicate(timeout=60)
    _, err1 = first.communicate(timeout=60)
    assert first.returncode == 0 and second.returncode == 0, (err1, err2)
    assert f"waiting for another faceforge process (pid {first.pid})" in err2
    # the second found the stage complete when it got the lock: it ran once, by the first
    assert "t_slow: up to date" in err2
    assert (tmp_path / "counter").read_text().split() == ["first"]


def test_status_lists_a_stage_with_an_unregistered_dep_instead_of_failing(stage_registry, tmp_path):
    stage_registry.register_stage(Stage("t_ok", lambda ctx: None))
    stage_registry.register_stage(Stage("t_orphan", lambda ctx: None, deps=("t_missing",)))
    statuses = runner.plan(runner.Workspace(tmp_path), load_config(), {})
    assert [(s.stage.name, s.reasons) for s in statuses] == [
        ("t_ok", ["never run"]), ("t_orphan", ["depends on unknown stage 't_missing'"])]
    with pytest.raises(StageError, match="stage 't_orphan' depends on unknown stage 't_missing'"):
        runner.run(runner.Workspace(tmp_path), load_config(), {}, ["t_orphan"])


def test_a_user_folder_with_a_stage_name_is_never_overwritten(chain):
    calls, ws, params = chain
    (ws.stage_dir("t_a")).mkdir(parents=True)
    (ws.stage_dir("t_a") / "mine.txt").write_text("keep")
    with pytest.raises(StageError, match="exists but is not a faceforge stage folder"):
        run_chain(ws, params)
    assert (ws.stage_dir("t_a") / "mine.txt").read_text() == "keep"
    assert not [p for p in ws.root.iterdir() if p.name.startswith((".tmp-", ".trash-"))]


def test_same_inputs_give_the_same_stage_bytes(chain, tmp_path):
    calls, ws, params = chain
    run_chain(ws, params)
    other = runner.Workspace(tmp_path / "other")
    run_chain(other, params)
    for name in ("t_a", "t_b", "t_c"):
        files = sorted(p.name for p in ws.stage_dir(name).iterdir())
        assert files == sorted(p.name for p in other.stage_dir(name).iterdir())
        for f in files:
            assert (ws.stage_dir(name) / f).read_bytes() == (other.stage_dir(name) / f).read_bytes()
