"""How mirror-symmetric is a fitted rig? (for heads that are themselves symmetric)

Usage::

    PYTHONPATH=. python tools/probe_symmetry.py WORKDIR [WORKDIR ...]

WORKDIR holds a ``fit`` stage (``faceforge --workdir WORKDIR fit MESH``). For each head it
prints, in ES0 (the pupil distance), how far from its mirror image (x -> -x, the head's
midplane taken as x = 0) lie: the skin (each vertex to the nearest mirrored vertex: 0 for an
exactly symmetric mesh such as MakeHuman's), the fitted skull (each vertex to the mirrored
surface), each right muscle of the fit (``fit.npz``, morphed from the template; vertex by
vertex against its mirrored left twin) and of the rig the animate stage builds from the
fitted muscle map (:func:`faceforge.animation.rig.muscle_system`), and the
orbicularis oris (each particle to the nearest mirrored particle). On a symmetric head,
what is not ~0 was put there by the template or the fit. MakeHuman at 585e8da: fit.npz
zygomaticus / risorius 0.079 / 0.079 ES mean, rig-built 0.061 / 0.084, skull 0.02. With the
symmetric rig (fit.symmetric_tolerance, issue 25) fit.npz holds the rig's own muscles: twins
0.001-0.014 ES mean (0.004-0.087 at worst, where their lines lie on the bone), cranium 0.004.
The motion: ``benchmarks/bench_mirror.py``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

X = np.array([-1.0, 1.0, 1.0])


def _muscles(fit: dict) -> dict:
    """{name: (vertices (k, 3))} of the muscles stored in fit.npz."""
    names, start, v = fit["muscle_names"], fit["muscle_vertex_start"], fit["muscle_vertices"]
    return {str(n): v[start[i]:start[i + 1]] for i, n in enumerate(names)}


def _rig_muscles(workdir: Path, fit: dict) -> dict:
    """{name: rest positions (k, 3)} of the muscles the animate stage builds (no solver)."""
    from faceforge.io.config import load_config
    from faceforge.animation.rig import muscle_system

    cfg = load_config()
    cranium = (fit["cranium_vertices"], fit["cranium_faces"])
    mandible = (fit["mandible_vertices"], fit["mandible_faces"])
    from faceforge.pbd.settings import SolverSettings

    system = muscle_system(fit, cranium, mandible, SolverSettings(), cfg, lambda m: None)
    return {n: system.rest_positions(n) for n in system.names}


def _pairs(muscles: dict, es0: float) -> dict:
    """{base name: (mean, max)} distance of each _R muscle to its mirrored _L twin, in ES0."""
    out = {}
    for n, r in muscles.items():
        if n.endswith("_R") and n[:-2] + "_L" in muscles and len(r) == len(muscles[n[:-2] + "_L"]):
            e = np.linalg.norm(r * X - muscles[n[:-2] + "_L"], axis=1) / es0
            out[n[:-2]] = (float(e.mean()), float(e.max()))
    return out


def probe(workdir: Path, rig: bool = True) -> dict:
    """The figures of the module docstring as a dict."""
    import trimesh
    from scipy.spatial import cKDTree

    from faceforge.anatomy import tissue as fit_tissue
    from faceforge.io.stagefiles import load_npz

    fit = load_npz(workdir / "fit" / "fit.npz")
    lm = {str(k): p for k, p in zip(fit["skin_landmark_ids"], fit["skin_landmark_positions"])}
    es0 = fit_tissue.es0(lm)
    skin = fit["skin_vertices"]
    res = {"workdir": str(workdir), "es0": es0,
           "skin": float(cKDTree(skin).query(skin * X)[0].max() / es0)}
    for part in ("cranium", "mandible"):
        mesh = trimesh.Trimesh(fit[f"{part}_vertices"], fit[f"{part}_faces"], process=False)
        d = trimesh.proximity.closest_point(mesh, fit[f"{part}_vertices"] * X)[1] / es0
        res[part] = (float(d.mean()), float(d.max()))
    muscles = _muscles(fit)
    res["fit_muscles"] = _pairs(muscles, es0)
    if "orbicularis_oris" in muscles:
        s = muscles["orbicularis_oris"]
        d = cKDTree(s).query(s * X)[0] / es0
        res["fit_orbicularis_oris"] = (float(d.mean()), float(d.max()))
    if rig:
        built = _rig_muscles(workdir, fit)
        res["rig_muscles"] = _pairs(built, es0)
        if "orbicularis_oris" in built:
            s = built["orbicularis_oris"]
            d = cKDTree(s).query(s * X)[0] / es0
            res["rig_orbicularis_oris"] = (float(d.mean()), float(d.max()))
    return res


def print_report(res: dict, out=sys.stdout) -> None:
    print(f"{res['workdir']}: ES0 {res['es0']:.4g}; distances to the mirror image in ES0 (mean / max)", file=out)
    print(f"  skin (largest vertex to nearest mirrored vertex) {res['skin']:.4f}", file=out)
    for part in ("cranium", "mandible"):
        print(f"  {part:28s} {res[part][0]:.4f} / {res[part][1]:.4f}", file=out)
    rig = res.get("rig_muscles", {})
    print(f"  {'muscle':28s} {'fit.npz':>15s} {'rig':>15s}", file=out)
    for n, (a, b) in res["fit_muscles"].items():
        r = rig.get(n)
        print(f"  {n:28s} {a:.4f} / {b:.4f}" + (f"  {r[0]:.4f} / {r[1]:.4f}" if r else ""), file=out)
    if "fit_orbicularis_oris" in res:
        r = res.get("rig_orbicularis_oris")
        a, b = res["fit_orbicularis_oris"]
        print(f"  {'orbicularis_oris (nearest)':28s} {a:.4f} / {b:.4f}" + (f"  {r[0]:.4f} / {r[1]:.4f}" if r else ""),
              file=out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("workdir", type=Path, nargs="+")
    ap.add_argument("--no-rig", action="store_true", help="skip building the animate stage's muscles")
    args = ap.parse_args(argv)
    for w in args.workdir:
        print_report(probe(w, rig=not args.no_rig))
    return 0


if __name__ == "__main__":
    sys.exit(main())
