"""Benchmark of the PBD engine (issue 3). Run: ``python benchmarks/bench_pbd.py [--quick]``.

Measures, on one core:

1. ns per constraint-iteration for each kind (one Gauss-Seidel sweep, timed in the
   compiled step on a Mesh_D-sized skin), and for the skin's stretch + bending (+ area)
   blocks together (fused per quad when coloured);
2. ms per frame for synthetic sphere-like skins of the sizes of the paper's Table I
   with the §8 skin constraint set (stretch on every edge and across each adjacent
   triangle pair, dihedral bending per pair, area per triangle, one volume, one anchor
   stretch per vertex to a kinematic particle) at 10 iterations, 1 substep;
3. a 70 x 70 cloth (distance + dihedral bending, 10 iterations, 1 substep, two pinned
   corners, gravity) stepped by faceforge and by Jan Bender's PositionBasedDynamics
   (``pypbd``, optional) in the same run;
4. first-call compile time (fresh NUMBA_CACHE_DIR, in a subprocess) and cached load.

Writes ``benchmarks/results/pbd.json`` and prints tables. Not a test.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")  # pypbd's OpenMP loops: one core, like the paper

import argparse  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numba  # noqa: E402
import numpy as np  # noqa: E402
from scipy.spatial import ConvexHull  # noqa: E402

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))

from _util import print_table, timeit as _timeit, write_results  # noqa: E402

from faceforge.pbd import ModelBuilder, Solver, SolverSettings  # noqa: E402

DT = 1.0 / 25.0


def timeit(fn, repeat, number):
    """CPU time of this (single-threaded) process: robust on the shared 2-core machine."""
    return _timeit(fn, repeat=repeat, number=number, clock=time.process_time)
#: (name, vertices, faces, constraints) of the paper's Table I, with its ms per frame
TABLE_I = [("Mesh_A", 1466, 2822, 16461, 31.0), ("Mesh_B", 2502, 4908, 28785, 28.0),
           ("Mesh_C", 4604, 9160, 53834, 45.0), ("Mesh_D", 4904, 9541, 55687, 50.0)]


# -- meshes ------------------------------------------------------------------------------
def sphere_skin(n_vertices: int, n_faces: int, seed: int = 0):
    """An open sphere-like skin with about ``n_vertices`` vertices and exactly ``n_faces``
    faces: Fibonacci points, convex hull, the faces nearest the bottom pole removed (a
    face mask with a neck opening)."""
    total = n_vertices
    for _ in range(5):  # grow the sphere until the cut one has enough vertices
        v, f = _cut_sphere(total, n_faces, seed)
        if len(v) >= n_vertices:
            break
        total += 2 * (n_vertices - len(v))
    return v, f


def _cut_sphere(n_vertices, n_faces, seed):
    i = np.arange(n_vertices) + 0.5
    phi = np.arccos(1.0 - 2.0 * i / n_vertices)
    theta = np.pi * (1.0 + 5.0 ** 0.5) * i
    v = np.c_[np.cos(theta) * np.sin(phi), np.cos(phi), np.sin(theta) * np.sin(phi)]
    v *= 1.0 + 0.05 * np.random.default_rng(seed).standard_normal((n_vertices, 1))  # bumpy
    f = ConvexHull(v / np.linalg.norm(v, axis=1, keepdims=True)).simplices.astype(np.int64)
    c = v[f].mean(axis=1)
    normal = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    flip = (normal * c).sum(axis=1) < 0
    f[flip] = f[flip][:, ::-1]
    if n_faces < len(f):  # open holes (neck, eyes, mouth, ...) by dropping faces round them
        holes = v[np.random.default_rng(seed).choice(len(v), 8, replace=False)]
        dist = np.linalg.norm(c[:, None, :] - holes[None], axis=2)  # (f, holes)
        owner = dist.argmin(axis=1)
        drop = len(f) - n_faces
        rank = np.empty(len(f), dtype=np.int64)
        for h in range(len(holes)):  # rank faces by distance within the hole they belong to
            ids = np.flatnonzero(owner == h)
            rank[ids[np.argsort(dist[ids, h], kind="stable")]] = np.arange(len(ids))
        order = np.lexsort((owner, rank))  # nearest faces of every hole first, round robin
        f = f[np.sort(order[drop:])]
    used = np.unique(f)
    remap = np.full(len(v), -1)
    remap[used] = np.arange(len(used))
    return v[used], remap[f]


def edges_of(f):
    e = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    return np.unique(e, axis=0)


def quads_of(f):
    """(p0, p1, p2, p3) per interior edge, p0 -> p1 oriented as in the face holding p2."""
    half = {}
    for t in f.tolist():
        for i in range(3):
            half[(t[i], t[(i + 1) % 3])] = t[(i + 2) % 3]
    return np.array(sorted((a, b, c, half[(b, a)]) for (a, b), c in half.items()
                           if a < b and (b, a) in half), dtype=np.int64)


def skin_model(v, f):
    """The §8 skin constraint set with the paper's stiffness values."""
    b = ModelBuilder()
    center = v.mean(axis=0)
    anchors = b.add_particles(center + 0.85 * (v - center), 0.0)  # kinematic "skull" points q
    skin = b.add_particles(v, 1.0)
    q = quads_of(f) + skin
    b.add_distance(edges_of(f) + skin, 0.15)
    b.add_distance(q[:, 2:], 0.15)
    b.add_bending(q, 0.95)
    b.add_area(f + skin, 0.95)
    b.add_volume(f + skin, 1.0)
    n = len(v)
    b.add_distance(np.c_[np.arange(n) + skin, np.arange(n) + anchors], 0.2)
    return b.finalize()


