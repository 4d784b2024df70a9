"""Byte-identity check of the pipeline's outputs across a refactor (issue 24).

Runs ``fit``, ``bind``, ``animate --fap samples/fap/joy.fap`` and ``animate --expression
surprise`` on the three sample heads (samples/makehuman, samples/ict, samples/mediapipe), each in
a temporary workdir, with the faceforge tree this script lives in, and records SHA-256 digests:

* every array of ``fit/fit.npz``, ``bind/bind.npz`` and each ``animate/animation.npz`` (name,
  dtype, shape and raw bytes: an ``.npz`` file's own bytes carry zip timestamps, so the arrays
  are digested, not the file);
* ``bind/influence.png`` byte for byte; ``fit/muscle_map.yaml`` as data (its header comment
  names the module that reads it, which a refactor may move);
* ``fit/report.json``, ``bind/report.json`` and ``animate/report.json`` with the volatile entries
  (timings, absolute paths, thread counts) removed.

``--fit-only`` runs just the fit (to add the fit's digests to a recording made before).

    python tools/same_bytes.py --record benchmarks/results/same_bytes.json
    python tools/same_bytes.py --check benchmarks/results/same_bytes.json   # exit 1 on a difference
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
HEADS = {
    "makehuman": "samples/makehuman/mh_head_default",
    "ict": "samples/ict/ict_face_headneck_neutral",
    "mediapipe": "samples/mediapipe/face_model_with_iris",
}
FAP = "samples/fap/joy.fap"
EXPRESSION = "surprise"
#: report keys whose values change from run to run (or from tree to tree) without any change in
#: the results: timings, absolute paths, the thread count
VOLATILE = ("ms", "s", "seconds", "time", "timings", "elapsed", "fap", "mapping", "threads", "path",
            "file", "mesh", "workdir", "version")


def _array_digests(path: Path) -> dict:
    import numpy as np

    out = {}
    with np.load(path, allow_pickle=False) as data:
        for name in sorted(data.files):
            a = np.ascontiguousarray(data[name])
            h = hashlib.sha256(f"{a.dtype.str}{a.shape}".encode())
            h.update(a.tobytes())
            out[name] = h.hexdigest()
    return out


def _volatile(key: str) -> bool:
    k = key.lower()
    return any(k == v or k.endswith("_" + v) or k.startswith(v + "_") for v in VOLATILE)


def _strip(value):
    if isinstance(value, dict):
        return {k: _strip(v) for k, v in value.items() if not _volatile(k)}
    if isinstance(value, list):
        return [_strip(v) for v in value]
    return value


def _json_digest(path: Path) -> str:
    data = _strip(json.loads(path.read_text(encoding="utf-8")))
    return hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()


def _yaml_digest(path: Path) -> str:
    import yaml

    data = yaml.safe_load(path.read_text(encoding="utf-8"))
    return hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()


def _file_digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _cli(workdir: Path, *args: str) -> None:
    env = dict(os.environ, PYTHONPATH=str(ROOT), NUMBA_NUM_THREADS="1")
    cmd = [sys.executable, "-c", "from faceforge.cli import main; main()",
           "-q", "--no-progress", "-w", str(workdir), *args]
    done = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(args)} failed in {workdir}:\n{done.stderr}")


def run_head(name: str, stem: str, fit_only: bool = False) -> dict:
    """Digests of one sample head's fit, bind and two animations (see module doc)."""
    with tempfile.TemporaryDirectory(prefix=f"same_bytes_{name}_") as tmp:
        work = Path(tmp)
        mesh = ROOT / f"{stem}.obj"
        _cli(work, "fit", str(mesh), "--landmarks", str(ROOT / f"{stem}.fdp.yaml"))
        out = {
            "fit/fit.npz": _array_digests(work / "fit" / "fit.npz"),
            "fit/muscle_map.yaml": _yaml_digest(work / "fit" / "muscle_map.yaml"),
            "fit/report.json": _json_digest(work / "fit" / "report.json"),
        }
        if fit_only:
            return out
        _cli(work, "bind")
        out.update({
            "bind/bind.npz": _array_digests(work / "bind" / "bind.npz"),
            "bind/influence.png": _file_digest(work / "bind" / "influence.png"),
            "bind/report.json": _json_digest(work / "bind" / "report.json"),
        })
        _cli(work, "animate", "--fap", str(ROOT / FAP))
        out["animate[joy.fap]/animation.npz"] = _array_digests(work / "animate" / "animation.npz")
        out["animate[joy.fap]/report.json"] = _json_digest(work / "animate" / "report.json")
        _cli(work, "animate", "--expression", EXPRESSION)
        key = f"animate[{EXPRESSION}]"
        out[f"{key}/animation.npz"] = _array_digests(work / "animate" / "animation.npz")
        out[f"{key}/report.json"] = _json_digest(work / "animate" / "report.json")
    return out


def record(jobs: int, fit_only: bool = False) -> dict:
    with ThreadPoolExecutor(max_workers=jobs) as pool:
        futures = {name: pool.submit(run_head, name, stem, fit_only) for name, stem in HEADS.items()}
        return {name: f.result() for name, f in futures.items()}


def _flatten(d: dict, prefix: str = "") -> dict:
    out = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out.update(_flatten(v, f"{prefix}{k}:"))
        else:
            out[f"{prefix}{k}"] = v
    return out


def compare(expected: dict, got: dict) -> list[str]:
    """Keys whose digests differ, are missing or are new."""
    a, b = _flatten(expected), _flatten(got)
    return sorted(k for k in a.keys() | b.keys() if a.get(k) != b.get(k))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument("--record", type=Path, help="write the digests to this JSON file")
    g.add_argument("--check", type=Path, help="compare against this JSON file (exit 1 if not equal)")
    p.add_argument("--jobs", type=int, default=2, help="heads run at once [2]")
    p.add_argument("--fit-only", action="store_true", help="run the fit alone; --record merges into FILE")
    args = p.parse_args(argv)
    got = record(args.jobs, args.fit_only)
    if args.record and args.fit_only and args.record.exists():
        old = json.loads(args.record.read_text(encoding="utf-8"))
        for name, digests in got.items():
            old.setdefault(name, {}).update(digests)
        got = old
    if args.record:
        args.record.write_text(json.dumps(got, indent=1, sort_keys=True) + "\n", encoding="utf-8")
        print(f"recorded {len(_flatten(got))} digests to {args.record}")
        return 0
    expected = json.loads(args.check.read_text(encoding="utf-8"))
    if args.fit_only:   # compare what was run
        expected = {name: {k: v for k, v in d.items() if k.startswith("fit/")} for name, d in expected.items()}
    diff = compare(expected, got)
    if diff:
        print(f"DIFFERENT: {len(diff)} of {len(_flatten(got))} digests")
        for k in diff:
            print("  " + k)
        return 1
    print(f"identical: {len(_flatten(got))} digests match {args.check}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
