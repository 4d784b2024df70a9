"""The fit stage: skull and muscle map morphed into the user's skin (§7).

``faceforge fit skin.obj [--landmarks skin.fdp.yaml]`` writes ``<workdir>/fit/``:

fit.npz (no pickle; head space, mesh units)
    ``skin_vertices (n,3)``, ``skin_faces (m,3)``: the internal (checked, merged) skin;
    ``skin_user_to_internal (n_user,)``: internal vertex of each of the user's vertices;
    ``cranium_vertices``, ``cranium_faces``, ``mandible_vertices``, ``mandible_faces``;
    ``landmark_ids (k,) str``, ``landmark_positions (k,3)``: fitted bone landmarks;
    ``skin_landmark_ids (s,) str``, ``skin_landmark_positions (s,3)``: snapped skin landmarks;
    ``target_ids``, ``target_positions``: the bone-landmark targets (tissue depth, refit);
    ``jaw_<axis>_point (3,)``, ``jaw_<axis>_direction (3,)`` for each template jaw axis;
    ``muscle_names (q,) str``, ``muscle_vertices (sum,3)``, ``muscle_vertex_start (q+1,)``,
    ``muscle_faces (sum,3)`` (muscle-local ids), ``muscle_face_start (q+1,)``, ``muscle_thickness (q,)``;
    ``muscle_map_names (r,)``, ``muscle_map_points (sum,3)``, ``muscle_map_start (r+1,)``:
    every point of the morphed muscle map; ``similarity (4,4)``: the initial alignment;
    ``user_rotation (3,3)``: ``R`` of :func:`faceforge.geometry.orientation.frame_rotation`,
    head space = the user's coordinates ``@ R.T`` (identity for a +Y-up head facing +Z).

Head space is faceforge's frame (+Y up, face along +Z, subject's left +X). A head in
another frame is turned into it first (``fit.orientation``: ``auto`` takes the landmark
file's ``orientation: {up, forward}`` or, without one, the frame its landmarks span,
snapped to the nearest axes; or ``UP,FORWARD`` such as ``+Z,-Y``); ``animate`` turns the
frames back, so the outputs are in the user's own frame.
muscle_map.yaml
    the muscle map in head space (same format as templates/muscle_map.yaml; every muscle
    written out, mirrors included), loadable with the fitted skull.
report.json
    mesh check, landmark residuals (fraction of the skin diagonal), inside fractions of
    front skull and muscle vertices, tissue thickness, muscles poking through, timings.
fit.png
    skull and muscles inside the translucent skin, front and side (Fig. 8b).
"""

from __future__ import annotations

from pathlib import Path

import click

from faceforge.pipeline import Stage, register_command, register_stage

VERSION = "6"


def _check_orientation(value, base):
    """``fit.orientation``: ``auto`` or ``UP,FORWARD`` (two signed axes, e.g. ``+Z,-Y``)."""
    axes = {"+x", "-x", "+y", "-y", "+z", "-z", "x", "y", "z"}
    words = [w.strip().lower() for w in value.split(",")] if isinstance(value, str) else []
    if value == "auto" or (len(words) == 2 and set(words) <= axes and words[0][-1] != words[1][-1]):
        return value
    raise ValueError("auto, or the mesh's up and forward axes as UP,FORWARD (e.g. +Z,-Y)")


def _register_rules() -> None:
    from faceforge.io.config import Rule, add_rule

    class Orientation(Rule):
        def check(self, value, base):
            return _check_orientation(value, base)

    add_rule("fit.orientation", Orientation())


_register_rules()


def run(ctx) -> None:
    """Stage body: read mesh + landmarks + template, fit, write fit.npz, report.json, fit.png."""
    import time

    from faceforge.io.landmarks import default_landmark_path

    t0 = time.perf_counter()
    mesh_path = ctx.param("mesh")
    lm_path = ctx.params.get("landmarks") or str(default_landmark_path(mesh_path))
    template = load_template(ctx.config.get("template.skull"), ctx.config.get("template.muscle_map"))
    result, report, extra = fit_files(mesh_path, lm_path, template, dict(ctx.config.get("fit") or {}),
                                      log=ctx.log)
    report["timings"]["stage_total_s"] = time.perf_counter() - t0
    write_outputs(ctx.out_dir, result, report, extra)
    m = report["muscles"]
    ctx.log(f"landmark residual max {report['landmarks']['max_residual']:.2%} of the diagonal, "
            f"skull inside {report['skull']['inside_fraction']:.1%}, muscles inside "
            + (f"{m['inside_fraction']:.1%}" if m["count"] else "n/a"))
    from faceforge.pipeline.fit_checks import enforce_checks

    enforce_checks(report, bool(ctx.config.get("fit.allow_failed_checks", False)), mesh_path, ctx.log)


