"""Time of the calibrate stage (issue 25: at most 30 s on the MakeHuman sample, 2 cores).

Runs ``faceforge --workdir W calibrate --force`` in a child process per workdir (fitted and
bound), and records its wall time, its CPU time (the child's user + system), the load average
before and after, and from the stage's report the median error, the poses and frames settled
and their residuals.

Usage::

    python benchmarks/bench_calibrate.py WORKDIR [WORKDIR ...]

Writes ``benchmarks/results/calibrate.json``. A timing figure on a shared machine: read the
CPU time and the load beside the wall time.
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _util import workdir_args, write_results  # noqa: E402


def time_calibrate(workdir: Path) -> dict:
    """Run the calibrate stage once in a child process; its times, load and report figures."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    load0 = os.getloadavg()
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", "from faceforge.cli import main; main()", "-q", "--workdir",
                    str(workdir), "calibrate", "--force"], check=True, stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    report = json.loads((workdir / "calibrate" / "report.json").read_text())
    stage = json.loads((workdir / "calibrate" / "stage.json").read_text())
    s = report["summary"]["all"]
    return {"wall_seconds": round(wall, 1), "cpu_seconds": round(cpu, 1),
            "stage_seconds": round(float(stage.get("seconds", 0.0) or 0.0), 1),
            "load_before": [round(x, 2) for x in load0], "load_after": [round(x, 2) for x in os.getloadavg()],
            "median_relative_error": s["median_relative_error"], "rows": s["count"],
            "within_10_percent": s["within_10_percent"], "statics": report.get("statics"),
            "threads_env": os.environ.get("NUMBA_NUM_THREADS")}


def main(argv=None) -> None:
    dirs = workdir_args(__doc__, argv).workdirs
    results = {}
    for d in dirs:
        r = results[d.name] = time_calibrate(d)
        print(f"{d.name}: {r['wall_seconds']} s wall, {r['cpu_seconds']} s CPU (load {r['load_before'][0]} -> "
              f"{r['load_after'][0]}); median {100 * r['median_relative_error']:.1f} % over {r['rows']} rows; "
              f"statics {r['statics']}")
    write_results("calibrate", {"heads": results, "budget_seconds": 30.0})


if __name__ == "__main__":
    main()