def grid(n: int):
    xs, zs = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n), indexing="ij")
    v = np.c_[xs.ravel(), np.zeros(n * n), zs.ravel()]
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = (idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(),
                  idx[:-1, 1:].ravel())
    return v, np.concatenate([np.c_[a, b, c], np.c_[a, c, d]]).astype(np.int64)


# -- measurements ------------------------------------------------------------------------
def bench_frames(repeat):
    rows = []
    for name, nv, nf, paper_c, paper_ms in TABLE_I:
        v, f = sphere_skin(nv, nf)
        model = skin_model(v, f)
        row = {"mesh": name, "vertices": len(v), "faces": len(f),
               "constraints": model.constraint_count, "paper_constraints": paper_c}
        for colouring in (False, True):
            solver = Solver(model, SolverSettings(iterations=10, substeps=1, colouring=colouring))
            state, control = model.state(), model.control()
            rng = np.random.default_rng(1)
            free = model.inv_mass > 0
            state.positions[free] += rng.normal(scale=0.002, size=(free.sum(), 3))
            t = timeit(lambda: solver.step(state, state, control, DT), repeat=repeat, number=10)
            key = "coloured" if colouring else "builder_order"
            row[f"ms_{key}"] = t["best"] * 1e3
            row[f"ms_{key}_median"] = t["median"] * 1e3
        row["paper_ms"] = paper_ms
        rows.append(row)
    return rows