class Template:
    """The template skull and muscle map, with the muscles built on the template skull.

    skull : :class:`faceforge.anatomy.skull.Skull`; specs : [MuscleSpec]; muscles :
    [(name, rest positions (2hw, 3), faces, hw, thickness fraction)]; layers : {name: layer}.
    """

    def __init__(self, skull, specs, muscles):
        from faceforge.anatomy.fit import FitTemplate
        from faceforge.anatomy.fit_mouth import point_weights, sheet_weights

        self.skull, self.specs, self.muscles = skull, specs, muscles
        self.layers = {s.name: s.layer for s in specs}
        jaw = skull.jaw
        self.fit_template = FitTemplate(
            skull.cranium, skull.mandible, skull.landmarks,
            {"pitch": (jaw.pitch_point, jaw.pitch_dir), "yaw": (jaw.yaw_point, jaw.yaw_dir),
             "protrusion": (jaw.pitch_point, jaw.protrusion_dir)},
            {s.name: s.points() for s in specs}, {s.name: point_weights(s) for s in specs})
        self.sheet_weights = {s.name: sheet_weights(s.type, s.h, s.w) for s in specs}

    def build_muscles(self, cranium, mandible, warp, shift=None):
        """The template muscles carried by ``warp``, then ``shift`` (the mouth's, weighted per
        particle), with Eq. 5 thickness (fitted skull diagonal)."""
        import numpy as np

        from faceforge.anatomy.fit_muscles import morph_muscle_meshes

        v = np.vstack([cranium[0], mandible[0]])
        return morph_muscle_meshes(self.muscles, warp, float(np.linalg.norm(np.ptp(v, axis=0))),
                                   shift, self.sheet_weights)


_TEMPLATES: dict = {}
#: bump when the way template muscles are built changes (invalidates the disk cache)
TEMPLATE_CACHE_VERSION = "2"


def template_cache_dir() -> Path:
    """``$FACEFORGE_CACHE`` or ``$XDG_CACHE_HOME/faceforge`` (default ``~/.cache/faceforge``)."""
    import os

    if os.environ.get("FACEFORGE_CACHE"):
        return Path(os.environ["FACEFORGE_CACHE"])
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "faceforge"


def load_template(skull_dir, muscle_map) -> Template:
    """The template named by ``template.*``, with its muscles built on the template skull.

    Building the 30 muscles takes seconds, so they are kept per process and on disk
    (:func:`template_cache_dir`, an npz named by the SHA-256 of the template files, the
    muscle-building source files and :data:`TEMPLATE_CACHE_VERSION`); a changed template
    file or muscle-model edit gives a new key.
    """
    import hashlib

    from faceforge.anatomy.muscle_map import load_muscle_map
    from faceforge.anatomy.skull import load_skull

    skull_dir, muscle_map = _resolve(skull_dir), _resolve(muscle_map)
    digest = hashlib.sha256(TEMPLATE_CACHE_VERSION.encode())
    for path in sorted(Path(skull_dir).glob("*")) + [Path(muscle_map)] + _muscle_code_files():
        if path.is_file():
            digest.update(path.name.encode() + path.read_bytes())
    key = digest.hexdigest()[:24]
    if key not in _TEMPLATES:
        skull = load_skull(skull_dir)
        specs = load_muscle_map(muscle_map, skull)
        _TEMPLATES.clear()
        _TEMPLATES[key] = Template(skull, specs, _template_muscles(key, specs, skull))
    return _TEMPLATES[key]


def _muscle_code_files() -> list[Path]:
    """Source files whose code decides the built muscles: they enter the cache key, so an
    edit to the muscle model can never be masked by muscles cached by older code."""
    import faceforge.anatomy.action_line as a
    import faceforge.anatomy.fit_muscles as b
    import faceforge.anatomy.hexmesh as c
    import faceforge.anatomy.muscle as d
    import faceforge.anatomy.muscle_map as e
    import faceforge.geometry.rbf as f
    import faceforge.geometry.surface_points as g

    return [Path(m.__file__) for m in (a, b, c, d, e, f, g)]


