"""Folded skin edges at the six presets' peaks and the ARKit shapes at full weight, and open_jaw's
chin path (issues 25 and 27), on the sample heads. Run::

    python benchmarks/bench_folds.py WORKDIR_MAKEHUMAN WORKDIR_ICT WORKDIR_MEDIAPIPE [--bake]

Each WORKDIR is fitted and bound (calibrated or not: the stages calibrate when they need to).
Through the CLI, as a user gets them: ``faceforge expressions`` and ``faceforge visemes`` (their reports' per-pose checks)
and, with ``--bake``, ``faceforge bake --shapes all`` (its report's per-shape checks at full weight). In process,
settled as the expressions stage settles them: where each preset's folded edges are (the nearest
FDP group: lips 2.x/8.x, lids and canthi 3.x, brows 4.x, cheeks 5.x, nose 9.x) and how many come
from the kinematic lids; the chin's (FDP 2.1) path down and back at open_jaw 713 MNS (the largest
the Xface files use) and at the request whose chin goes 713 MNS down. Writes
``benchmarks/results/folds.json``. Not a test (the counts are the checks' ``folded_edges``,
:func:`faceforge.animation.checks.folded_edges`).
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import expr_measure as em  # noqa: E402
from _util import workdir_args, write_results  # noqa: E402

PRESETS = ("joy", "sadness", "anger", "fear", "disgust", "surprise")
GROUPS = {"2": "lips", "8": "lips", "3": "lids", "4": "brows", "5": "cheeks", "9": "nose"}


def cli(workdir: Path, *args) -> float:
    """Run faceforge in ``workdir``; wall seconds."""
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", "from faceforge.cli import main; main()", "--workdir", str(workdir),
                    *args], check=True, capture_output=True, text=True)
    return round(time.perf_counter() - t0, 1)


def stage_folds(workdir: Path, stage: str, key: str) -> dict:
    """{pose: folded edges} from a stage's report.json."""
    report = json.loads((workdir / stage / "report.json").read_text())
    return {name: r["checks"]["folded_edges"] for name, r in report[key].items()
            if r.get("checks") is not None}


def where(head, faps: np.ndarray, config) -> list[dict]:
    """Per preset row of ``faps`` (k, 68): folds with and without the lids, by region."""
    from faceforge.animation.checks import folded_edges
    from faceforge.animation.controls import controls
    from faceforge.pipeline.stages.expressions import settled_poses
    from faceforge.skin.layer import skin_topology

    mapping = head._bench_mapping
    c, jaw = controls(mapping, faps, head)
    raw, _ = settled_poses(head, c, jaw, config)
    lids = head.eyelids(config)
    poses = lids.apply(raw, faps) if lids is not None else raw
    quads = skin_topology(head.faces).bending_quads
    names = sorted(head.fdp_vertex)
    fdp = head.rest[[head.fdp_vertex[n] for n in names]]
    mid = 0.5 * (head.rest[quads[:, 0]] + head.rest[quads[:, 1]])
    near = np.array([GROUPS.get(names[j].split(".")[0], "other")
                     for j in np.linalg.norm(mid[:, None] - fdp[None], axis=2).argmin(1)])
    with_lids, without = folded_edges(head.rest, poses, head.faces), folded_edges(head.rest, raw, head.faces)
    return [{"folded_edges": int(with_lids[k].sum()), "without_lids": int(without[k].sum()),
             "by_region": dict(Counter(near[with_lids[k]].tolist()))} for k in range(len(faps))]


def chin(head, mapping) -> dict:
    """open_jaw 713 MNS, and the request whose chin drops 713 MNS (two secant steps on the chin's
    drop against the request)."""
    req, rows = [713.0], em.chin_path(head, mapping, values=(713.0,))
    req.append(713.0 * 713.0 / max(rows[0]["down_mns"], 1.0))
    rows += em.chin_path(head, mapping, values=(req[1],))
    slope = (rows[1]["down_mns"] - rows[0]["down_mns"]) / (req[1] - req[0])
    if abs(slope) > 1e-6 and abs(rows[1]["down_mns"] - 713.0) > 2.0:
        rows += em.chin_path(head, mapping, values=(req[1] + (713.0 - rows[1]["down_mns"]) / slope,))
    return {"at_713": rows[0], "chin_down_713": rows[-1]}


def head_figures(workdir: Path, bake: bool) -> dict:
    """All figures of one workdir."""
    out = {"expressions_seconds": cli(workdir, "expressions", "--force")}
    out["presets"] = {n: f for n, f in stage_folds(workdir, "expressions", "expressions").items() if n in PRESETS}
    out["visemes_seconds"] = cli(workdir, "visemes", "--force")
    out["visemes"] = {n: f for n, f in stage_folds(workdir, "visemes", "visemes").items() if n != "neutral"}
    head, mapping, config = em.load_head(workdir)
    head._bench_mapping = mapping
    faps = np.array([mapping.expressions[n] for n in PRESETS], float).reshape(len(PRESETS), 68)
    out["presets_where"] = dict(zip(PRESETS, where(head, faps, config)))
    out["chin_path"] = chin(head, mapping)
    if bake:
        out["bake_seconds"] = cli(workdir, "bake", "--shapes", "all", "--force")
        folds = stage_folds(workdir, "bake", "shapes")
        out["bake_folds"] = {n: f for n, f in sorted(folds.items()) if f}
        out["bake_shapes_folding"] = len(out["bake_folds"])
    return out


def main(argv=None) -> None:
    args = workdir_args(__doc__, argv, {"--bake": "also bake every shape (bake --shapes all) and count its folds"})
    bake = args.bake
    dirs = args.workdirs
    results = {}
    for d in dirs:
        results[d.name] = r = head_figures(d, bake)
        print(d.name, "presets", r["presets"], "chin", r["chin_path"]["chin_down_713"], flush=True)
        print("   visemes folding", {n: f for n, f in r["visemes"].items() if f}, flush=True)
        if bake:
            print("   bake shapes folding", r["bake_shapes_folding"], r["bake_folds"], flush=True)
    import os

    write_results("folds", {"heads": results, "load": os.getloadavg()})


if __name__ == "__main__":
    main()
