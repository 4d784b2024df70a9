"""The first run after an install: fit -> bind -> calibrate on a cold numba cache (issue 28).

Run: ``python benchmarks/bench_first_run.py [--head mediapipe] [--rounds 1]``

Each round runs the three commands twice in fresh processes, each time with an empty
``NUMBA_CACHE_DIR``: once as a user gets it (fit and bind compile the solver's step kernels
in a background process, :mod:`faceforge.pbd.warm`) and once with ``FACEFORGE_COMPILE_AHEAD=0``
(everything compiles at first use, as before). The order alternates between rounds. Reports
each command's wall time, the whole sequence's wall time, the CPU time of the commands (the
background process's own CPU is not in it: it is a detached grandchild), the load average
before, and the ratio with / without. Writes ``benchmarks/results/first_run.json``. On a
busy machine the wall times measure the load: compare ratios of rounds run side by side.
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from _util import SAMPLE_HEADS, print_table, write_results  # noqa: E402

ROOT = HERE.parent


def sequence(mesh: Path, ahead: bool, tmp: Path) -> dict:
    """fit, bind, calibrate in fresh processes on an empty numba cache; seconds per step."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp / "numba"), FACEFORGE_COMPILE_AHEAD="1" if ahead else "0",
               PYTHONPATH=str(ROOT))
    cli = [sys.executable, "-c", "from faceforge.cli import main; main()", "-q", "--no-progress",
           "--workdir", str(tmp / "work")]
    out = {"load_before": list(os.getloadavg())}
    cpu0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t_all = time.perf_counter()
    for name, args in (("fit", ["fit", str(mesh)]), ("bind", ["bind"]), ("calibrate", ["calibrate"])):
        t0 = time.perf_counter()
        subprocess.run(cli + args, env=env, check=True, stdout=subprocess.DEVNULL)
        out[f"{name}_s"] = round(time.perf_counter() - t0, 1)
    out["total_s"] = round(time.perf_counter() - t_all, 1)
    cpu1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    out["commands_cpu_s"] = round(cpu1.ru_utime + cpu1.ru_stime - cpu0.ru_utime - cpu0.ru_stime, 1)
    return out


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--head", default="mediapipe", choices=sorted(SAMPLE_HEADS))
    ap.add_argument("--rounds", type=int, default=1)
    args = ap.parse_args(argv)
    rows = []
    for r in range(args.rounds):
        order = (True, False) if r % 2 == 0 else (False, True)
        got = {}
        for ahead in order:
            with tempfile.TemporaryDirectory() as tmp:
                got[ahead] = sequence(SAMPLE_HEADS[args.head], ahead, Path(tmp))
        rows.append({"round": r, "with_background_compile": got[True], "without": got[False],
                     "total_ratio": round(got[True]["total_s"] / got[False]["total_s"], 3)})
    print_table([{"round": x["round"], "way": way, **x[key]} for x in rows
                 for way, key in (("background compile", "with_background_compile"), ("at first use", "without"))],
                ["round", "way", "fit_s", "bind_s", "calibrate_s", "total_s", "commands_cpu_s", "load_before"],
                title=f"first run on {args.head}, cold numba cache")
    result = {"head": args.head, "rounds": rows}
    write_results("first_run", result)
    return result


if __name__ == "__main__":
    main()