def bench_kinds(repeat):
    """ns per constraint-iteration: a model holding one kind on a Mesh_D-sized skin, stepped
    at 10 iterations, minus the step overhead (predict, velocities) of a model without
    constraints, divided by iterations x constraints."""
    v, f = sphere_skin(4904, 9541)
    e, q = edges_of(f), quads_of(f)
    rng = np.random.default_rng(2)
    x0 = v + rng.normal(scale=0.01, size=v.shape)
    rows = []
    kinds = {
        "distance": lambda b: b.add_distance(e, 0.15),
        "bending": lambda b: b.add_bending(q, 0.95),
        "area": lambda b: b.add_area(f, 0.95),
        "volume": lambda b: b.add_volume(f, 1.0),
        "position": lambda b: b.add_position(np.arange(len(v)), 0.2),
        "attachment": None,
        # the skin's stretch block then bending block: fused per quad when coloured
        "stretch+bending": lambda b: (b.add_distance(e, 0.15), b.add_distance(q[:, 2:], 0.15),
                                      b.add_bending(q, 0.95)),
        # ... then the area block: coloured, each quad also projects one triangle's area
        "stretch+bending+area": lambda b: (b.add_distance(e, 0.15),
                                           b.add_distance(q[:, 2:], 0.15),
                                           b.add_bending(q, 0.95), b.add_area(f, 0.95)),
    }
    iters = 10
    base = ModelBuilder()
    base.add_particles(v, 1.0)
    bm = base.finalize()
    bs = Solver(bm, SolverSettings(iterations=iters))
    st0 = bm.state()
    overhead = timeit(lambda: bs.step(st0, st0, bm.control(), DT), repeat=repeat, number=20)["best"]
    for kind, add in kinds.items():
        b = ModelBuilder()
        b.add_particles(x0, 1.0)
        if kind == "attachment":  # pulled to the face centres of a kinematic deeper copy
            deep = b.add_particles(v * 0.9, 0.0)
            b.add_attachment(f[:, 0], f + deep, np.full((len(f), 3), 1.0 / 3.0), 0.5)
        else:
            add(b)
        model = b.finalize()
        m = model.constraint_count
        row = {"kind": kind, "constraints": m}
        for colouring in (False, True):
            solver = Solver(model, SolverSettings(iterations=iters, colouring=colouring))
            state, control = model.state(), model.control()
            state.positions[: len(v)] = x0
            t = timeit(lambda: solver.step(state, state, control, DT), repeat=repeat, number=20)
            key = "ns_coloured" if colouring else "ns_builder_order"
            row[key] = (t["best"] - overhead) / (iters * m) * 1e9
        row["note"] = {
            "volume": "per body (9,541 triangles)",
            "bending": "vectorised batches when coloured",
            "area": "vectorised batches when coloured",
            "distance": "PBD sweep with precomputed weight shares",
            "stretch+bending": "per constraint; coloured: fused per quad (2 stretches + "
                               "bending), vectorised",
            "stretch+bending+area": "per constraint; coloured: fused per quad (2 stretches "
                                    "+ bending + the area of one of its triangles)",
        }.get(kind, "")
        rows.append(row)
    return rows