def _template_muscles(key: str, specs, skull) -> list:
    """[(name, rest, faces, hw, fraction)] from the disk cache, or built and cached."""
    import numpy as np

    from faceforge.anatomy.fit_muscles import build_muscles_on
    from faceforge.exceptions import StageError
    from faceforge.io.stagefiles import load_npz, save_npz

    path = template_cache_dir() / f"template-muscles-{key}.npz"
    if path.exists():
        try:
            d = load_npz(path)
            vs, fs = d["vertex_start"], d["face_start"]
            return [(str(n), d["vertices"][vs[i]:vs[i + 1]], d["faces"][fs[i]:fs[i + 1]], int(d["hw"][i]),
                     float(d["fraction"][i])) for i, n in enumerate(d["names"])]
        except (StageError, KeyError, ValueError):
            pass  # a damaged cache file is rebuilt
    fraction = {s.name: s.thickness for s in specs}
    built = [(m.name, m.rest_positions, m.faces, m.topology.h * m.topology.w, fraction[m.name])
             for m in build_muscles_on(specs, skull.cranium, skull.mandible, skull.diagonal)]
    try:
        save_npz(path, names=np.array([b[0] for b in built], dtype=str),
                 vertices=np.vstack([b[1] for b in built]), faces=np.vstack([b[2] for b in built]),
                 vertex_start=np.cumsum([0] + [len(b[1]) for b in built]),
                 face_start=np.cumsum([0] + [len(b[2]) for b in built]),
                 hw=np.array([b[3] for b in built]), fraction=np.array([b[4] for b in built]))
    except OSError:
        pass  # a read-only cache only costs time
    return built


def _resolve(path) -> Path:
    """A template path as given, or relative to the package's repository root."""
    p = Path(path)
    if p.exists() or p.is_absolute():
        return p
    root = Path(__file__).resolve().parents[3]
    return root / p if (root / p).exists() else p


def fit_files(mesh_path, lm_path, template: Template, fit_config: dict, log=lambda m: None):
    """Load and check the skin and its landmarks, fit ``template``.

    Returns ``(FitResult, report dict, extra)``; ``extra`` holds the checked mesh and the
    landmarks for :func:`write_outputs`.
    """
    import time

    from faceforge.anatomy.fit import FitSettings, SkinSurface, fit_head, orient_outward
    from faceforge.anatomy.fit_report import build_report
    from faceforge.io.landmarks import load_landmarks, read_landmarks
    from faceforge.io.mesh import load_mesh
    from faceforge.io.mesh_check import check_mesh

    t = time.perf_counter()
    v, f, _ = load_mesh(mesh_path)
    checked = check_mesh(v, f, str(mesh_path))
    raw = read_landmarks(lm_path)
    orientation = head_orientation(fit_config.get("orientation", "auto"), raw, v)
    if not orientation.identity:   # exact (a signed permutation): same head space bits as an upright mesh
        checked.vertices = checked.vertices @ orientation.rotation.T
        log(f"{mesh_path}: {orientation.describe()}")
    checked.faces = orient_outward(checked.vertices, checked.faces)   # stage files: outward winding
    for w in checked.report.warnings:
        log(f"{mesh_path}: {w}")
    lm = load_landmarks(lm_path, checked.vertices, checked.faces, user_to_internal=checked.user_to_internal,
                        rotation=None if orientation.identity else orientation.rotation, raw=raw)
    # animate measures the FAP units on these landmarks (pupils, eyelids, nose, mouth): a file
    # without them must fail here, not after fit and bind ran (issue 28)
    from faceforge.mpeg4 import fapu_from_landmarks

    fapu_from_landmarks(dict(zip(lm.ids, lm.positions)), lm_path)
    t_load = time.perf_counter() - t
    t = time.perf_counter()
    settings = FitSettings.from_config(fit_config)
    skin = SkinSurface.build(checked.vertices, checked.faces)
    try:
        result = fit_head(template.fit_template, skin, lm.ids, lm.positions, settings, template.build_muscles)
    except ValueError as exc:   # too few usable landmark pairs, degenerate configuration
        from faceforge.exceptions import LandmarkError

        raise LandmarkError(f"cannot fit the template: {exc}", lm_path) from None
    t_fit = time.perf_counter() - t
    t = time.perf_counter()
    mesh_report = {"path": str(mesh_path), **checked.report.as_dict()}
    report = build_report(result, skin, lm, mesh_report, settings.front_offset_es0)
    report["settings"] = dict(settings.__dict__)
    report["orientation"] = orientation.as_dict()
    report["timings"] = {"load_s": t_load, "fit_s": t_fit, "report_s": time.perf_counter() - t}
    return result, report, {"checked": checked, "landmarks": lm, "skin": skin, "template": template,
                            "orientation": orientation}


