"""Threads under load (issue 28): the default thread choice against one thread and against
always-threads, with the other core free and with it busy.

Plays ``samples/fap/joy.fap`` (``--loops`` times) on a head already fitted and bound in
``--workdir`` (MakeHuman: its skin is partitioned into parts that numba's threads project), in
one process, three ways, alternating (``--rounds`` rounds):

* ``default``: :class:`faceforge.pbd.thread_choice.ThreadChooser` as shipped;
* ``one``: every step on the calling thread (what ``NUMBA_NUM_THREADS=1`` runs, the same bits);
* ``threads``: every step on numba's threads.

Each round is played twice, with no competing load and with a busy-loop process this script
starts and stops itself (``--pin CPU`` pins it with ``os.sched_setaffinity``); other processes
on the machine are not controlled: the load average is recorded with every row. Reports the
wall ms per frame of each and the ratios default / one and threads / one per round, and their
medians. Writes ``benchmarks/results/threads.json``.

Run: ``NUMBA_NUM_THREADS=2 python benchmarks/bench_threads.py --workdir W [--rounds 5]``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _util import print_table, write_results  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
MODE = {"way": "default"}


def _patch_chooser() -> None:
    """Route ThreadChooser.pick through MODE (the shipped rule for ``default``)."""
    from faceforge.pbd import thread_choice

    shipped = thread_choice.ThreadChooser.pick

    def pick(self):
        if MODE["way"] == "one":
            return False
        if MODE["way"] == "threads":
            return self.enabled
        return shipped(self)

    thread_choice.ThreadChooser.pick = pick


def busy_loop(pin: int | None) -> subprocess.Popen:
    """A process spinning on one core (pinned to CPU ``pin`` when given)."""
    code = "import os,sys\nif len(sys.argv) > 1: os.sched_setaffinity(0, {int(sys.argv[1])})\nwhile True: pass\n"
    return subprocess.Popen([sys.executable, "-c", code] + ([str(pin)] if pin is not None else []))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workdir", required=True, type=Path)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--loops", type=int, default=2, help="joy.fap played this many times per measurement")
    ap.add_argument("--pin", type=int, default=None, help="pin the busy loop to this CPU")
    args = ap.parse_args()
    _patch_chooser()
    from faceforge.animation.controls import track_controls
    from faceforge.animation.playback import play, warm_up
    from faceforge.animation.rig import BoundHead
    from faceforge.io.config import load_config
    from faceforge.mpeg4 import read_fap
    from faceforge.pipeline.stages.animate import mapping_template_path
    from faceforge.animation.fap_mapping import load_fap_mapping

    config = load_config(None, ())
    head = BoundHead(args.workdir / "fit", args.workdir / "bind", config)
    track = read_fap(ROOT / "samples" / "fap" / "joy.fap")
    c, jaw, _, _ = track_controls(track, load_fap_mapping(mapping_template_path(config)), head)
    c, jaw = np.tile(c, (args.loops, 1)), np.tile(jaw, (args.loops, 1))
    warm_up(head.rig, c, jaw, track.fps, print, guards=(head.orientation,))
    rows = []
    for r in range(args.rounds):
        for load in ("free", "busy"):
            spinner = busy_loop(args.pin) if load == "busy" else None
            time.sleep(0.3 if spinner else 0.0)
            try:
                ms = {}
                ways = ("default", "one", "threads")
                for way in ways[r % 3:] + ways[:r % 3]:   # the order turns from round to round
                    MODE["way"] = way
                    head.rig.reset()
                    t0 = time.perf_counter()
                    play(head.rig, c, jaw, track.fps, sink=lambda s, f: None)
                    ms[way] = 1e3 * (time.perf_counter() - t0) / len(jaw)
            finally:
                if spinner is not None:
                    spinner.kill()
                    spinner.wait()
            rows.append({"round": r, "other_core": load, "default_ms": round(ms["default"], 3),
                         "one_ms": round(ms["one"], 3), "threads_ms": round(ms["threads"], 3),
                         "default_over_one": round(ms["default"] / ms["one"], 3),
                         "threads_over_one": round(ms["threads"] / ms["one"], 3),
                         "load1": round(os.getloadavg()[0], 2)})
            print_table(rows[-1:], list(rows[-1]))
    summary = {"workdir": str(args.workdir), "rounds": rows, "numba_threads": os.environ.get("NUMBA_NUM_THREADS"),
               "threaded_solvers": int(head.skin.solver.threads)}
    for load in ("free", "busy"):
        sel = [r for r in rows if r["other_core"] == load]
        summary[f"median_default_over_one_{load}"] = statistics.median(r["default_over_one"] for r in sel)
        summary[f"median_threads_over_one_{load}"] = statistics.median(r["threads_over_one"] for r in sel)
    print_table(rows, list(rows[0]), title="threads under load")
    print({k: v for k, v in summary.items() if k.startswith("median")})
    write_results("threads", summary)


if __name__ == "__main__":
    main()
