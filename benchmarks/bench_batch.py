"""Benchmark of ``faceforge batch`` (issue 8). Run: ``python benchmarks/bench_batch.py [--heads N] [--quick]``.

Heads per minute for fit + bind + one second of animation (``--expression joy --seconds 1``,
26 frames at 25 fps) on copies of the sample MakeHuman head (4,295 vertices), three ways:

* ``one process``: ``faceforge batch --jobs 1`` (every head in the batch's own process);
* ``processes x2``: ``faceforge batch --jobs 2`` (spawned local worker processes);
* ``dask x2``: ``faceforge batch --scheduler tcp://...`` on a ``LocalCluster(n_workers=2,
  threads_per_worker=1, processes=True)`` started here (its start-up is timed apart).

Each mode runs the real command line as a subprocess into a fresh output folder (no cache
hits), so the wall time is what a user waits for, process start-up and imports included.
One untimed head first fills numba's on-disk cache. The machine's load average is recorded
before and after: on a shared machine it says how far the figures are from an idle one.
``--quick`` uses the MediaPipe head (478 vertices) instead. Writes ``benchmarks/results/batch.json``.
Not a test.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(ROOT))

from _util import print_table, write_results  # noqa: E402

HEADS = {"makehuman": ROOT / "samples" / "makehuman" / "mh_head_default.obj",
         "mediapipe": ROOT / "samples" / "mediapipe" / "face_model_with_iris.obj"}


def make_heads(folder: Path, sample: Path, n: int) -> list[Path]:
    """``n`` copies of ``sample`` (with its landmark file) named head0.obj ..."""
    folder.mkdir(parents=True, exist_ok=True)
    out = []
    for i in range(n):
        mesh = folder / f"head{i}.obj"
        shutil.copy(sample, mesh)
        shutil.copy(sample.with_name(sample.stem + ".fdp.yaml"), folder / f"head{i}.fdp.yaml")
        out.append(mesh)
    return out


def worker_cpu() -> float:
    """CPU seconds of this process (run on each Dask worker through ``Client.run``)."""
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def run_batch(heads: list[Path], out: Path, seconds: float, extra: list[str]) -> dict:
    """Run the CLI once; wall and CPU seconds (CPU of waited-for processes only), the report."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT)] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p])
    cmd = [sys.executable, "-m", "faceforge.cli", "-q", "batch", *map(str, heads), "--expression", "joy",
           "--seconds", str(seconds), "--out", str(out), *extra]
    cpu0, t0 = children_cpu(), time.perf_counter()
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True)
    wall, cpu = time.perf_counter() - t0, children_cpu() - cpu0
    if proc.returncode != 0:
        raise SystemExit(f"batch failed ({proc.returncode}): {' '.join(cmd)}\n{proc.stderr[-2000:]}")
    report = json.loads((out / "batch_report.json").read_text())
    return {"wall_s": wall, "cpu_s": cpu, "report": report}


def stage_means(report: dict) -> dict:
    """Mean seconds per stage over the heads (as each head's worker measured it)."""
    sums: dict[str, list[float]] = {}
    for r in report["results"]:
        for name, info in r["stages"].items():
            sums.setdefault(name, []).append(info["seconds"])
    return {name: sum(v) / len(v) for name, v in sums.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--heads", type=int, default=4, help="heads per mode [4]")
    parser.add_argument("--seconds", type=float, default=1.0, help="animation length per head [1]")
    parser.add_argument("--quick", action="store_true", help="the MediaPipe head instead of MakeHuman")
    parser.add_argument("--no-dask", action="store_true", help="skip the LocalCluster mode")
    args = parser.parse_args()
    sample_name = "mediapipe" if args.quick else "makehuman"
    sample = HEADS[sample_name]
    load_before = os.getloadavg()
    rows, modes = [], {}
    with tempfile.TemporaryDirectory(prefix="bench_batch_") as tmp:
        tmp = Path(tmp)
        heads = make_heads(tmp / "heads", sample, args.heads)
        t0 = time.perf_counter()
        run_batch(heads[:1], tmp / "warmup", args.seconds, ["--jobs", "1"])   # fills numba's disk cache
        warmup = time.perf_counter() - t0
        plans = [("one process", ["--jobs", "1"]), ("processes x2", ["--jobs", "2"])]
        cluster = None
        if not args.no_dask:
            from distributed import LocalCluster

            t0 = time.perf_counter()
            cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None)
            modes["dask_cluster_start_s"] = time.perf_counter() - t0
            plans.append(("dask x2", ["--scheduler", cluster.scheduler_address]))
        client = None
        if cluster is not None:
            from distributed import Client

            client = Client(cluster.scheduler_address, set_as_default=False)
        try:
            for i, (name, extra) in enumerate(plans):
                dask_cpu0 = sum(client.run(worker_cpu).values()) if name.startswith("dask") else 0.0
                res = run_batch(heads, tmp / f"out{i}", args.seconds, extra)
                if name.startswith("dask"):
                    res["cpu_s"] += sum(client.run(worker_cpu).values()) - dask_cpu0
                failed = res["report"]["failed"]
                row = {"mode": name, "heads": args.heads, "wall_s": res["wall_s"],
                       "heads_per_min": 60.0 * args.heads / res["wall_s"], "failed": failed,
                       **{f"{k}_s": v for k, v in stage_means(res["report"]).items()}}
                row["cpu_s"] = res["cpu_s"]
                row["cpu_s_per_head"] = res["cpu_s"] / args.heads
                workers = 1 if name == "one process" else min(2, os.cpu_count() or 1)
                row["cpu_bound_heads_per_min"] = 60.0 * workers / row["cpu_s_per_head"]
                rows.append(row)
                print(f"{name}: {row['heads_per_min']:.2f} heads/min", file=sys.stderr)
        finally:
            if client is not None:
                client.close()
            if cluster is not None:
                cluster.close()
    base = rows[0]["heads_per_min"]
    for row in rows:
        row["speedup"] = row["heads_per_min"] / base
    columns = ["mode", "heads", "wall_s", "heads_per_min", "speedup", "fit_s", "bind_s", "animate_s",
               "cpu_s_per_head", "cpu_bound_heads_per_min"]
    print_table(rows, columns, title=f"faceforge batch: {sample_name} head, fit + bind + {args.seconds:g} s of "
                                     f"animation (load average before {load_before[0]:.1f})")
    path = write_results("batch", {
        "head": sample_name, "vertices": sum(1 for line in sample.open() if line.startswith("v ")),
        "animation_seconds": args.seconds, "heads_per_mode": args.heads, "warmup_head_s": warmup,
        "load_average_before": load_before, "load_average_after": os.getloadavg(),
        "notes": "wall time of the CLI as a subprocess, fresh output folders; stage seconds are per head "
                 "as measured inside its worker (wall); cpu_s is the CPU time of the batch process and its "
                 "workers (Dask workers measured with Client.run): on a loaded machine it is the honest cost; "
                 "cpu_bound_heads_per_min = 60 * workers / cpu_s_per_head is what an idle machine would "
                 "give if the work were purely CPU-bound (an estimate, not a measurement)",
        **modes, "rows": rows})
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