def bench_cloth(repeat, steps=100, n=70):
    v, f = grid(n)
    e, q = edges_of(f), quads_of(f)
    pinned = [0, (n - 1) * n]
    out = {"grid": f"{n}x{n}", "vertices": len(v), "distance": len(e), "bending": len(q),
           "iterations": 10, "substeps": 1, "steps": steps, "dt": 0.005}
    # faceforge
    w = np.ones(len(v))
    w[pinned] = 0.0
    b = ModelBuilder()
    b.add_particles(v, w)
    b.add_distance(e, 1.0)
    b.add_bending(q, 0.5)
    model = b.finalize()
    for colouring in (False, True):
        solver = Solver(model, SolverSettings(iterations=10, substeps=1, damping=0.0,
                                              gravity=9.81, colouring=colouring))

        def run_ff():
            state, control = model.state(), model.control()
            for _ in range(steps):
                solver.step(state, state, control, out["dt"])
            return state

        key = "faceforge_coloured" if colouring else "faceforge"
        out[f"{key}_ms_per_step"] = timeit(run_ff, repeat=repeat, number=1)["best"] / steps * 1e3
        out[f"{key}_sag"] = float(-run_ff().positions[:, 1].min())
    try:
        import pypbd  # optional, benchmark only
    except ImportError as exc:  # pragma: no cover
        out["pypbd"] = f"not available: {exc}"
        return out

    def build_pbd():
        sim = pypbd.Simulation.getCurrent()
        sim.initDefault()
        pm = sim.getModel()
        pm.cleanup()
        tm = pm.addTriangleModel(list(v), list(f.ravel().tolist()))
        off = tm.getIndexOffset()
        for i, j in e.tolist():
            pm.addDistanceConstraint(i + off, j + off, 1.0)
        for e0, e1, o2, o3 in q.tolist():  # Bender: (opposite, opposite, edge, edge)
            pm.addDihedralConstraint(o2 + off, o3 + off, e0 + off, e1 + off, 0.5)
        pd = pm.getParticles()
        for i in pinned:
            pd.setMass(i + off, 0.0)
        pm.initConstraintGroups()
        ts = sim.getTimeStep()
        ts.setValueUInt(pypbd.TimeStepController.NUM_SUB_STEPS, 1)
        ts.setValueUInt(pypbd.TimeStepController.MAX_ITERATIONS, 10)
        ts.setValueUInt(pypbd.TimeStepController.MAX_ITERATIONS_V, 0)
        pypbd.TimeManager.getCurrent().setTimeStepSize(out["dt"])
        return sim, pm, ts

    sim, pm, ts = build_pbd()

    def run_pbd():
        pm.reset()
        for _ in range(steps):
            ts.step(pm)

    t_pbd = timeit(run_pbd, repeat=repeat, number=1)["best"]
    run_pbd()  # leave the final state of one full run for the sag
    pd = pm.getParticles()
    out["pypbd_ms_per_step"] = t_pbd / steps * 1e3
    out["pypbd_sag"] = float(-min(np.ravel(pd.getPosition(i))[1] for i in range(len(v))))
    out["pypbd_constraints"] = len(pm.getConstraints())
    out["pypbd_constraint_groups"] = len(pm.getConstraintGroups())
    out["speedup_faceforge_over_pypbd"] = out["pypbd_ms_per_step"] / out["faceforge_ms_per_step"]
    out["speedup_faceforge_coloured_over_pypbd"] = (out["pypbd_ms_per_step"]
                                                    / out["faceforge_coloured_ms_per_step"])
    out["pypbd_step_extras"] = (
        "Same mesh, constraint kinds (PBD distance k=1, dihedral k=0.5), 10 iterations, 1 "
        "substep, gravity, no damping, 100 steps; both end at the same sag. pypbd's "
        "TimeStepController::step (read from its source) additionally: clears accelerations "
        "and re-applies gravity per particle, keeps last/old positions, loops over (empty) "
        "rigid bodies/orientations, calls initConstraintBeforeProjection on every constraint "
        "each step, projects through two virtual calls per constraint (updateConstraint + "
        "solvePositionConstraint) in its own colour groups (OpenMP, 1 thread here), calls "
        "updateConstraint once more per constraint before the (0) velocity iterations, scans "
        "all constraints for motor joints and advances the TimeManager. faceforge's step "
        "additionally applies velocity damping (0 here) and writes kinematic particles.")
    return out


@numba.njit(cache=False)
def _touch(x, idx, eps, runs):
    """Read and write back every particle of every row of ``idx`` (runs times), no math."""
    for _ in range(runs):
        for j in range(idx.shape[0]):
            for t in range(idx.shape[1]):
                i = idx[j, t]
                x[i, 0] = x[i, 0] + eps
                x[i, 1] = x[i, 1] + eps
                x[i, 2] = x[i, 2] + eps


