"""A stage's key holds what its upstream *wrote* (digests recorded in the upstream's stage.json),
so an upstream rerun after a code change without a version bump makes its downstream stale, and
one that writes the same bytes leaves it up to date (docs/reliability.md)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from faceforge.io.config import load_config
from faceforge.pipeline import Stage, runner
from faceforge.pipeline.cache import record_key


@pytest.fixture
def mapping_chain(stage_registry, tmp_path):
    """``t_cal`` writes a mapping from ``code["scale"]`` (a code change, no version bump);
    ``t_play`` reads it. ``calls`` lists the runs."""
    calls, code = [], {"scale": 2}

    def run_cal(ctx):
        calls.append("t_cal")
        (ctx.out_dir / "mapping.txt").write_text(f"scale {code['scale']}")

    def run_play(ctx):
        calls.append("t_play")
        (ctx.out_dir / "take.txt").write_text((ctx.input("t_cal") / "mapping.txt").read_text() + " played")

    stage_registry.register_stage(Stage("t_cal", run_cal, outputs=("mapping.txt",)))
    stage_registry.register_stage(Stage("t_play", run_play, deps=("t_cal",), outputs=("take.txt",)))
    return calls, code, runner.Workspace(tmp_path / "w")


def _run(ws, target, force=False):
    lines = []
    runner.run(ws, load_config(), {}, [target], force=force, log=lines.append)
    return lines


def test_a_forced_upstream_that_writes_a_new_mapping_makes_the_downstream_stale(mapping_chain):
    calls, code, ws = mapping_chain
    _run(ws, "t_play")
    code["scale"] = 3                                   # the code changed, the version did not
    _run(ws, "t_cal", force=True)
    statuses = {s.stage.name: s.reasons for s in runner.plan(ws, load_config(), {}, ["t_play"])}
    assert statuses == {"t_cal": [], "t_play": ["upstream t_cal changed"]}
    calls.clear()
    lines = _run(ws, "t_play")
    assert calls == ["t_play"] and "t_play: running (upstream t_cal changed)" in lines
    assert (ws.stage_dir("t_play") / "take.txt").read_text() == "scale 3 played"
    stored = json.loads((ws.stage_dir("t_cal") / "stage.json").read_text())
    assert list(stored["output_sha256"]) == ["mapping.txt"]


def test_an_upstream_rerun_writing_the_same_bytes_leaves_the_downstream_up_to_date(mapping_chain):
    calls, code, ws = mapping_chain
    _run(ws, "t_play")
    calls.clear()
    _run(ws, "t_cal", force=True)
    lines = _run(ws, "t_play")
    assert calls == ["t_cal"] and lines == ["t_cal: up to date", "t_play: up to date"]


def test_a_rerun_upstream_in_the_same_run_keys_the_downstream_by_its_new_files(mapping_chain, stage_registry):
    """The plan cannot know a stale upstream's files: the downstream is judged again once it ran."""
    calls, code, ws = mapping_chain
    _run(ws, "t_play")
    (ws.stage_dir("t_cal") / "mapping.txt").unlink()    # t_cal reruns (output missing) and writes the same
    calls.clear()
    lines = _run(ws, "t_play")
    assert calls == ["t_cal"] and lines[-1] == "t_play: up to date"
    code["scale"] = 4
    (ws.stage_dir("t_cal") / "mapping.txt").unlink()
    calls.clear()
    _run(ws, "t_play")
    assert calls == ["t_cal", "t_play"]
    assert (ws.stage_dir("t_play") / "take.txt").read_text() == "scale 4 played"


def test_a_stage_written_before_the_digests_enters_by_its_key(mapping_chain):
    """An upgrade does not rerun every downstream stage: an upstream without recorded digests
    (an older faceforge) counts as before, by its key, until it runs again."""
    calls, code, ws = mapping_chain
    _run(ws, "t_play")
    for name in ("t_cal", "t_play"):                     # as an older faceforge wrote them
        path = ws.stage_dir(name) / "stage.json"
        record = json.loads(path.read_text())
        del record["output_sha256"]
        if name == "t_play":
            record["upstream"] = {"t_cal": json.loads((ws.stage_dir("t_cal") / "stage.json").read_text())["key"]}
            record["key"] = record_key({k: v for k, v in record.items() if k not in ("key", "outputs",
                                                                                   "faceforge_version")})
        path.write_text(json.dumps(record))
    calls.clear()
    assert _run(ws, "t_play") == ["t_cal: up to date", "t_play: up to date"] and calls == []
    code["scale"] = 5
    _run(ws, "t_cal", force=True)                         # its next run records digests
    assert "t_play: running (upstream t_cal changed)" in _run(ws, "t_play")
