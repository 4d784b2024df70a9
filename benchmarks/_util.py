"""Tiny shared helpers for the benchmarks: time a callable, print a table, write JSON.

Usage::

    from _util import timeit, print_table, write_results
    t = timeit(lambda: solver.step(s, s, c, dt), repeat=5, number=20)   # seconds per call
    print_table(rows, ["name", "ms"])                                   # rows: list of dicts
    write_results("pbd", {"rows": rows})          # -> benchmarks/results/pbd.json

Benchmarks are scripts, not tests: run them with ``python benchmarks/bench_<name>.py``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"
#: the sample heads shipped in samples/, by name
SAMPLE_HEADS = {name: Path(__file__).resolve().parents[1] / "samples" / rel for name, rel in (
    ("makehuman", "makehuman/mh_head_default.obj"),
    ("ict", "ict/ict_face_headneck_neutral.obj"),
    ("mediapipe", "mediapipe/face_model_with_iris.obj"),
)}


def workdir_args(doc: str, argv=None, flags: dict[str, str] | None = None) -> argparse.Namespace:
    """Parse ``WORKDIR [WORKDIR ...] [--flag ...]`` for a benchmark that measures fitted workdirs.

    ``doc`` is the benchmark's module docstring (its first line is the ``--help`` text);
    ``flags`` maps each on/off option (``"--signed"``) to its help. Every workdir must be an
    existing directory: a mistyped path or ``--help`` is never taken for one (a benchmark
    would otherwise write an empty results file). Returns the namespace: ``.workdirs``
    (list of Path) and one boolean per flag (``--no-cli`` -> ``.no_cli``).
    """
    def existing_dir(text: str) -> Path:
        path = Path(text)
        if not path.is_dir():
            raise argparse.ArgumentTypeError(f"{text}: not a directory (a fitted workdir)")
        return path

    ap = argparse.ArgumentParser(description=doc.strip().splitlines()[0])
    ap.add_argument("workdirs", nargs="+", type=existing_dir, metavar="WORKDIR",
                    help="fitted (and bound) workdirs, e.g. made with faceforge -w W fit head.obj")
    for flag, help_text in (flags or {}).items():
        ap.add_argument(flag, action="store_true", help=help_text)
    return ap.parse_args(argv)


def timeit(fn, repeat: int = 5, number: int = 1, warmup: int = 1, clock=time.perf_counter) -> dict:
    """Time ``fn()``: ``warmup`` untimed calls, then ``repeat`` rounds of ``number`` calls.

    Returns seconds per call: ``{"best": float, "median": float, "mean": float, "runs": int}``
    (best is the least noisy on a shared machine). ``clock=time.process_time`` measures
    CPU time of this process instead of wall time: for single-threaded code on a busy
    machine it does not count the time the process waited for a core.
    """
    for _ in range(warmup):
        fn()
    per_call = []
    for _ in range(repeat):
        t0 = clock()
        for _ in range(number):
            fn()
        per_call.append((clock() - t0) / number)
    per_call.sort()
    return {"best": per_call[0], "median": per_call[len(per_call) // 2],
            "mean": sum(per_call) / len(per_call), "runs": repeat * number}


def _fmt(v) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


def print_table(rows: list[dict], columns: list[str] | None = None, title: str | None = None) -> None:
    """Print ``rows`` (dicts) as an aligned text table with the given ``columns``."""
    if not rows:
        return
    columns = columns or list(rows[0])
    cells = [[_fmt(r.get(c, "")) for c in columns] for r in rows]
    widths = [max(len(c), *(len(row[i]) for row in cells)) for i, c in enumerate(columns)]
    if title:
        print(title)
    print("  ".join(c.ljust(w) for c, w in zip(columns, widths)))
    print("  ".join("-" * w for w in widths))
    for row in cells:
        print("  ".join(v.ljust(w) for v, w in zip(row, widths)))
    print()


#: the libraries whose releases move the figures (numba's LLVM compiles the solver)
LIBRARIES = ("numpy", "scipy", "numba", "llvmlite", "trimesh", "tbb")


def _cpu() -> dict:
    """The CPU's model name, clock and widest vector extension, from /proc/cpuinfo (Linux)."""
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        return {}
    fields = dict(line.split(":", 1) for line in text.splitlines()[:40] if ":" in line)
    fields = {k.strip(): v.strip() for k, v in fields.items()}
    flags = set(fields.get("flags", "").split())
    vector = next((f for f in ("avx512f", "avx2", "avx", "sse4_2") if f in flags), None)
    return {"model": fields.get("model name"), "mhz": fields.get("cpu MHz"), "vector": vector}


def machine() -> dict:
    """A short description of where the numbers were measured: the platform, the CPU and the
    versions of the libraries that move the figures (a new numba can change them as much as
    a new machine)."""
    from importlib.metadata import PackageNotFoundError, version

    libs = {}
    for name in LIBRARIES:
        try:
            libs[name] = version(name)
        except PackageNotFoundError:
            libs[name] = None
    return {"platform": platform.platform(), "python": platform.python_version(),
            "processor": platform.processor() or platform.machine(), "cpus": os.cpu_count(),
            "cpu": _cpu(), "libraries": libs}


def write_results(name: str, data: dict) -> Path:
    """Write ``data`` plus machine info and a UTC timestamp to ``results/<name>.json``."""
    RESULTS.mkdir(parents=True, exist_ok=True)
    out = RESULTS / f"{name}.json"
    payload = {"benchmark": name, "when_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
               "machine": machine(), **data}
    out.write_text(json.dumps(payload, indent=2, sort_keys=False) + "\n")
    return out