def bench_floor(repeat):
    """The memory-traffic floor of a Mesh_D frame: 10 sweeps that only load and store the
    particles of every projection of the coloured, fused skin solver (anchors, leftover
    stretches, quads (with their fused stretches and areas), leftover triangles, the
    volume's triangles and particles), in its order."""
    v, f = sphere_skin(4904, 9541)
    model = skin_model(v, f)
    solver = Solver(model, SolverSettings(iterations=10, colouring=True))
    rows = {"quads": solver._arrays["bending"][0], "triangles": solver._arrays["area"][0],
            "pairs": solver._arrays["distance"][0],
            "volume triangles": model.volume_triangles,
            "volume particles": model.volume_particles[:, None]}
    x = model.rest_positions.copy()
    out = {}
    total = 0.0
    for name, idx in rows.items():
        idx = np.ascontiguousarray(idx, dtype=np.int64)
        _touch(x, idx, 0.0, 1)
        t = timeit(lambda: _touch(x, idx, 0.0, 10), repeat=repeat, number=5)["best"]
        out[f"{name}_ms"] = t * 1e3
        total += t * (2.0 if name == "volume particles" else 1.0)  # read g, update x
    out["frame_ms"] = total * 1e3
    out["note"] = ("10 iterations of loads + stores of each projection's particles, no math; "
                   "a lower bound for any Gauss-Seidel sweep over these constraints")
    return out


COMPILE_SNIPPET = """
import time, numpy as np
t0 = time.perf_counter()
from faceforge.pbd import ModelBuilder, Solver, SolverSettings
b = ModelBuilder(); b.add_particles(np.eye(3), 1.0); b.add_particles(np.ones((1, 3)), 0.0)
b.add_distance([[0, 1]], 0.5); b.add_bending([[0, 1, 2, 3]], 0.5); b.add_area([[0, 1, 2]], 0.5)
b.add_volume([[0, 1, 2]], 0.5); b.add_position([0], 0.2)
b.add_attachment([1], [[0, 2, 3]], [[0.3, 0.3, 0.4]], 0.5)
m = b.finalize(); s = m.state()
t1 = time.perf_counter()
Solver(m, SolverSettings()).step(s, s, m.control(), 0.04)
t2 = time.perf_counter()
print(t1 - t0, t2 - t1)
"""


def bench_compile():
    env = dict(os.environ, PYTHONPATH=str(HERE.parent))
    with tempfile.TemporaryDirectory() as cache:
        env["NUMBA_CACHE_DIR"] = cache
        out = {}
        for label in ("first_call", "cached"):
            r = subprocess.run([sys.executable, "-c", COMPILE_SNIPPET], env=env, check=True,
                               capture_output=True, text=True)
            imp, step = map(float, r.stdout.split())
            out[f"{label}_import_s"] = imp
            out[f"{label}_step_s"] = step
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer repeats")
    args = ap.parse_args()
    repeat = 3 if args.quick else 7
    t0 = time.perf_counter()
    compile_ = bench_compile()
    print_table([compile_], title="compile (seconds; fresh NUMBA_CACHE_DIR, then cached)")
    kinds = bench_kinds(repeat)
    print_table(kinds, ["kind", "constraints", "ns_builder_order", "ns_coloured", "note"],
                title="ns per constraint-iteration (Mesh_D-sized skin)")
    frames = bench_frames(repeat)
    print_table(frames, ["mesh", "vertices", "faces", "constraints", "paper_constraints",
                         "ms_builder_order", "ms_coloured", "ms_coloured_median", "paper_ms"],
                title="ms per frame, §8 skin set, 10 iterations, 1 substep (best of runs)")
    floor = bench_floor(repeat)
    print_table([floor], title="memory-traffic floor of the Mesh_D frame (ms; loads/stores only)")
    cloth = bench_cloth(repeat)
    keys = [k for k in cloth if k.endswith(("ms_per_step", "sag")) or k.startswith("speedup")]
    print_table([{k: cloth[k] for k in keys}], title="cloth 70x70, 10 iterations: faceforge vs pypbd")
    path = write_results("pbd", {"compile": compile_, "kinds": kinds, "frames": frames,
                                 "cloth": cloth, "floor": floor,
                                 "target_ms_mesh_d": 3.0,
                                 "wall_s": time.perf_counter() - t0})
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
