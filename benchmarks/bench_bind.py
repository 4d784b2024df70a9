"""Benchmark of the bind stage's work (§8): ~5,000 and ~50,000 skin vertices.

Times, end to end, :func:`faceforge.skin.head.bind_head` (lip cut, ray-cast
binding, geodesic influence map, report) plus building the skin layer into a PBD
model (:func:`faceforge.skin.layer.add_skin` + ``finalize``). Targets: < 5 s for
~5k vertices (the paper), < 60 s for ~50k.

Heads: the MakeHuman sample (4,295 v) and the ICT sample subdivided once by
trimesh (~45k v), each bound to its fitted skull and 26 muscles (the fit
stage's functions, as in tests/bind/test_samples.py).

Also measured (not timed in tests): the rest drift over 1,000 frames of the
skull + skin layer on each sample head (target < 1e-4 of the diagonal).

Run: ``python benchmarks/bench_bind.py`` -> ``benchmarks/results/bind.json``.
"""

from __future__ import annotations

import json
import platform
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from faceforge.skin.head import bind_head  # noqa: E402
from faceforge.skin.layer import SkinStiffness, add_skin  # noqa: E402
from faceforge.geometry.rays import has_embree  # noqa: E402

SAMPLES = ROOT / "samples"


def fitted(mesh: Path, work: Path) -> dict:
    """Fit the sample (the fit stage's functions) and bind it; returns the fitted head arrays."""
    from faceforge.io.config import load_config
    from faceforge.io.stagefiles import load_npz
    from faceforge.pipeline.stages.bind import head_from_fit_arrays
    from tests.bind.test_samples import fit_and_bind

    fit_and_bind(mesh, work, load_config())
    return head_from_fit_arrays(load_npz(work / "fit" / "fit.npz"))


def cli_bind(mesh: Path, work: Path, repeats: int = 3) -> dict:
    """``faceforge fit MESH`` once, then ``faceforge bind --force`` in a new process each time,
    wall seconds: what a user waits
    for, cold (no in-process cache of the bodies' ray casters and projectors, which the
    in-process repeats of :func:`run_case` reuse), with loading fit.npz, the report and
    influence.png. min and median over ``repeats``."""
    import subprocess

    cmd = [sys.executable, "-m", "faceforge.cli", "-q", "-w", str(work)]
    subprocess.run([*cmd, "fit", str(mesh)], check=True, cwd=ROOT)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        subprocess.run([*cmd, "bind", "--force"], check=True, cwd=ROOT)
        times.append(time.perf_counter() - t0)
    return {"min": min(times), "median": float(np.median(times))}


def run_case(name, v, f, head, repeats=3):
    """Time bind_head + skin layer assembly of skin ``(v, f)`` against the fitted ``head``."""
    from faceforge.pbd import ModelBuilder

    times, layer_times = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        bound = bind_head(v, f, head["landmarks"], head["cranium"], head["mandible"], head["muscles"], 0.15)
        t1 = time.perf_counter()
        b = ModelBuilder()
        add_skin(b, bound.cut.vertices, bound.cut.faces, SkinStiffness(),
                 bound.binding.vertex_ids, bound.binding.points)
        b.finalize()
        t2 = time.perf_counter()
        times.append(t1 - t0)
        layer_times.append(t2 - t1)
    total = [a + b for a, b in zip(times, layer_times)]
    r = bound.report
    return {
        "head": name, "vertices": int(len(v)), "faces": int(len(f)),
        "muscles": len(head["muscles"]), "anchors": int(len(bound.binding.vertex_ids)),
        "bind_head_s": {"min": min(times), "median": float(np.median(times))},
        "skin_layer_s": {"min": min(layer_times), "median": float(np.median(layer_times))},
        "total_s": {"min": min(total), "median": float(np.median(total))},
        "face_front_bound": r["regions"]["face_front"]["fraction"]["bound"],
        "all_bound": r["regions"]["all"]["fraction"], "closest_point_anchors": r["closest_point_anchors"],
        "mouth": r["mouth"]["case"],
    }


def rest_drift(name, work: Path, frames=1000):
    """Max skin drift over ``frames`` rest frames of the whole bound head (BoundHead), / diagonal."""
    from faceforge.io.config import load_config
    from faceforge.animation.rig import BoundHead

    head = BoundHead(work / "fit", work / "bind", load_config())
    diag = float(np.linalg.norm(np.ptp(head.rest, axis=0)))
    drift = 0.0
    t0 = time.perf_counter()
    for _ in range(frames):
        head.system.step()
        head.skin.step(head.system, 1.0 / 25.0)
        drift = max(drift, float(np.abs(head.skin.simulated() - head.rest).max()))
    dt = time.perf_counter() - t0
    return {"head": name, "frames": frames, "skin_vertices": int(len(head.rest)),
            "muscles": len(head.muscle_names), "max_drift_over_diagonal": drift / diag,
            "ms_per_frame": 1e3 * dt / frames, "target": 1e-4}


def main():
    import tempfile

    import trimesh

    out = {"benchmark": "bind", "bodies": "the sample's fitted skull and muscles (faceforge fit)",
           "embree": has_embree(), "python": platform.python_version(),
           "machine": platform.machine(), "cases": [], "rest_drift": []}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        heads = {}
        for name, mesh in (("makehuman", SAMPLES / "makehuman" / "mh_head_default.obj"),
                           ("ict", SAMPLES / "ict" / "ict_face_headneck_neutral.obj"),
                           ("mediapipe", SAMPLES / "mediapipe" / "face_model_with_iris.obj")):
            (tmp / name).mkdir()
            heads[name] = fitted(mesh, tmp / name)
        mh = heads["makehuman"]
        run_case("makehuman", mh["vertices"], mh["faces"], mh, repeats=1)  # warm-up
        case = run_case("makehuman", mh["vertices"], mh["faces"], mh)
        case["target_s"] = 5.0
        case["cli_s"] = cli_bind(SAMPLES / "makehuman" / "mh_head_default.obj", tmp / "cli")
        out["cases"].append(case)
        ict = heads["ict"]
        v2, f2 = trimesh.remesh.subdivide(ict["vertices"], ict["faces"])
        case = run_case("ict subdivided once", np.asarray(v2), np.asarray(f2, np.int64), ict, repeats=2)
        case["target_s"] = 60.0
        out["cases"].append(case)
        for name in heads:
            out["rest_drift"].append(rest_drift(name, tmp / name))

    path = ROOT / "benchmarks" / "results" / "bind.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(out, indent=2) + "\n")
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
