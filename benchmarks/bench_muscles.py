"""Per-frame time of the layered musculoskeletal system (§6) at the paper's size.

Paper, Table I, "Skull + muscles": 4,297 vertices, 8,352 faces, 4,919 constraints,
6 ms per frame (C++, one core of a 2.4 GHz Core2 Duo). Here: a synthetic skull (an
icosphere cut into cranium and mandible) carrying 25 linear muscles in three layers
plus a sphincter, with the paper's stiffness values and 10 iterations. The real template
muscle map is measured by the lead later.

Run: ``python benchmarks/bench_muscles.py`` -> table + ``benchmarks/results/muscles.json``;
``--template`` measures the real template map instead (``results/muscles_template.json``)
and lists the muscles whose rest mesh has sheet faces turned over.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _util import print_table, timeit, write_results  # noqa: E402

LINEAR = dict(latitudinal_up=1.0, longitudinal_up=0.1, connection=1.0, bend=0.4, volume=1.0, position=0.2)
SPHINCTER = dict(latitudinal_up=0.2, connection=1.0, shear_up=0.3, shear_low=0.3, bend=1.0, volume=1.0,
                 position=0.2)


def skull(subdivisions=4, cut_y=-0.3):
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=subdivisions)
    v, f = np.asarray(m.vertices), np.asarray(m.faces, np.int64)
    upper = v[f].mean(axis=1)[:, 1] > cut_y
    parts = []
    for mask in (upper, ~upper):
        used = np.unique(f[mask])
        remap = np.full(len(v), -1)
        remap[used] = np.arange(len(used))
        parts.append((v[used], remap[f[mask]]))
    return parts


def on_sphere(pts):
    p = np.array([[x, y, 1.0] for x, y in pts])
    return p / np.linalg.norm(p, axis=1, keepdims=True)


def scene(h=6, w=3):
    """Skull + 25 linear muscles (12 / 9 / 4 in layers 0 / 1 / 2) + a sphincter (layer 2)."""
    from faceforge.anatomy.muscles.action_line import ActionLine
    from faceforge.anatomy.layers import underlying_mesh
    from faceforge.anatomy.muscles.muscle import build_linear_muscle, build_sphincter_muscle
    from faceforge.anatomy.muscles.sphincter import align_loops

    cranium, mandible = skull()
    centres = [(x, y) for y in (0.55, 0.2, -0.55) for x in (-0.45, -0.15, 0.15, 0.45)]
    muscles, below = [], {}
    plan = [(0, centres, 0.0), (1, centres[:9], 0.04), (2, centres[:4], 0.08)]
    for layer, where, shift in plan:
        for k, (x, y) in enumerate(where):
            name = f"m{layer}_{k}"
            lies = ("skull",) if layer == 0 else ("skull", below[(layer - 1, k)])
            deeper = [m for m in muscles if m.name in lies]
            v, f = underlying_mesh(lies, cranium, mandible, deeper)
            x0, x1, y0, y1 = x - 0.06 + shift, x + 0.06 + shift, y + 0.12, y - 0.12
            o = on_sphere([(x0, y0), (x1, y0)])
            i = on_sphere([(x0, y1), (x1, y1)])

            def line(p):
                return ActionLine.from_points(p, v, f, project="outermost")

            muscles.append(build_linear_muscle(name, line(o), line(i), line([o[0], i[0]]), line([o[1], i[1]]),
                                               v, f, h, w, 0.02, LINEAR, lies_on=lies, layer=layer))
            below[(layer, k)] = name
    ang = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    inner = on_sphere(np.stack([0.15 * np.cos(ang), -0.3 + 0.07 * np.sin(ang)], 1))
    outer = on_sphere(np.stack([0.32 * np.cos(ang), -0.3 + 0.17 * np.sin(ang)], 1))
    inner, outer = align_loops(inner, outer)
    v, f = underlying_mesh(("skull",), cranium, mandible)
    muscles.append(build_sphincter_muscle("oris", ActionLine.from_points(inner, v, f, closed=True),
                                          ActionLine.from_points(outer, v, f, closed=True), v, f, 16, 3, 0.02,
                                          SPHINCTER, lies_on=("skull",), layer=2))
    return cranium, mandible, muscles


def jaw(pitch):
    c, s = np.cos(pitch), np.sin(pitch)
    T = np.eye(4)
    T[1:3, 1:3] = [[c, -s], [s, c]]
    return T


def template_scene():
    """The real template (templates/skull + templates/muscle_map.yaml) via the public loaders."""
    import yaml

    from faceforge.anatomy.muscles.build import build_muscles_on
    from faceforge.anatomy.muscles.muscle_map import load_muscle_map
    from faceforge.anatomy.skull import load_skull

    root = Path(__file__).resolve().parents[1]
    cfg = yaml.safe_load((root / "configs" / "default.yaml").read_text())["muscle"]
    stiffness = {kind: cfg[kind]["stiffness"] for kind in ("linear", "sphincter")}
    skull = load_skull(root / "templates" / "skull")
    specs = load_muscle_map(root / "templates" / "muscle_map.yaml", skull)
    return skull.cranium, skull.mandible, build_muscles_on(specs, skull.cranium, skull.mandible,
                                                           skull.diagonal, stiffness)


def main(argv=None):
    from faceforge.anatomy.layers import MusculoskeletalSystem

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--template", action="store_true",
                    help="the shipped template skull and muscle map instead of the synthetic scene")
    use_template = ap.parse_args(argv).template
    t0 = time.perf_counter()
    cranium, mandible, muscles = template_scene() if use_template else scene()
    build_s = time.perf_counter() - t0
    from faceforge.io.config import load_config
    from faceforge.pbd import SolverSettings

    settings = SolverSettings.from_config(load_config().get("solver"))   # what animate runs
    t0 = time.perf_counter()
    system = MusculoskeletalSystem.from_parts(cranium, mandible, muscles, settings)
    assemble_s = time.perf_counter() - t0
    v, f = system.world()
    n_muscle_faces = sum(len(m.faces) for m in muscles)
    size = {"scene": "template" if use_template else "synthetic",
            "vertices": int(len(v)), "faces": int(len(f)), "muscle_particles": system.particle_count(),
            "muscle_faces": n_muscle_faces, "constraints": system.constraint_count(),
            "muscles": len(muscles), "layers": len(system.layer_indices)}
    folded = system.folded_faces(rest=True)
    names = list(system.muscles)
    frame = {"k": 0}

    def animated():
        k = frame["k"] = frame["k"] + 1
        c = {n: 0.5 + 0.5 * np.sin(0.05 * k + j) for j, n in enumerate(names)}
        system.step(c, jaw(np.radians(10) * (0.5 + 0.5 * np.sin(0.03 * k))))

    def rest():
        system.step({}, None)

    def targets_only():
        for layer in system._layers:
            system._set_targets(layer, system.contraction_array({n: 0.5 for n in names}))

    def solver_only():
        for layer in system._layers:
            layer.solver.step(layer.state, layer.state, layer.control, 1 / 25)

    rows = []
    for name, fn in (("frame, animated", animated), ("frame, rest", rest),
                     ("targets (action-line sampling) only", targets_only), ("PBD solve only", solver_only)):
        wall = timeit(fn, repeat=5, number=20, warmup=5)
        cpu = timeit(fn, repeat=5, number=20, warmup=1, clock=time.process_time)
        rows.append({"what": name, "best_ms": 1e3 * wall["best"], "median_ms": 1e3 * wall["median"],
                     "cpu_best_ms": 1e3 * cpu["best"]})
    print_table([size], title="scene (paper: 4,297 vertices, 8,352 faces, 4,919 constraints)")
    print_table(rows, ["what", "best_ms", "median_ms", "cpu_best_ms"],
                title=f"per frame, {settings.iterations} iterations, colouring {settings.colouring} "
                      "(paper: 6 ms, C++, one core)")
    print(f"build muscles {build_s:.2f} s, assemble {assemble_s:.2f} s")
    print(f"muscles with sheet faces turned over at rest: {folded or 'none'}")
    out = write_results("muscles_template" if use_template else "muscles",
                        {"scene": size, "rows": rows, "build_s": build_s, "assemble_s": assemble_s,
                         "solver": {"iterations": settings.iterations, "colouring": settings.colouring},
                         "folded_at_rest": folded,
                         "paper": {"vertices": 4297, "faces": 8352, "constraints": 4919, "ms": 6}})
    print(f"-> {out}")


if __name__ == "__main__":
    main()
