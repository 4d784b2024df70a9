"""The step kernels compiled ahead in a background process (faceforge.pbd.compile_ahead, .warm)."""

from __future__ import annotations

import subprocess
import sys
import time

import numpy as np

from faceforge.pbd import Solver, SolverSettings
from faceforge.pbd import compile_ahead, warm
from faceforge.pbd._kernels import _step, _step_parts
from tests.pbd.meshes import skin_builder, sphere


def test_the_warm_model_has_every_constraint_kind():
    m = warm.warm_model()
    counts = [len(m.distance_indices), len(m.bending_indices), len(m.area_indices),
              len(m.volume_rest_volume), len(m.position_indices), len(m.attachment_indices),
              len(m.kinematic_indices)]
    assert min(counts) > 0, counts


def test_a_face_like_model_steps_on_the_kernels_the_warm_up_compiled():
    """The warm model's solvers call the step kernels with the argument types a skin model
    of the §8 set gives (else the background compile would be for nothing): stepping one
    after the warm-up adds no compiled signature."""
    warm.warm_kernels()
    before = (len(_step.signatures), len(_step_parts.signatures))
    v, f = sphere(3)
    b, _ = skin_builder(v, f)
    model = b.finalize()
    for parts in (1, 2):
        solver = Solver(model, SolverSettings(iterations=2, colouring=True, partitions=parts))
        state, control = model.state(), model.control()
        for _ in range(3):
            solver.step(state, state, control, 1 / 25)
        assert np.isfinite(state.positions).all()
    assert (len(_step.signatures), len(_step_parts.signatures)) == before
    assert not compile_ahead.cold()
    assert compile_ahead.start() is None          # a warm cache: nothing is spawned


def test_wait_blocks_while_a_background_compile_holds_the_lock(monkeypatch):
    path = compile_ahead.lock_path()
    holder = subprocess.Popen([sys.executable, "-c", (
        "import fcntl, sys, time\n"
        f"f = open({str(path)!r}, 'a+b'); fcntl.flock(f, fcntl.LOCK_EX)\n"
        "print('held', flush=True); time.sleep(1.5)\n")], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        said = []
        monkeypatch.setattr(compile_ahead, "_waited", False)
        t0 = time.perf_counter()
        waited = compile_ahead.wait(said.append)
        assert time.perf_counter() - t0 >= 1.0 and waited >= 1.0
        assert said and "waiting" in said[0]
        assert compile_ahead.wait() == 0.0            # once per process
    finally:
        holder.wait(timeout=30)
    monkeypatch.setattr(compile_ahead, "_waited", False)
    assert compile_ahead.wait() < 0.5                 # nobody holds it: no wait


def test_the_background_process_does_not_wait_for_itself():
    """``python -m faceforge.pbd.warm`` holds the lock its own solver steps check: it must not
    wait on it (it did, for compile_ahead.WAIT_SECONDS, on the first version). The kernels
    are cached by the tests above, so it only loads them."""
    warm.warm_kernels()
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "faceforge.pbd.warm"], timeout=300)
    assert done.returncode == 0
    assert time.perf_counter() - t0 < 0.5 * compile_ahead.WAIT_SECONDS