class HeadOrientation:
    """How the user's mesh is turned into head space (see the module docstring).

    rotation : (3, 3) float, head space = user coordinates ``@ rotation.T``
    up, forward : the mesh's own axes, as names (``"+Z"``)
    source : "config" (``fit.orientation``), "landmark file" (its ``orientation``),
        "landmarks" (the frame they span, snapped to the axes) or "default" (too few
        landmarks to tell: faceforge's own frame)
    tilt_deg : largest angle between the landmarks' own up and forward and those used,
        degrees (NaN when the landmarks do not span a frame)
    """

    def __init__(self, rotation, up: str, forward: str, source: str, tilt_deg: float):
        self.rotation, self.up, self.forward, self.source, self.tilt_deg = rotation, up, forward, source, tilt_deg

    @property
    def identity(self) -> bool:
        import numpy as np

        return bool(np.array_equal(self.rotation, np.eye(3)))

    def describe(self) -> str:
        return (f"the head is {self.up} up and faces {self.forward} (from the {self.source}); it is fitted "
                f"and simulated turned to +Y up, facing +Z, and the animation is written back in its own frame")

    def as_dict(self) -> dict:
        return {"up": self.up, "forward": self.forward, "source": self.source,
                "landmark_tilt_deg": None if self.tilt_deg != self.tilt_deg else round(float(self.tilt_deg), 3),
                "rotation": self.rotation.tolist()}


def user_rotation(fit_dir):
    """``user_rotation (3, 3)`` of a fit stage folder's fit.npz (identity for fits made
    before faceforge turned heads): head space = the user's frame ``@ R.T``."""
    import numpy as np

    from faceforge.io.stagefiles import load_npz

    fit = load_npz(Path(fit_dir) / "fit.npz")
    return np.asarray(fit["user_rotation"], dtype=float) if "user_rotation" in fit else np.eye(3)


#: the landmarks' own up may differ from the declared or snapped one by at most this (degrees)
MAX_ORIENTATION_TILT_DEG = 50.0


def head_orientation(setting: str, raw, vertices) -> HeadOrientation:
    """The orientation of a head (``fit.orientation``; see the module docstring).

    ``raw``: :class:`faceforge.io.landmarks.RawLandmarks` read from the file;
    ``vertices (n, 3)``: the user's mesh (the file's vertex ids refer to it). Raises
    LandmarkError when the frame cannot be told, or when the given one contradicts the
    landmarks by more than :data:`MAX_ORIENTATION_TILT_DEG`.
    """
    import numpy as np

    from faceforge.exceptions import LandmarkError
    from faceforge.geometry.orientation import (angle_between, axis_name, frame_rotation, parse_axis,
                                                snap_to_axes)
    from faceforge.io.landmarks import landmark_frame

    if setting != "auto":
        try:
            _check_orientation(setting, None)
            up, forward = (parse_axis(w) for w in setting.split(","))
        except ValueError as exc:
            from faceforge.exceptions import ConfigError

            raise ConfigError(f"fit.orientation: expected {exc}, got {setting!r}") from None
        source = "config"
    elif raw.orientation is not None:
        (up, forward), source = raw.orientation, "landmark file"
    else:
        up = forward = None
        source = "landmarks"
    try:
        est_up, est_forward = landmark_frame(raw, vertices)
    except LandmarkError:
        if up is None:   # too few landmarks to tell: faceforge's frame, and the landmark checks say what is missing
            up, forward, source = np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0]), "default"
        return HeadOrientation(frame_rotation(up, forward), axis_name(up), axis_name(forward), source, float("nan"))
    if up is None:
        try:
            up, forward = snap_to_axes(est_up, est_forward)
        except ValueError as exc:
            raise LandmarkError(f"{exc} (fit.orientation=UP,FORWARD, or orientation: {{up, forward}} "
                                "in the landmark file)", raw.path) from None
    tilt = max(angle_between(up, est_up), angle_between(forward, est_forward))
    if tilt > MAX_ORIENTATION_TILT_DEG:
        raise LandmarkError(f"the {source} say{'s' if source != 'landmarks' else ''} the head is "
                            f"{axis_name(up)} up facing {axis_name(forward)}, but its landmarks rise along "
                            f"{np.round(est_up, 2).tolist()} and face {np.round(est_forward, 2).tolist()} "
                            f"({tilt:.0f} degrees apart)", raw.path)
    return HeadOrientation(frame_rotation(up, forward), axis_name(up), axis_name(forward), source, tilt)


