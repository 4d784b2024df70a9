"""Threads under load (issue 28): the default against one thread, with the other core busy.

Plays ``samples/fap/joy.fap`` on a bound workdir (default: fit and bind of the MakeHuman
sample, built in a temporary folder) in one process, alternating three ways of running the
partitioned steps, with and without a competing busy process that this script starts and
stops itself (``python -c 'while 1: pass'``, killed by its pid):

* ``default``: :class:`faceforge.pbd.thread_choice.ThreadChooser` (threads or the calling
  thread, whichever the clock says);
* ``threads``: always the parts on threads (the behaviour before issue 28);
* ``one``: always the calling thread.

All three give the same bits; only the time differs. Reports the median ms a frame of each
way per condition and the ratio default / one -> ``benchmarks/results/load.json``.

Run: ``python benchmarks/bench_load.py [--workdir W] [--rounds 3]``.
"""

from __future__ import annotations

import argparse
import gc
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from statistics import median

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _util import print_table, write_results  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


class Always:
    """A stand-in for ThreadChooser that always runs one way."""

    def __init__(self, threaded: bool):
        self.threaded = threaded

    def run(self, step, *args):
        step(self.threaded, *args)


def solvers():
    from faceforge.pbd.solver import Solver

    return [o for o in gc.get_objects() if isinstance(o, Solver)]


def set_mode(mode: str) -> None:
    from faceforge.pbd.thread_choice import ThreadChooser

    for s in solvers():
        if mode == "default":
            s._chooser = ThreadChooser(s._threaded)
        else:
            s._chooser = Always(mode == "threads" and s._threaded)


def play_ms(head, c, jaw, fps) -> float:
    """ms a frame of one playback of the track (the rig reset first)."""
    from faceforge.animation.playback import Timings, play

    head.rig.reset()
    t = Timings()
    play(head.rig, c, jaw, fps, timings=t, sink=lambda start, frames: None)
    return t.per_frame_ms()["total"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workdir", default=None, help="a bound workdir (default: MakeHuman, built here)")
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()
    from faceforge.io.config import load_config
    from faceforge.mpeg4 import read_fap
    from faceforge.pipeline import stage as registry
    from faceforge.animation.controls import track_controls
    from faceforge.animation.fap_mapping import load_fap_mapping
    from faceforge.animation.rig import BoundHead

    registry.discover()
    tmp = Path(tempfile.mkdtemp(prefix="load-"))
    try:
        work = Path(args.workdir) if args.workdir else tmp / "w"
        if not args.workdir:
            ff = [sys.executable, "-c", "from faceforge.cli import main; main()", "-q", "-w", str(work)]
            subprocess.run(ff + ["fit", str(ROOT / "samples" / "makehuman" / "mh_head_default.obj")], check=True)
            subprocess.run(ff + ["bind"], check=True)
        config = load_config(None, (), remembered=work / "config.yaml" if (work / "config.yaml").exists() else None)
        head = BoundHead(work / "fit", work / "bind", config)
        track = read_fap(ROOT / "samples" / "fap" / "joy.fap")
        mapping = load_fap_mapping(config.get("animate.fap_mapping"))
        c, jaw, _, _ = track_controls(track, mapping, head)
        set_mode("threads")
        play_ms(head, c[:5], jaw[:5], track.fps)          # compile / load the kernels
        rows = []
        for busy in (False, True):
            hog = subprocess.Popen([sys.executable, "-c", "while 1: pass"]) if busy else None
            try:
                times = {m: [] for m in ("default", "threads", "one")}
                for _ in range(args.rounds):
                    for mode in times:
                        set_mode(mode)
                        times[mode].append(play_ms(head, c, jaw, track.fps))
            finally:
                if hog is not None:
                    os.kill(hog.pid, signal.SIGKILL)
                    hog.wait()
            row = {"competing_load": busy, "load_avg_1min": round(os.getloadavg()[0], 2),
                   **{f"{m}_ms": round(median(v), 3) for m, v in times.items()}}
            row["default_over_one"] = round(row["default_ms"] / row["one_ms"], 3)
            row["threads_over_one"] = round(row["threads_ms"] / row["one_ms"], 3)
            rows.append(row)
            print_table([row], list(row))
        print_table(rows, list(rows[0]), title="ms a frame (median of rounds), joy.fap")
        write_results("load", {"rows": rows, "frames": track.n_frames, "rounds": args.rounds,
                               "threads": max(s.threads for s in solvers()), "when": time.ctime()})
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
