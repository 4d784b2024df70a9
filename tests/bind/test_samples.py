"""Acceptance on the three sample heads: fit -> bind -> layered simulation.

One fitted and bound head per sample is shared by every test (session fixture):
the fit stage's functions write ``fit/fit.npz`` in a temporary workdir, the bind
stage's ``run`` writes ``bind/``, and the animate stage's :class:`BoundHead`
assembles the skull, muscles and skin exactly as ``faceforge animate`` does.

Until the fit's template loader (``faceforge.anatomy.fit_template``) is
importable, the fixture fits the skull alone with :func:`faceforge.anatomy.fit.fit_head`
on ``templates/skull`` and writes the same ``fit.npz`` keys without muscles.

The rest test runs 1,000 frames on the MediaPipe head and 50 frames with a
100 times tighter bound on the two larger heads (a fixed point does not move
at all: the drift measured is ~1e-14 of the diagonal); ``benchmarks/bench_bind.py``
runs the full 1,000 frames on all three.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
SAMPLES = {
    "makehuman": ROOT / "samples" / "makehuman" / "mh_head_default.obj",
    "ict": ROOT / "samples" / "ict" / "ict_face_headneck_neutral.obj",
    "mediapipe": ROOT / "samples" / "mediapipe" / "face_model_with_iris.obj",
}

pytestmark = pytest.mark.slow


@pytest.fixture(scope="session")
def config():
    from faceforge.io.config import load_config

    return load_config()


@pytest.fixture(scope="session")
def template(config):
    """The fit stage's template, or None when its loader has not landed (skull-only fit)."""
    try:
        import faceforge.anatomy.fit_template  # noqa: F401
    except ImportError:
        return None
    from faceforge.pipeline.stages.fit import load_template

    return load_template(config)


def _skull_only_fit(mesh, fit_dir):
    """fit.npz of a skull-only fit (no muscles) with the keys the bind and animate stages read."""
    import yaml

    from faceforge.anatomy.fit import FitSettings, FitTemplate, SkinSurface, fit_head
    from faceforge.io.landmarks import default_landmark_path, load_landmarks
    from faceforge.io.mesh import load_mesh
    from faceforge.io.mesh_check import check_mesh
    from faceforge.io.stagefiles import save_npz

    skull = ROOT / "templates" / "skull"
    bone = {k: load_mesh(skull / f"{k}.obj")[:2] for k in ("cranium", "mandible")}
    lm = yaml.safe_load((skull / "landmarks.yaml").read_text())["landmarks"]
    jaw = yaml.safe_load((skull / "jaw.yaml").read_text())
    pivot = np.asarray(jaw["pitch_axis"]["point"], float)
    axes = {"pitch": (pivot, jaw["pitch_axis"]["direction"]),
            "yaw": (jaw["yaw_axis"]["point"], jaw["yaw_axis"]["direction"]),
            "protrusion": (pivot, jaw["protrusion"]["direction"])}
    tpl = FitTemplate(bone["cranium"], bone["mandible"],
                      {k: np.asarray(x["position"], float) for k, x in lm.items()}, axes)
    v, f, _ = load_mesh(mesh)
    checked = check_mesh(v, f, str(mesh))
    marks = load_landmarks(default_landmark_path(mesh), checked.vertices, checked.faces,
                           user_to_internal=checked.user_to_internal)
    skin = SkinSurface.build(checked.vertices, checked.faces)
    r = fit_head(tpl, skin, marks.ids, marks.positions, marks.face_ids, marks.bary, FitSettings())
    arrays = dict(skin_vertices=skin.vertices, skin_faces=skin.faces,
                  skin_user_to_internal=checked.user_to_internal,
                  cranium_vertices=r.cranium, cranium_faces=bone["cranium"][1],
                  mandible_vertices=r.mandible, mandible_faces=bone["mandible"][1],
                  skin_landmark_ids=np.asarray(marks.ids), skin_landmark_positions=marks.positions)
    for name, (point, direction) in r.jaw_axes.items():
        arrays[f"jaw_{name}_point"], arrays[f"jaw_{name}_direction"] = point, direction
    save_npz(fit_dir / "fit.npz", **arrays)


_HEADS: dict = {}


