"""Benchmark of the bind stage's work (§8): ~5,000 and ~50,000 skin vertices.

Times, end to end, :func:`faceforge.anatomy.binding.bind_head` (lip cut, ray-cast
binding, geodesic influence map, report) plus building the skin layer into a PBD
model (:func:`faceforge.anatomy.skin.add_skin` + ``finalize``). Targets: < 5 s for
~5k vertices (the paper), < 60 s for ~50k.

Heads: the MakeHuman sample (4,295 v) and the ICT sample subdivided once by
trimesh (~45k v). Bodies: the sample's skull fitted by the fit (skull only, as
in tests/bind/test_samples.py) plus 26 *proxy* muscle sheets built from the
skin (front patches offset inward by 1-2% of the diagonal), since the fitted
muscles cannot be rebuilt yet; ``bodies`` in the JSON says so.

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

from faceforge.anatomy.binding import bind_head  # noqa: E402
from faceforge.anatomy.skin import SkinStiffness, add_skin  # noqa: E402
from faceforge.geometry.rays import has_embree  # noqa: E402
from faceforge.geometry.triangles import vertex_normals  # noqa: E402
from faceforge.io.mesh import load_mesh  # noqa: E402

SAMPLES = ROOT / "samples"


def _landmarks(path: Path) -> dict:
    import yaml

    data = yaml.safe_load(path.read_text())["landmarks"]
    return {k: np.asarray(x["position"], float) for k, x in data.items()}


def proxy_bodies(v, f, landmarks, n_muscles=26, seed=0):
    """Cranium, mandible and muscle sheets shaped from the skin (see the module text)."""
    d = float(np.linalg.norm(np.ptp(v, axis=0)))
    n = vertex_normals(v, f)
    cranium = (v - 0.03 * d * n, f)
    cen = v[f].mean(axis=1)
    chin, mouth = landmarks["2.1"][1], landmarks["8.3"][1]
    low = f[(cen[:, 1] < mouth) & (cen[:, 1] > chin - 0.02 * d)]
    mandible = (v - 0.025 * d * n, low)
    rng = np.random.default_rng(seed)
    front = np.flatnonzero(cen[:, 2] > np.quantile(cen[:, 2], 0.6))
    seeds = cen[rng.choice(front, n_muscles, replace=False)]
    owner = np.argmin(((cen[front, None, :] - seeds[None]) ** 2).sum(-1), axis=1)
    muscles = []
    for i in range(n_muscles):
        faces = f[front[owner == i]]
        used, local = np.unique(faces, return_inverse=True)
        depth = (0.01 + 0.01 * i / n_muscles) * d
        muscles.append((f"m{i}", i % 4, (v - depth * n)[used], local.reshape(-1, 3)))
    return cranium, mandible, muscles


def fitted_skull(mesh: Path):
    """Skull-only fit of a sample head (the tests' fixture path): fit.npz arrays as a dict."""
    import tempfile

    from faceforge.io.stagefiles import load_npz
    from tests.bind.test_samples import _skull_only_fit

    with tempfile.TemporaryDirectory() as tmp:
        _skull_only_fit(mesh, Path(tmp))
        return dict(load_npz(Path(tmp) / "fit.npz"))


def run_case(name, v, f, landmarks, fit, repeats=3):
    _, _, muscles = proxy_bodies(v, f, landmarks)
    cranium = (fit["cranium_vertices"], fit["cranium_faces"])
    mandible = (fit["mandible_vertices"], fit["mandible_faces"])
    times, layer_times = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        bound = bind_head(v, f, landmarks, cranium, mandible, muscles, 0.15)
        t1 = time.perf_counter()
        from faceforge.pbd import ModelBuilder

        b = ModelBuilder()
        add_skin(b, bound.cut.vertices, bound.cut.faces, SkinStiffness(),
                 bound.binding.vertex_ids, bound.binding.points)
        b.finalize()
        t2 = time.perf_counter()
        times.append(t1 - t0)
        layer_times.append(t2 - t1)
    total = [a + b for a, b in zip(times, layer_times)]
    front = bound.report["regions"]["face_front"]["fraction"]["bound"]
    return {
        "head": name, "vertices": int(len(v)), "faces": int(len(f)),
        "muscles": len(muscles), "anchors": int(len(bound.binding.vertex_ids)),
        "bind_head_s": {"min": min(times), "median": float(np.median(times))},
        "skin_layer_s": {"min": min(layer_times), "median": float(np.median(layer_times))},
        "total_s": {"min": min(total), "median": float(np.median(total))},
        "face_front_bound": front, "mouth": bound.report["mouth"]["case"],
    }


def rest_drift(name, mesh: Path, fit, frames=1000):
    """Max skin drift over ``frames`` rest frames (skull + skin layer), fraction of the diagonal."""
    from faceforge.anatomy.binding import bind_head as bind
    from faceforge.anatomy.layers import MusculoskeletalSystem
    from faceforge.anatomy.skin import SkinSimulation

    lm = {str(k): p for k, p in zip(fit["skin_landmark_ids"], fit["skin_landmark_positions"])}
    cranium = (fit["cranium_vertices"], fit["cranium_faces"])
    mandible = (fit["mandible_vertices"], fit["mandible_faces"])
    bound = bind(fit["skin_vertices"], fit["skin_faces"], lm, cranium, mandible, [], 0.15)
    system = MusculoskeletalSystem.from_parts(cranium, mandible, [])
    sim = SkinSimulation(bound.cut.vertices, bound.cut.faces, bound.binding, SkinStiffness())
    system.add_layer(sim)
    diag = float(np.linalg.norm(np.ptp(sim.rest, axis=0)))
    drift = 0.0
    t0 = time.perf_counter()
    for _ in range(frames):
        system.step()
        drift = max(drift, float(np.abs(sim.simulated() - sim.rest).max()))
    dt = time.perf_counter() - t0
    return {"head": name, "frames": frames, "skin_vertices": int(len(sim.rest)),
            "anchors": int(len(bound.binding.vertex_ids)), "max_drift_over_diagonal": drift / diag,
            "ms_per_frame": 1e3 * dt / frames, "target": 1e-4}


def main():
    import trimesh

    out = {"benchmark": "bind",
           "bodies": "skull-only fit of the sample (templates/skull) + 26 proxy muscle sheets "
                     "(skin offset inward, see bench_bind.py)",
           "embree": has_embree(), "python": platform.python_version(),
           "machine": platform.machine(), "cases": [], "rest_drift": []}
    mh = SAMPLES / "makehuman" / "mh_head_default.obj"
    fit = fitted_skull(mh)
    v, f, _ = load_mesh(mh)
    lm = _landmarks(SAMPLES / "makehuman" / "mh_head_default.fdp.yaml")
    run_case("makehuman", v, f, lm, fit, repeats=1)  # warm-up: numba compilation, imports
    case = run_case("makehuman", v, f, lm, fit)
    case["target_s"] = 5.0
    out["cases"].append(case)

    ict = SAMPLES / "ict" / "ict_face_headneck_neutral.obj"
    fit_ict = fitted_skull(ict)
    v, f, _ = load_mesh(ict)
    lm = _landmarks(SAMPLES / "ict" / "ict_face_headneck_neutral.fdp.yaml")
    v2, f2 = trimesh.remesh.subdivide(v, f)
    case = run_case("ict subdivided once", np.asarray(v2), np.asarray(f2, np.int64), lm, fit_ict, repeats=2)
    case["target_s"] = 60.0
    out["cases"].append(case)

    mp = SAMPLES / "mediapipe" / "face_model_with_iris.obj"
    for name, mesh, fitted in (("makehuman", mh, fit), ("ict", ict, fit_ict),
                               ("mediapipe", mp, fitted_skull(mp))):
        out["rest_drift"].append(rest_drift(name, mesh, fitted))

    path = ROOT / "benchmarks" / "results" / "bind.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(out, indent=2) + "\n")
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
