"""A result that fails its checks is an error (exit 3) every time it is asked for, names the check
and the frame, writes no outputs; ``--keep-going`` accepts it (docs/reliability.md)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from faceforge.pipeline import Stage
from faceforge.pipeline.result_checks import failed_checks

from .conftest import cli_run

TAKE = {"checks": {"frames": 107, "non_finite": 0, "inverted_triangles": 0, "inverted_faces": 0,
                   "inverted_max_per_frame": 0, "folded_edges": 40, "folded_max_per_frame": 40, "fold_limit": 32,
                   "skin_inside_skull": 1, "ok": False, "where": {"folded": [12, 40], "inside_skull": {"33": 1}}}}


def test_each_failed_check_is_named_with_its_frame():
    assert failed_checks(TAKE) == [
        "skin_inside_skull (1 skin vertex inside the skull at frame 33)",
        "folded_edges (40 skin edges folded in one frame at frame 12, limit 32)"]
    sheet = {"expressions": {"joy": {"checks": {"ok": True}}, "fear": TAKE}}
    assert failed_checks(sheet)[0] == "fear: skin_inside_skull (1 skin vertex inside the skull at frame 33)"
    ok = {"checks": {**TAKE["checks"], "skin_inside_skull": 0, "folded_max_per_frame": 3, "ok": True}}
    assert failed_checks(ok) == []
    # the fit's own checks (no "ok") are the fit stage's business
    assert failed_checks({"checks": {"skull_inside_98pct": False}}) == []


def _grid():
    """A 4x4 vertex sheet (rest (16, 3)) and its 18 triangles."""
    xs, ys = np.meshgrid(np.arange(4.0), np.arange(4.0))
    rest = np.stack([xs.ravel(), ys.ravel(), np.zeros(16)], axis=1)
    faces = []
    for i in range(3):
        for j in range(3):
            a = 4 * i + j
            faces += [[a, a + 1, a + 5], [a, a + 5, a + 4]]
    return rest, np.asarray(faces)


def test_the_checks_say_where_whole_and_streamed():
    from faceforge.animation.check_stream import StreamChecker
    from faceforge.animation.checks import check_animation

    rest, faces = _grid()
    frames = np.repeat(rest[None], 6, axis=0)
    frames[5, 5] = np.nan                 # non-finite at frame 5
    frames[4, 5, 2] = 3.0                 # a spike: triangles around vertex 5 fold
    frames[4, 5, :2] = [2.5, 2.5]         # and turn over
    whole = check_animation(rest, frames, faces)
    stream = StreamChecker(rest, faces, 6)
    for k in range(0, 6, 4):
        stream.add(frames[k:k + 4])
    streamed = stream.report()
    assert whole.where["non_finite"] == 5 and whole.where["inverted"] == 4 and whole.where["folded"][0] == 4
    assert streamed.as_dict() == whole.as_dict()


@pytest.fixture
def take_stage(stage_registry, tmp_path):
    """A stage ``t_take`` writing a report whose checks fail when its input says ``bad``."""
    runs = []

    def run(ctx):
        runs.append(1)
        bad = Path(ctx.params["src"]).read_text().strip() == "bad"
        (ctx.out_dir / "take.txt").write_text("frames")
        (ctx.out_dir / "report.json").write_text(json.dumps(
            {"checks": {**TAKE["checks"], "ok": not bad, "skin_inside_skull": int(bad), "folded_max_per_frame": 0}}))

    stage_registry.register_stage(Stage("t_take", run, inputs=("src",), outputs=("take.txt", "report.json")))
    src = tmp_path / "src.txt"
    return runs, src


def test_a_failed_result_exits_3_every_time_until_kept(take_stage, tmp_path):
    runs, src = take_stage
    work = tmp_path / "w"
    src.write_text("bad")
    first = cli_run("-w", work, "run", "t_take", "--param", f"src={src}")
    assert first.exit_code == 3
    line = first.stderr.strip().splitlines()[-1]
    assert line.startswith(f"faceforge: error: {work / 't_take' / 'report.json'}: t_take failed its checks: "
                           "skin_inside_skull (1 skin vertex inside the skull at frame 33)")
    assert line.endswith("accept it with --keep-going")
    assert (work / "t_take" / "take.txt").exists()       # kept: the next command does not simulate again
    again = cli_run("-w", work, "run", "t_take")           # the remembered input was remembered
    assert again.exit_code == 3 and "t_take: up to date" in again.stderr and len(runs) == 1
    status = cli_run("-w", work, "status")
    assert "up to date; failed its checks: skin_inside_skull" in status.output
    kept = cli_run("-w", work, "-q", "run", "t_take", "--keep-going")
    assert kept.exit_code == 0 and len(runs) == 1
    assert kept.stderr.strip() == ("faceforge: warning: t_take: check failed, kept (--keep-going): "
                                   "skin_inside_skull (1 skin vertex inside the skull at frame 33)")
    src.write_text("good")
    assert cli_run("-w", work, "run", "t_take").exit_code == 0


def test_commands_with_checked_results_take_keep_going():
    from faceforge.cli import cli
    from faceforge.pipeline import stage as registry

    registry.discover()
    for name in ("animate", "expressions", "visemes", "bake", "batch"):
        assert "keep_going" in [p.name for p in registry.COMMANDS[name].params], name
    assert "keep_going" in [p.name for p in cli.commands["run"].params]


def test_a_thrown_vertex_fails_the_checks_whole_and_streamed():
    from faceforge.animation.check_stream import StreamChecker
    from faceforge.animation.checks import check_animation
    from faceforge.pipeline.result_checks import describe

    rest, faces = _grid()                 # 3 x 3 units: diagonal 4.24, displacement limit 1.06
    frames = np.repeat(rest[None], 3, axis=0)
    frames[1] += [0.3, 0.0, 0.9]          # the whole sheet moves 0.95: nothing fails
    frames[2, 15] = [6.0, 6.0, 0.0]       # a corner vertex thrown 4.2 in the plane: no fold, no turn
    assert check_animation(rest, frames[:2], faces).ok
    whole = check_animation(rest, frames, faces)
    assert whole.inverted_triangles == 0 and whole.folded_max_per_frame == 0
    assert not whole.ok and whole.where["thrown"] == 2
    stream = StreamChecker(rest, faces, 3)
    stream.add(frames[:2])
    stream.add(frames[2:])
    assert stream.report() == whole
    (phrase,) = describe(whole.as_dict())
    assert phrase.startswith("thrown_vertex (a skin vertex moved 4.243 units at frame 2, past the limit 1.061")