def write_outputs(out_dir, result, report, extra) -> None:
    """fit.npz, report.json and fit.png into ``out_dir``."""
    from faceforge.anatomy.fit_report import npz_arrays, save_fit_png
    from faceforge.io.stagefiles import save_json, save_npz

    checked, lm = extra["checked"], extra["landmarks"]
    out_dir = Path(out_dir)
    save_npz(out_dir / "fit.npz", user_rotation=extra["orientation"].rotation,
             **npz_arrays(result, checked.vertices, checked.faces, checked.user_to_internal, lm,
                          extra["template"].layers))
    save_json(out_dir / "report.json", report)
    from faceforge.anatomy.fit_muscles import fitted_muscle_map
    from faceforge.io.stagefiles import save_yaml

    save_yaml(out_dir / "muscle_map.yaml",
              fitted_muscle_map(extra["template"].specs, result.muscle_points),
              header="the template muscle map carried into this head by the fit (points in head units);\n"
                     "load with faceforge.anatomy.muscle_map.load_muscle_map(path, fitted skull)")
    layers = [("cranium", result.cranium, result.cranium_faces, (0.93, 0.91, 0.84)),
              ("mandible", result.mandible, result.mandible_faces, (0.88, 0.86, 0.78))]
    layers += [(n, v, f, (0.78, 0.25, 0.22)) for n, v, f in result.muscles]
    import numpy as np

    targets = np.vstack([result.targets, result.enhancement_targets])
    save_fit_png(out_dir / "fit.png", checked.vertices, checked.faces, layers, points=targets,
                 title=f"fit: {Path(report['mesh']['path']).name} ({len(result.targets)} landmark and "
                       f"{len(result.enhancement_targets)} enhancement targets)")


STAGE = register_stage(Stage(
    name="fit", deps=(), config_keys=("fit", "template"),
    inputs=("mesh", "landmarks?", "template.skull", "template.muscle_map"),
    outputs=("fit.npz", "report.json", "fit.png", "muscle_map.yaml"), version=VERSION, run=run,
    description="fit the skull and muscle map into the skin (§7)"))


@click.command("fit", help="Fit the template skull and muscle map into a skin mesh (§7).")
@click.argument("mesh", type=click.Path(dir_okay=False))
@click.option("--landmarks", type=click.Path(dir_okay=False), default=None,
              help="FDP landmark file (.yaml, .json, .csv) [default: <mesh stem>.fdp.yaml next to the mesh].")
@click.option("--orientation", default=None, metavar="UP,FORWARD",
              help="The mesh's up and forward axes, e.g. +Z,-Y (sets fit.orientation) "
                   "[default: from the landmark file or the landmarks].")
@click.option("--force", is_flag=True, help="Rerun even if up to date.")
@click.pass_obj
def command(app, mesh, landmarks, orientation, force):
    from faceforge.io.landmarks import default_landmark_path

    if landmarks is None:
        landmarks = str(default_landmark_path(mesh))
    if orientation is not None:
        app.add_sets(f"fit.orientation={orientation}")
    statuses = app.run_stage("fit", params={"mesh": mesh, "landmarks": landmarks}, force=force)
    if any(s.ran and s.stage.name == "fit" for s in statuses):
        app.log(f"fit: wrote {app.workspace.stage_dir('fit')}")


register_command(command)