@pytest.fixture(scope="session", params=sorted(SAMPLES))
def bound(request, config, template, tmp_path_factory):
    """(name, workdir, report dict, BoundHead) of one fitted + bound sample head."""
    name = request.param
    if name in _HEADS:
        return _HEADS[name]
    from faceforge.io.landmarks import default_landmark_path
    from faceforge.io.stagefiles import save_npz
    from faceforge.pipeline import StageContext
    from faceforge.pipeline.stages.animate import BoundHead
    from faceforge.pipeline.stages.bind import run

    work = tmp_path_factory.mktemp(name)
    mesh = SAMPLES[name]
    (work / "fit").mkdir()
    if template is None:
        _skull_only_fit(mesh, work / "fit")
    else:
        from faceforge.anatomy.fit_template import npz_arrays
        from faceforge.pipeline.stages.fit import fit_files

        result, _ = fit_files(str(mesh), str(default_landmark_path(mesh)), template,
                              dict(config.get("fit") or {}))
        save_npz(work / "fit" / "fit.npz", **npz_arrays(result))
    (work / "bind").mkdir()
    run(StageContext(name="bind", config=config, params={}, out_dir=work / "bind", workdir=work,
                     deps=("fit",)))
    report = json.loads((work / "bind" / "report.json").read_text())
    head = BoundHead(work / "fit", work / "bind", config)
    _HEADS[name] = (name, work, report, head)
    return _HEADS[name]


def _diag(v):
    return float(np.linalg.norm(np.ptp(v, axis=0)))


def _inside(points, vertices, faces):
    """Parity of ray crossings along two directions (inside only if both say so)."""
    from faceforge.geometry.rays import RayCaster

    rc = RayCaster(vertices, faces)
    inside = np.ones(len(points), bool)
    for d in ((0.31, 0.93, 0.17), (-0.57, 0.12, 0.81)):
        ray, _, _, t = rc.all_hits(points, np.tile(d, (len(points), 1)))
        count = np.bincount(ray[t > 0], minlength=len(points))
        inside &= count % 2 == 1
    return inside


def test_face_front_is_fully_bound(bound):
    name, _, report, _ = bound
    front = report["regions"]["face_front"]
    assert front["vertices"] > 0
    assert front["fraction"]["bound"] == 1.0, f"{name}: {front['unbound_vertices']} front vertices unbound"


def test_rest_is_a_fixed_point(bound):
    name, _, _, head = bound
    head.rig.reset()
    frames, bound_ = (1000, 1e-4) if len(head.rest) < 2000 else (50, 1e-6)
    for _ in range(frames):
        head.system.step()
        head.skin.step(head.system, 1.0 / 25.0)
    drift = np.abs(head.skin.simulated() - head.rest).max()
    assert drift < bound_ * _diag(head.rest), f"{name}: drift {drift:.3g} after {frames} frames"


@pytest.mark.xfail(strict=False, reason="fit: the MakeHuman closed eye sockets (~350 v, up to 1.2 cm deep) "
                   "and the ICT nostrils (~120 v) lie inside the fitted cranium; binding cannot move bone")
def test_no_skin_vertex_inside_the_skull_at_rest(bound):
    name, _, _, head = bound
    n = len(head.rest)
    for part in (head.cranium, head.mandible):
        inside = _inside(head.rest, *part)
        assert not inside.any(), f"{name}: {inside.sum()} of {n} skin vertices inside the bone"


def _opening_pitch(head, angle):
    """The pitch sign that lowers the chin (front of the mandible)."""
    v, _ = head.mandible
    front = v[:, 2] > np.quantile(v[:, 2], 0.9)
    t = head.skull.jaw_transform(angle, 0.0, 0.0)
    moved = v[front] @ t[:3, :3].T + t[:3, 3]
    return angle if moved[:, 1].mean() < v[front, 1].mean() else -angle


def test_opening_the_jaw_separates_the_lips(bound):
    name, _, report, head = bound
    up, lo = head.fdp_vertex["2.2"], head.fdp_vertex["2.3"]
    head.rig.reset()
    gap0 = np.linalg.norm(head.rest[up] - head.rest[lo])
    pitch = _opening_pitch(head, np.radians(12.0))
    head.system.set_jaw(head.skull.jaw_transform(pitch, 0.0, 0.0))
    for _ in range(40):
        head.system.step()
        head.skin.step(head.system, 1.0 / 25.0)
    p = head.skin.simulated()
    gap = np.linalg.norm(p[up] - p[lo])
    assert gap > gap0 + 0.01 * _diag(head.rest), f"{name}: lip gap {gap0:.4g} -> {gap:.4g} ({report['mouth']})"
    assert p[lo, 1] < head.rest[lo, 1]
    head.rig.reset()
