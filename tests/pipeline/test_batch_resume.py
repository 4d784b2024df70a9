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


def _running(pid: int) -> bool:
    """True while ``pid`` exists and is not a zombie waiting to be reaped."""
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


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


def test_killing_the_batch_takes_its_worker_processes_along(tmp_path, heads_dir, short_fap, subprocess_env):
    """A SIGKILLed batch leaves no orphan worker writing into the workdirs (PR_SET_PDEATHSIG)."""
    from .conftest import PLUGIN, ROOT

    out = tmp_path / "out"
    args = [sys.executable, "-m", "faceforge.cli", "--no-progress", "batch",
            *[heads_dir / f"{h}.obj" for h in HEADS], "--fap", short_fap, "--plugin", PLUGIN,
            "--out", out, "--jobs", "2"]
    env = {**subprocess_env, "FACEFORGE_FAKE_DELAY": "5"}
    proc = subprocess.Popen([str(a) for a in args], cwd=ROOT, env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    logs = [out / h / batch.HEAD_LOG for h in HEADS[:2]]
    deadline = time.monotonic() + 60
    while not all(p.exists() and "fit: running" in p.read_text() for p in logs) and time.monotonic() < deadline:
        time.sleep(0.05)
    workers = {int(re.search(r"pid (\d+)", p.read_text()).group(1)) for p in logs}
    assert len(workers) == 2 and proc.pid not in workers
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    deadline = time.monotonic() + 10
    alive = set(workers)
    while alive and time.monotonic() < deadline:
        for pid in list(alive):
            if not _running(pid):
                alive.discard(pid)
        time.sleep(0.05)
    assert not alive, f"worker processes {alive} outlived the killed batch"
    assert not any((out / h / "fit" / "stage.json").exists() for h in HEADS)


def test_ctrl_c_stops_at_once_with_status_130_and_a_partial_report(tmp_path, heads_dir, short_fap, subprocess_env):
    """SIGINT to the batch's process group (a terminal's Ctrl-C): exit 130 within seconds, the
    report marks unfinished heads "interrupted", and the same command resumes them."""
    from .conftest import PLUGIN, ROOT

    out = tmp_path / "out"
    args = [str(a) for a in [sys.executable, "-m", "faceforge.cli", "--no-progress", "batch",
                             *[heads_dir / f"{h}.obj" for h in HEADS], "--fap", short_fap,
                             "--plugin", PLUGIN, "--out", out, "--jobs", "2"]]
    # a terminal's process gets SIGINT's default action; one started from a background job
    # (``pytest ... &``) inherits it ignored, and Python then never raises KeyboardInterrupt
    proc = subprocess.Popen(args, cwd=ROOT, env={**subprocess_env, "FACEFORGE_FAKE_DELAY": "5"},
                            start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    logs = [out / h / batch.HEAD_LOG for h in HEADS[:2]]
    deadline = time.monotonic() + 60
    while not all(p.exists() and "fit: running" in p.read_text() for p in logs) and time.monotonic() < deadline:
        time.sleep(0.05)
    t0 = time.monotonic()
    os.killpg(proc.pid, signal.SIGINT)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 130, err
    assert time.monotonic() - t0 < 4.0                      # did not wait for the 5 s stages
    assert "run the same command again to resume" in err
    report = json.loads((out / batch.REPORT_NAME).read_text())
    assert (report["ok"], report["failed"], report["interrupted"]) == (0, 0, 3)
    rerun = subprocess.run(args, cwd=ROOT, env=subprocess_env, capture_output=True, text=True, timeout=120)
    assert rerun.returncode == 0, rerun.stderr
    assert not list(out.rglob(".tmp-*"))                    # the killed stages' temp folders were cleaned
