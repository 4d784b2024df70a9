"""A batch killed with SIGKILL in the middle, then rerun: only the remainder runs."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time

from faceforge.pipeline import batch

HEADS = ("anna", "ben", "carl")


def _done_lines(out):
    """(head, stage) of every "<stage>: done in" line in the per-head batch logs, with repeats."""
    found = []
    for head in HEADS:
        log = out / head / batch.HEAD_LOG
        if log.exists():
            found += [(head, m) for m in re.findall(r" (\w+): done in ", log.read_text())]
    return found


def test_kill_then_rerun_completes_only_the_remainder(tmp_path, heads_dir, short_fap, subprocess_env):
    from .conftest import PLUGIN, ROOT

    out = tmp_path / "out"
    args = [sys.executable, "-m", "faceforge.cli", "--no-progress", "batch",
            *[heads_dir / f"{h}.obj" for h in HEADS], "--fap", short_fap, "--plugin", PLUGIN,
            "--out", out, "--jobs", "1"]
    env = {**subprocess_env, "FACEFORGE_FAKE_DELAY": "0.4"}
    proc = subprocess.Popen([str(a) for a in args], cwd=ROOT, env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    first_done = out / HEADS[0] / "animate" / "stage.json"
    deadline = time.monotonic() + 60
    while not first_done.exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    assert first_done.exists(), proc.stderr.read().decode() if proc.poll() is not None else "timeout"
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    proc.stderr.close()
    assert proc.returncode == -signal.SIGKILL
    assert not (out / batch.REPORT_NAME).exists()
    complete = {(h, s): (out / h / s / "stage.json").stat().st_mtime_ns
                for h in HEADS for s in batch.DEFAULT_TARGETS if (out / h / s / "stage.json").exists()}
    assert all((HEADS[0], s) in complete for s in batch.DEFAULT_TARGETS)
    assert (HEADS[-1], "animate") not in complete                  # killed in the middle

    rerun = subprocess.run([str(a) for a in args], cwd=ROOT, env=subprocess_env, capture_output=True,
                           text=True, timeout=120)
    assert rerun.returncode == 0, rerun.stderr
    report = json.loads((out / batch.REPORT_NAME).read_text())
    for r in report["results"]:
        assert r["status"] == "ok"
        for stage, info in r["stages"].items():
            assert info["state"] == ("cached" if (r["name"], stage) in complete else "ran"), (r["name"], stage)
    for key, mtime in complete.items():                             # finished stages untouched
        assert (out / key[0] / key[1] / "stage.json").stat().st_mtime_ns == mtime
    done = _done_lines(out)                                         # every stage finished exactly once
    assert sorted(done) == sorted((h, s) for h in HEADS for s in batch.DEFAULT_TARGETS)
    assert not [p for p in out.rglob(".tmp-*")]
    assert os.listdir(out / HEADS[0] / "animate")
