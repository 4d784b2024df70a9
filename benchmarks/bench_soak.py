"""A long take: memory flat in the frame count, no NaN, no inverted triangle, no drift (issue 28).

Fits and binds a sample head once, then plays takes of 1,000, 5,000 and 10,000 frames (a
FAP track: ``samples/fap/joy.fap`` looped, then ``--tail`` neutral frames), each in its own
``faceforge animate ... -o take.pc2`` process, and reports per take:

* ``peak_rss_mb``: the process's peak resident memory (``wait4``'s ``ru_maxrss``), simulation,
  stage file and the PC2 export included; flat in the frame count is the point;
* ``non_finite`` and ``inverted_triangles``: from the stage's report;
* ``drift_rel``: the largest distance between the take's last frame and the last frame of a
  one-loop take (the same track, the same neutral tail: the two end in the same state unless
  a long take accumulates error), as a fraction of the head's bounding-box diagonal; must be
  <= 1e-4. ``rest_residual_rel``: the last frame against the first (neutral) one, how far the
  tail's settling has got (not a drift: the one-loop take has it too).

Takes are whole loops of joy.fap (108 frames) plus the tail: "1000 frames" plays 9 loops + 50.

Run: ``python benchmarks/bench_soak.py [--head mediapipe|makehuman] [--frames 1000 5000 10000]``
-> ``benchmarks/results/soak.json``. Minutes: the 16,000 frames are simulated for real.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _util import print_table, write_results  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
HEADS = {"mediapipe": ROOT / "samples" / "mediapipe" / "face_model_with_iris.obj",
         "makehuman": ROOT / "samples" / "makehuman" / "mh_head_default.obj"}


def soak_track(n_frames: int, tail: int, path: Path) -> int:
    """Write a FAP file: joy.fap looped ``max(1, n_frames // 108)`` times, then ``tail``
    neutral frames. Returns its frame count."""
    from faceforge.mpeg4 import FapTrack, read_fap, write_fap

    joy = read_fap(ROOT / "samples" / "fap" / "joy.fap")
    loops = max(1, n_frames // joy.n_frames)
    values = np.vstack([np.tile(np.nan_to_num(joy.values), (loops, 1)), np.zeros((tail, 68))])
    mask = np.ones(values.shape, bool)
    mask[:, :2] = False
    write_fap(path, FapTrack.from_given(joy.fps, mask, values, name="soak"))
    return len(values)


def run(cmd: list[str], env: dict) -> tuple[int, float, float, str]:
    """(exit status, peak RSS in MB, wall seconds, stderr) of a child process."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    err = proc.stderr.read()
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    return proc.returncode, usage.ru_maxrss / 1024.0, time.perf_counter() - t0, err


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--head", choices=sorted(HEADS), default="mediapipe")
    ap.add_argument("--frames", type=int, nargs="+", default=[1000, 5000, 10000])
    ap.add_argument("--tail", type=int, default=50, help="neutral frames at the end of each take")
    ap.add_argument("--keep", action="store_true", help="keep the work folder")
    args = ap.parse_args()
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    ff = [sys.executable, "-c", "from faceforge.cli import main; main()"]
    work = Path(tempfile.mkdtemp(prefix="soak-"))
    rows = []
    try:
        wd = work / "head"
        for stage in (["fit", str(HEADS[args.head])], ["bind"]):
            code, rss, secs, err = run(ff + ["-q", "-w", str(wd)] + stage, env)
            if code:
                raise SystemExit(f"{stage[0]} failed: {err}")
        reference = None
        for n in [1] + list(args.frames):          # 1: the one-loop reference take
            fap = work / f"soak_{n}.fap"
            total = soak_track(n, args.tail, fap)
            code, rss, secs, err = run(ff + ["-q", "-w", str(wd), "animate", "--fap", str(fap), "-o",
                                             str(work / f"take_{n}.pc2")], env)
            if code:
                raise SystemExit(f"animate of {n} frames failed: {err}")
            report = json.loads((wd / "animate" / "report.json").read_text())
            from faceforge.io.frame_stream import open_frames

            frames = open_frames(wd / "animate" / "animation.npz")   # the first and last frames only
            first, last = np.asarray(frames[0], float), np.asarray(frames[-1], float)
            del frames
            diag = float(np.linalg.norm(np.ptp(first, axis=0)))
            if reference is None:
                reference = last
            rows.append({"frames": total, "peak_rss_mb": round(rss, 1), "wall_s": round(secs, 1),
                         "ms_per_frame": round(report["per_frame_ms"]["total"], 3),
                         "non_finite": report["checks"]["non_finite"],
                         "inverted_triangles": report["checks"]["inverted_triangles"],
                         "folded_max_per_frame": report["checks"]["folded_max_per_frame"],
                         "drift_rel": float(np.linalg.norm(last - reference, axis=1).max() / diag),
                         "rest_residual_rel": float(np.linalg.norm(last - first, axis=1).max() / diag),
                         "checks_ok": report["checks"]["ok"]})
            print_table(rows[-1:], list(rows[-1]))
    finally:
        if not args.keep:
            shutil.rmtree(work, ignore_errors=True)
    rows = rows[1:] if len(rows) > 1 else rows   # the reference take is not reported
    rss = [r["peak_rss_mb"] for r in rows]
    summary = {"head": args.head, "tail_frames": args.tail, "rows": rows,
               "rss_growth_mb_per_1000_frames": (rss[-1] - rss[0]) / max(1, (rows[-1]["frames"] - rows[0]["frames"]) / 1000)
               if len(rows) > 1 else 0.0,
               "all_finite": all(r["non_finite"] == 0 for r in rows),
               "no_inverted_triangle": all(r["inverted_triangles"] == 0 for r in rows),
               "max_drift_rel": max(r["drift_rel"] for r in rows), "drift_limit": 1e-4,
               "load_average": os.getloadavg(), "cpus": os.cpu_count()}
    print_table(rows, list(rows[0]), title=f"soak on {args.head}")
    print(json.dumps({k: v for k, v in summary.items() if k != "rows"}, indent=1))
    write_results("soak", summary)


if __name__ == "__main__":
    main()
