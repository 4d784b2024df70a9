"""Light stand-ins for fit, bind and animate with the real stages' names, deps and inputs.

Imported as a batch plugin (``--plugin tests/batch/fake_stages.py``), in the batch process
and in every worker. They read the real inputs (the mesh through ``load_mesh``, so a
garbage OBJ fails with the real MeshError; the FAP track through ``read_fap``) and write
the files the batch reads (``report.json`` metrics, ``animation.npz`` frames), in well
under a second, so the batch machinery is tested without the minutes the real
stages take. ``FACEFORGE_FAKE_DELAY`` (seconds, default 0) makes each stage slower, for
the kill test; ``FACEFORGE_FAKE_CRASH=<mesh stem>`` makes fit SIGKILL its own process on that head;
``FACEFORGE_FAKE_FAIL_CHECKS=<mesh stem>`` makes animate's report say a check failed on that head.
"""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

from faceforge.pipeline import Stage, register_stage
from faceforge.pipeline.stage import discover


def _delay() -> None:
    time.sleep(float(os.environ.get("FACEFORGE_FAKE_DELAY", "0")))


def run_fit(ctx):
    import numpy as np

    from faceforge.io.mesh import load_mesh
    from faceforge.io.stagefiles import save_json, save_npz

    v, f, _ = load_mesh(ctx.param("mesh"))
    if os.environ.get("FACEFORGE_FAKE_CRASH") == Path(ctx.param("mesh")).stem:
        os.kill(os.getpid(), signal.SIGKILL)           # a worker dying in native code / OOM
    _delay()
    save_npz(ctx.out_dir / "fit.npz", skin_vertices=v, skin_faces=f)
    diag = float(np.linalg.norm(v.max(0) - v.min(0)))
    save_json(ctx.out_dir / "report.json", {"landmarks": {"max_residual": 0.001 * len(v) / diag},
                                             "mesh": {"vertices": len(v), "path": str(ctx.param("mesh"))},
                                             "iterations": ctx.config.get("fit.iterations", None)})


def run_bind(ctx):
    from faceforge.io.stagefiles import load_npz, save_json, save_npz

    d = load_npz(ctx.input("fit") / "fit.npz")
    _delay()
    save_npz(ctx.out_dir / "bind.npz", vertices=d["skin_vertices"])
    save_json(ctx.out_dir / "report.json", {"regions": {"face_front": {"fraction": {"bound": 1.0}}}})


def run_animate(ctx):
    import numpy as np

    from faceforge.io.stagefiles import load_npz, save_json, save_npz
    from faceforge.mpeg4 import read_fap

    track = read_fap(ctx.param("fap"))
    rest = load_npz(ctx.input("bind") / "bind.npz")["vertices"]
    _delay()
    t = np.arange(track.n_frames, dtype=np.float64)[:, None, None]
    frames = (rest[None] + 0.001 * t).astype(np.float32)
    save_npz(ctx.out_dir / "animation.npz", frames=frames, fps=np.float64(track.fps))
    bad = os.environ.get("FACEFORGE_FAKE_FAIL_CHECKS") == Path(ctx.param("mesh")).stem
    save_json(ctx.out_dir / "report.json", {"frames": int(track.n_frames), "checks": {
        "ok": not bad, "skin_inside_skull": 2 if bad else 0, "where": {"inside_skull": {"3": 2}} if bad else {}}})


discover()   # the real stages first, so these replace them for good
register_stage(Stage(name="fit", run=run_fit, config_keys=("fit",), inputs=("mesh", "landmarks?"),
                     outputs=("fit.npz", "report.json"), version="fake"), replace=True)
register_stage(Stage(name="bind", run=run_bind, deps=("fit",), outputs=("bind.npz", "report.json"),
                     version="fake"), replace=True)
register_stage(Stage(name="animate", run=run_animate, deps=("fit", "bind"), inputs=("fap", "fap_mapping"),
                     outputs=("animation.npz", "report.json"), version="fake"), replace=True)
