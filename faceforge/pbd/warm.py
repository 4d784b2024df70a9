"""The background process of :mod:`faceforge.pbd.compile_ahead`: step a small model with every
constraint kind until each step kernel a face's solvers run is compiled and cached.

``python -m faceforge.pbd.warm`` holds :func:`~faceforge.pbd.compile_ahead.lock_path`'s exclusive
lock while it compiles (a second copy exits at once); the first solver step of another process
waits on that lock (:func:`~faceforge.pbd.compile_ahead.wait`).
"""

from __future__ import annotations

import sys

from faceforge.pbd.compile_ahead import compiling_here, lock_path


def warm_model():
    """A small model with every constraint kind (distance, bending, area, volume, position,
    attachment) and kinematic particles, large enough (~20,000 constraints) that two
    partitions both hold work: a solver stepping it calls the same compiled kernels, with
    the same argument types, as the face's layers do."""
    import numpy as np
    import trimesh

    from faceforge.pbd.builder import ModelBuilder

    sphere = trimesh.creation.icosphere(subdivisions=4)
    v = np.asarray(sphere.vertices, dtype=np.float64)
    f = np.asarray(sphere.faces, dtype=np.int64)
    b = ModelBuilder()
    inner = b.add_particles(0.8 * v, 0.0)                   # kinematic
    skin = b.add_particles(v, 1.0)
    edges = np.asarray(sphere.edges_unique, dtype=np.int64)
    b.add_distance(edges + skin, 0.5)
    b.add_distance(np.stack([np.arange(len(v)) + inner, np.arange(len(v)) + skin], axis=1), 0.2)
    shared = np.asarray(sphere.face_adjacency_edges, dtype=np.int64)
    unshared = np.asarray(sphere.face_adjacency_unshared, dtype=np.int64)
    quads = np.column_stack([shared, unshared]) + skin
    b.add_bending(quads, 0.9)
    b.add_area(f + skin, 0.9)
    b.add_volume(f + skin, 1.0)
    b.add_position(np.arange(0, len(v), 7) + skin, 0.2)
    bary = np.full((len(f) // 9 + 1, 3), 1.0 / 3.0)
    b.add_attachment(np.arange(len(bary)) + skin, f[::9] + inner, bary, 0.5)
    return b.finalize()


def warm_kernels() -> None:
    """Step :func:`warm_model` on two solvers (the skin's settings: coloured; two partitions
    when threads are used, one otherwise) until each step kernel it can run has been called."""
    from faceforge.pbd.settings import SolverSettings
    from faceforge.pbd.solver import Solver
    from faceforge.pbd.threads import threaded

    model = warm_model()
    for parts in ((1, 2) if threaded() else (1,)):
        solver = Solver(model, SolverSettings(iterations=2, colouring=True, partitions=parts))
        state, control = model.state(), model.control()
        for _ in range(2):   # the first step threaded, the second on this thread (ThreadChooser)
            solver.step(state, state, control, 1.0 / 25.0)


def main() -> int:
    """Hold the lock and compile; a second copy started meanwhile exits at once."""
    import fcntl

    path = lock_path()
    with open(path, "a+b") as f:
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            return 0
        compiling_here()   # this process holds the lock: its steps must not wait for it
        warm_kernels()
    return 0


if __name__ == "__main__":
    sys.exit(main())
