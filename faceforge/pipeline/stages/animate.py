"""The animate and calibrate stages: FAP playback on the bound head (paper §9).

``faceforge animate --fap track.fap -o out.pc2`` (or ``--expression joy [--intensity 0.8]``)
plays an MPEG-4 FAP track on the head bound in the workdir and writes ``<workdir>/animate/``:

animation.npz
    ``frames (F, n_user, 3) float32``: skin positions per frame in the **user's** vertex
    order and count (the mouth cut's appended vertices dropped, the fit's merged vertices
    expanded); ``fps``; ``contractions (F, m)``, ``controls (m,)`` (the contractions' columns:
    the muscles, then the sphincter's protrusion drive), ``jaw (F, 3)``.
report.json
    frames, fps, the mapping used (template or calibrated), FAPs with values but no mapping,
    per-layer time per frame, and the physical checks (NaN, inverted triangles, skin inside
    the skull).

then exports ``-o`` by suffix (:mod:`faceforge.io.export`: .pc2, .mdd, .glb, .usda/.usdc, or a
folder of OBJ files) and ``--preview sheet.png`` (a contact sheet). Exports are not cached: a new
``-o`` reuses the simulated frames.

``faceforge calibrate`` writes ``<workdir>/calibrate/``: ``fap_mapping.yaml`` (the mapping with
fitted response curves and measured jaw couplings; ``animate`` uses it when present),
``report.json`` and ``report.txt`` (per FAP: requested, achieved, relative error).

The mapping template is ``animate.fap_mapping`` (relative paths are resolved against the
current folder, then the repository).
"""

from __future__ import annotations

from pathlib import Path

import click

from faceforge.io.config import Choice, Integer, Number, add_rule
from faceforge.pipeline import Stage, register_command, register_stage

add_rule("skin.carry", Choice(("muscles", "all", "none")))
add_rule("muscle.damping", Number(0.0, 0.99))
add_rule("animate.orientation_guard.rounds", Integer(0))           # 0 turns the guard off
add_rule("animate.orientation_guard.min_area", Number(0.0, 0.95))
add_rule("animate.skull_guard.collision_reach", Number(0.0, 0.5))    # 0 turns bone collision off

#: FDPs on the lower lip (inner and outer contour), located on the lower side of a cut lip line
LOWER_LIP_FDPS = ("2.3", "2.8", "2.9", "8.2", "8.7", "8.8")
UPPER_LIP_FDPS = ("2.2", "2.6", "2.7", "8.1", "8.5", "8.6")


# --------------------------------------------------------------------------- paths

def mapping_template_path(config) -> Path:
    """``animate.fap_mapping`` (made absolute by the config against the file that set it)."""
    from faceforge.exceptions import ConfigError

    path = Path(str(config.get("animate.fap_mapping")))
    if not path.is_file():
        raise ConfigError(f"animate.fap_mapping: {path} not found")
    return path


def calibrated_mapping_path(workdir) -> Path:
    return Path(workdir) / "calibrate" / "fap_mapping.yaml"


def mapping_digest_without_presets(path) -> str:
    """SHA-256 of a FAP mapping file without its presets, the ``expressions`` and ``visemes``
    tables (the calibrate stage's digest of the template: calibration never reads the presets,
    animate takes them from the template, so editing one costs no recalibration). A file that
    is not a YAML mapping is digested whole (the stage then reports it when it runs)."""
    import hashlib
    import json

    import yaml

    from faceforge.pipeline.cache import file_digest

    try:
        data = yaml.safe_load(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, yaml.YAMLError):
        return file_digest(path)
    if not isinstance(data, dict):
        return file_digest(path)
    data.pop("expressions", None)
    data.pop("visemes", None)
    text = json.dumps(data, sort_keys=True, default=str)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


# --------------------------------------------------------------------------- the bound head

class BoundHead:
    """Everything animate and calibrate need, loaded from the fit and bind stages.

    Attributes
    ----------
    rig : faceforge.anatomy.animate.Rig (working skin)
    muscle_names : tuple of str, the muscles
    controls : tuple of str, column order of the contractions: the muscles, then the
        sphincter's protrusion drive (``MusculoskeletalSystem.controls``)
    skull : faceforge.anatomy.skull.Skull (fitted; jaw_transform); levers : JawLevers
    fapu : faceforge.mpeg4.Fapu
    rest : (n, 3) working skin at rest; faces : (m, 3) working faces
    user_index : (n_user,) int, working vertex of each of the user's vertices
    user_rotation : (3, 3) head space = the user's frame ``@ user_rotation.T`` (fit.npz)
    fdp_vertex : dict FDP -> working vertex index
    landmarks : dict FDP -> (3,) position on the neutral skin (head frame)
    cranium, mandible : (vertices, faces) at rest
    guard : faceforge.anatomy.animate.SkullGuard
    orientation : faceforge.anatomy.orientation_guard.OrientationGuard, or None when
        ``animate.orientation_guard.rounds`` is 0; after each skin step it alternates with
        the skull guard, and it is the rig's ``finish`` on each weighted frame
    """

    def __init__(self, fit_dir: Path, bind_dir: Path, config, log=lambda m: None):
        import numpy as np

        from dataclasses import replace

        from faceforge.anatomy.animate import Rig, SkullGuard
        from faceforge.anatomy.bone_collision import BoneCollision
        from faceforge.anatomy.binding import Binding
        from faceforge.anatomy.fap_mapping import JawLevers
        from faceforge.anatomy.orientation_guard import OrientationGuard
        from faceforge.anatomy.skin import SkinSimulation, SkinStiffness
        from faceforge.anatomy.skull import JawAxes, Skull
        from faceforge.exceptions import StageError
        from faceforge.io.stagefiles import load_npz
        from faceforge.mpeg4 import fapu_from_landmarks
        from faceforge.pbd import SolverSettings

        fit = load_npz(fit_dir / "fit.npz")
        bind = load_npz(bind_dir / "bind.npz")
        self.cranium = (fit["cranium_vertices"], fit["cranium_faces"])
        self.mandible = (fit["mandible_vertices"], fit["mandible_faces"])
        self.rest = np.asarray(bind["vertices"], dtype=float)
        self.faces = np.asarray(bind["faces"], dtype=np.int64)
        n_internal = int(bind["n_user"])
        u2i = fit["skin_user_to_internal"] if "skin_user_to_internal" in fit else np.arange(n_internal)
        self.user_index = np.asarray(u2i, dtype=np.int64)
        self.user_rotation = np.asarray(fit["user_rotation"], dtype=float) if "user_rotation" in fit else np.eye(3)
        try:
            axes = JawAxes(*(np.asarray(fit[f"jaw_{k}"], dtype=float) for k in (
                "pitch_point", "pitch_direction", "yaw_point", "yaw_direction",
                "protrusion_direction")), limits={}, condyles=np.zeros((2, 3)))
        except KeyError as exc:
            raise StageError(f"fit.npz lacks the jaw axes ({exc.args[0]}); rerun `faceforge fit`",
                             fit_dir / "fit.npz") from None
        self.skull = Skull(self.cranium, self.mandible, {}, {}, axes)
        self.landmarks = skin_lm = {str(k): p for k, p in zip(fit["skin_landmark_ids"],
                                                              fit["skin_landmark_positions"])}
        self.fapu = fapu_from_landmarks(skin_lm, fit_dir / "fit.npz")
        self.fdp_vertex = _fdp_vertices(skin_lm, self.rest, bind.get("lip_sides"))
        chin = skin_lm.get("2.1", self.rest[self.fdp_vertex.get("2.1", 0)])
        self.levers = JawLevers(_lever(chin, axes.pitch_point, axes.pitch_dir),
                                _lever(chin, axes.yaw_point, axes.yaw_dir))

        settings = SolverSettings.from_config(config.get("solver"))
        self.system = system = _muscle_system(fit, self.cranium, self.mandible, settings, config, log)
        self.muscle_names = tuple(system.muscles)
        self.controls = system.controls
        binding = Binding.from_arrays(bind)
        missing = [n for n in binding.body_names if n not in system.names]
        if missing:
            raise StageError(f"bind.npz binds the skin to {missing}, which the fitted head lacks; "
                             "rerun `faceforge bind`", bind_dir / "bind.npz")
        for b, name in enumerate(binding.body_names):
            ids = binding.face_ids[binding.body == b]
            if len(ids) and ids.max() >= len(system.faces(name)):
                raise StageError(f"bind.npz binds the skin to faces of {name!r} that the fitted head does "
                                 "not have (the muscle map changed?); rerun `faceforge bind`",
                                 bind_dir / "bind.npz")
        # anchors on the system's own rest bodies (the rebuilt muscles may differ from the meshes
        # bind saw by a projection): then the rest pose is an exact fixed point
        binding = replace(binding, points=binding.targets([system.surface(n) for n in binding.body_names]))
        self.skin = skin = SkinSimulation(self.rest, self.faces, binding, SkinStiffness.from_config(config),
                                          settings, carried=carried_anchors(binding, config.get("skin.carry")))

        last = [None, None]  # the last jaw DOFs and their transform (held poses repeat them)

        def skull(jaw):
            key = np.asarray(jaw, dtype=float).tobytes()  # bits: -0.0 is not 0.0 here
            if key != last[0]:
                last[:] = key, self.skull.jaw_transform(*jaw)
            system.set_jaw(last[1])  # returns at once when the mandible is already there

        def muscles(c, _bones, dt):
            system.step(dict(zip(self.controls, c)), None, dt)

        diag = float(np.linalg.norm(np.ptp(self.rest, axis=0)))
        self.guard = guard = SkullGuard(
            self.rest, {"cranium": self.cranium, "mandible": self.mandible},
            reach=float(config.get("animate.skull_guard.reach")) * diag,
            keep=float(config.get("animate.skull_guard.keep")))
        reach = float(config.get("animate.skull_guard.collision_reach")) * diag
        self.collision = collision = BoneCollision(
            self.rest, {"cranium": self.cranium, "mandible": self.mandible}, reach=reach,
            keep=float(config.get("animate.skull_guard.keep"))) if reach > 0 else None

        rounds = int(config.get("animate.orientation_guard.rounds"))
        self.orientation = orientation = OrientationGuard(
            self.rest, self.faces, min_area=float(config.get("animate.orientation_guard.min_area"))) \
            if rounds > 0 else None

        # the guard's bones (cranium, mandible) are the first rows of the system's world mesh,
        # in the same order (MusculoskeletalSystem.from_parts puts them there)
        bone_rows = system.vertex_range("mandible").stop
        pushed = np.empty(len(guard.vertex), dtype=np.int64)

        def skin_step(_bones, _muscles, dt):
            skin.step(system, dt)
            x = skin.layer.skin_positions(skin.state.positions)
            bones = system.world_view()[:bone_rows]
            # the skull guard pushes vertices one by one along the bone's normals, which can turn
            # a sliver over; the orientation guard moves them sideways, which can sink one below
            # its floor: alternate until the orientation pass has nothing left to do. After the
            # first round each looks again only where the other moved something (and the skull
            # guard at what it pushed itself, which round-off may push again): a full pass's result
            k = 0
            for r in range(max(rounds, 1)):
                only = None if r == 0 else np.concatenate([pushed[:k], orientation.touched])
                k = guard.apply_stacked(x, bones, pushed, only)
                if orientation is None or not orientation.apply(x, None if r == 0 else pushed[:k]):
                    break
            # skin that slid into a bone beyond the triangle the skull guard holds it above (the
            # lips onto the other jaw's teeth, the cheek over the cheekbone) is put back out. A
            # vertex pushed out of one jaw's bone can land in the other's, and the orientation
            # pass that follows can move one sideways into a bone again: the collision looks
            # again until it finds nothing (at most ``rounds`` times), after the first pass only
            # at what the last two passes moved (the rest was outside and has not moved since)
            jaw = np.eye(4) if last[1] is None else last[1]
            again = None
            for _ in range(max(rounds, 1) if collision is not None else 0):
                if not collision.apply(x, {"mandible": jaw}, again):
                    break
                again = collision.moved
                if orientation is not None and orientation.apply(x, collision.moved):
                    again = np.concatenate([again, orientation.touched])
            return skin.simulated()

        def reset():
            system.reset()
            skin.reset()

        self.rig = Rig(skull=skull, muscles=muscles, skin=skin_step, rest=self.rest,
                       influence=np.asarray(bind["influence"], dtype=float), reset=reset,
                       finish=None if orientation is None else orientation.apply)

    def bone_heights(self) -> tuple[float, float]:
        """(lowest, highest) height (+Y) of the bones at rest (cranium and mandible)."""
        import numpy as np

        y = np.concatenate([self.cranium[0][:, 1], self.mandible[0][:, 1]])
        return float(y.min()), float(y.max())

    def eyelids(self, config):
        """The lids of this head's eyes (:class:`faceforge.anatomy.eyelids.Eyelids`) as the
        config sets them (``animate.eyelids``, ``.eyelid_reach``, ``.eyelid_depth``); None when
        ``animate.eyelids`` is off."""
        from faceforge.anatomy.eyelids import Eyelids

        if not config.get("animate.eyelids"):
            return None
        return Eyelids(self.rest, self.faces, self.landmarks, self.fapu.unit("IRISD"),
                       config.get("animate.eyelid_reach"), config.get("animate.eyelid_depth"))

    def skull_at(self, jaw_dofs):
        """[(vertices, faces)] of cranium and mandible for jaw DOFs (3,)."""
        t = self.skull.jaw_transform(*jaw_dofs)
        v, f = self.mandible
        return [self.cranium, (v @ t[:3, :3].T + t[:3, 3], f)]

    def to_user(self, frames):
        """(F, n_working, 3) -> (F, n_user, 3) in the user's vertex order and frame."""
        import numpy as np

        out = frames[:, self.user_index]
        return out if np.array_equal(self.user_rotation, np.eye(3)) else out @ self.user_rotation


def carried_anchors(binding, carry: str):
    """(k,) bool: the anchors that carry their skin vertex (``skin.carry``: muscles | all | none;
    :class:`faceforge.anatomy.skin.SkinSimulation`)."""
    import numpy as np

    bone = np.isin(np.asarray(binding.body_names, dtype=object)[binding.body], ("cranium", "mandible"))
    return {"muscles": ~bone, "all": np.ones(len(bone), bool), "none": np.zeros(len(bone), bool)}[carry]


def _lever(point, axis_point, axis_dir) -> float:
    """Distance from ``point`` (3,) to the line through ``axis_point`` along ``axis_dir``."""
    import numpy as np

    d = np.asarray(axis_dir, dtype=float) / np.linalg.norm(axis_dir)
    r = np.asarray(point, dtype=float) - axis_point
    return float(np.linalg.norm(r - (r @ d) * d))


def _fdp_vertices(landmarks: dict, rest, lip_sides) -> dict:
    """FDP -> nearest working vertex.

    Where the lip line was cut by duplicating a shared ring, an upper and a lower vertex sit
    at the same place: lower-lip FDPs then take the lower copy (``lip_sides < 0``) and
    upper-lip FDPs the upper one (``lip_sides > 0``), whenever such a vertex is as near as the
    nearest vertex overall.
    """
    import numpy as np

    sides = np.zeros(len(rest), dtype=np.int8) if lip_sides is None else np.asarray(lip_sides)
    out = {}
    for fdp, p in landmarks.items():
        d = np.linalg.norm(rest - np.asarray(p, dtype=float), axis=1)
        want = -1 if fdp in LOWER_LIP_FDPS else 1 if fdp in UPPER_LIP_FDPS else 0
        if want and np.any(sides == want):
            side = np.where(sides == want, d, np.inf)
            if side.min() <= d.min() * (1.0 + 1e-9) + 1e-12:
                d = side
        out[fdp] = int(np.argmin(d))
    return out


def _muscle_system(fit, cranium, mandible, settings, config, log):
    """The layered muscles of the fitted head (§6), rebuilt from fit.npz.

    The muscle map's specs (``template.muscle_map`` on ``template.skull``) get the fitted
    points the fit stage stored (``muscle_map_points``, in ``MuscleSpec.points()`` order) and
    are built on the fitted skull (Eq. 5 thickness from its diagonal), deepest layer first.
    Without muscles in fit.npz the system is the skull alone.
    """
    from dataclasses import replace

    import numpy as np

    from faceforge.anatomy.fit_muscles import build_muscles_on
    from faceforge.anatomy.layers import MusculoskeletalSystem
    from faceforge.anatomy.muscle_map import load_muscle_map
    from faceforge.anatomy.skull import load_skull
    from faceforge.exceptions import StageError, TemplateError

    if "muscle_map_names" not in fit or not len(fit["muscle_map_names"]):
        log("fit.npz has no muscles: animating the skull alone")
        return MusculoskeletalSystem.from_parts(cranium, mandible, [], settings)
    specs = load_muscle_map(_template_path(config.get("template.muscle_map")),
                            load_skull(_template_path(config.get("template.skull"))))
    start = fit["muscle_map_start"]
    points = {str(n): fit["muscle_map_points"][start[i]:start[i + 1]]
              for i, n in enumerate(fit["muscle_map_names"])}
    fitted = []
    for spec in specs:
        p = points.get(spec.name)
        if p is None or len(p) != len(spec.points()):
            raise StageError(f"fit.npz has no fitted points for muscle {spec.name!r} of the muscle map; "
                             "rerun `faceforge fit`")
        fitted.append(spec.with_points(p))
    diagonal = float(np.linalg.norm(np.ptp(np.vstack([cranium[0], mandible[0]]), axis=0)))
    stiffness = {"linear": dict(config.get("muscle.linear.stiffness")),
                 "sphincter": dict(config.get("muscle.sphincter.stiffness"))}
    try:
        muscles = build_muscles_on(fitted, cranium, mandible, diagonal, stiffness,
                                   float(config.get("muscle.sphincter.carry_inner")),
                                   float(config.get("muscle.sphincter.protrusion")))
    except TemplateError as exc:
        raise StageError(f"fit.npz: {exc.message} (see fit/fit.png; rerun `faceforge fit`, or fit with "
                         "another muscle map)") from None
    settings = replace(settings, damping=float(config.get("muscle.damping")))
    return MusculoskeletalSystem.from_parts(cranium, mandible, muscles, settings)


def _template_path(raw) -> Path:
    p = Path(str(raw))
    if p.exists() or p.is_absolute():
        return p
    for root in (Path(__file__).resolve().parents[3], Path(__file__).resolve().parents[2]):
        if (root / p).exists():
            return root / p
    return p


# --------------------------------------------------------------------------- FAPs -> controls

def track_faps(track, mapping):
    """``(faps, missing)``: the low-level FAP frames ``(F, 68)`` of a track, its own values
    (absent ones 0) plus those of its FAP 2 expressions and FAP 1 visemes (the mapping's
    ``expressions`` and ``visemes`` tables), and the names of the visemes it selects that the
    mapping has no shape for."""
    import numpy as np

    from faceforge.anatomy.fap_mapping import expression_faps, viseme_faps

    faps = np.nan_to_num(np.asarray(track.values, dtype=float))
    faps[:, :2] = 0.0
    shapes, missing = viseme_faps(mapping, track.viseme)
    return faps + expression_faps(mapping, track.expression) + shapes, missing


def track_controls(track, mapping, head):
    """(contractions (F, m), jaw (F, 3), unmapped FAP numbers with nonzero values, the track's
    low-level FAP frames (F, 68) of :func:`track_faps`). FAP 1 counts as unmapped when the
    track selects a viseme the mapping's ``visemes`` table lacks."""
    import numpy as np

    faps, missing = track_faps(track, mapping)
    mapped = set(mapping.mapped_faps().tolist())
    unmapped = sorted(int(k + 1) for k in np.flatnonzero(np.abs(faps).max(axis=0) > 0) if k + 1 not in mapped)
    if missing:
        unmapped = [1, *unmapped]
    c, jaw = controls(mapping, faps, head)
    return c, jaw, unmapped, faps


def visemes_played(track) -> tuple[list[str], int]:
    """The names (in code order) of the visemes a track's FAP 1 gives a weight, and in how
    many frames it gives one."""
    from faceforge.anatomy.fap_mapping import VISEME_IDS, viseme_weights

    w = viseme_weights(track.viseme) > 0.0
    names = [name for name in sorted(VISEME_IDS, key=VISEME_IDS.get) if w[:, VISEME_IDS[name] - 1].any()]
    return names, int(w.any(axis=1).sum())


def controls(mapping, faps, head):
    """Contractions in ``head.controls`` order (F, m) and jaw DOFs (F, 3) for FAPs (F, 68).

    With muscles, every muscle the mapping names must exist (TemplateError otherwise);
    without (a jaw-only head), the muscle part is dropped.
    """
    import numpy as np

    from faceforge.anatomy.fap_mapping import fap_controls

    names = head.controls if head.controls else mapping.muscles
    c, jaw = fap_controls(mapping, faps, names, head.fapu.as_dict(), head.levers)
    return (c if head.controls else np.zeros((len(c), 0))), jaw


def warm_up(rig, contractions, jaw, fps: float, log, guards=()) -> float:
    """Play the track's first frame once and put the rig back at rest, so that the timed
    playback does not count numba's compilation of the kernels (about 35 s on the first run
    after an install or an upgrade; cached on disk afterwards). Logs the compilation when the
    frame took more than a second; returns its seconds. The rig is left at rest, also for an
    empty track."""
    import time

    from faceforge.anatomy.animate import play

    rig.reset()
    if not len(jaw):
        return 0.0
    t0 = time.perf_counter()
    play(rig, contractions[:1], jaw[:1], fps)
    for guard in guards:   # kernels frame 0 does not reach (the orientation guard's rescans)
        if guard is not None:
            guard.warm_up()
    seconds = time.perf_counter() - t0
    rig.reset()
    if seconds > 1.0:
        log(f"compiled the simulation kernels in {seconds:.0f} s (once: numba caches them)")
    return seconds


def _mapping(ctx):
    """The mapping to play (``animate_mapping``) and its path. Playing the workdir's calibration,
    the presets (expressions and visemes) are the template's (``animate.fap_mapping``):
    calibration measures the FAP entries only, and a preset edited there (or new in a faceforge
    release) plays without a recalibration."""
    from dataclasses import replace

    from faceforge.anatomy.fap_mapping import load_fap_mapping

    path = ctx.param("animate_mapping")
    mapping = load_fap_mapping(path)
    if Path(path).resolve() == calibrated_mapping_path(ctx.workdir).resolve():
        template = load_fap_mapping(mapping_template_path(ctx.config))
        mapping = replace(mapping, expressions=template.expressions, visemes=template.visemes)
    return mapping, str(path)


def write_frames(ctx, head, track, c, jaw, faps, angles, weights, lids, timings, mapping_path):
    """Play the track and stream its frames, a chunk at a time, through the lids, the checks,
    the head turn and the user's vertex order into ``animation.npz`` (issue 28: a take's
    memory does not grow with its length). Returns the
    :class:`~faceforge.anatomy.check_stream.StreamChecker` that saw every frame."""
    import numpy as np

    from faceforge.anatomy.animate import play
    from faceforge.anatomy.check_stream import StreamChecker
    from faceforge.anatomy.head_motion import turn_head
    from faceforge.io.frame_stream import FrameNpzWriter

    checker = StreamChecker(head.rest, head.faces, track.n_frames)

    def sink(start, frames):
        stop = start + len(frames)
        if lids is not None:   # kinematic, over the simulated skin; before the checks, which see them
            frames = lids.apply(frames, faps[start:stop])
        checker.add(frames)
        if weights is not None:
            frames = turn_head(frames, angles[start:stop], head.skull.jaw.yaw_point, weights)
        writer.write(head.to_user(frames))

    with FrameNpzWriter(ctx.out_dir / "animation.npz", track.n_frames, len(head.user_index)) as writer:
        try:
            warm_up(head.rig, c, jaw, track.fps, ctx.log, guards=(head.orientation,))   # leaves the rig at rest
            play(head.rig, c, jaw, track.fps, progress=ctx.progress, timings=timings, sink=sink)
        except FloatingPointError as exc:
            from faceforge.exceptions import StageError

            raise StageError(f"{exc}: the simulation diverged on this track (mapping {mapping_path}); "
                             "try more solver.iterations or a larger muscle.damping", ctx.param("fap")) from None
        writer.close(fps=np.float64(track.fps), contractions=c, controls=np.asarray(head.controls, dtype=str),
                     jaw=jaw)
    return checker


def run_animate(ctx):
    """Simulate the FAP track in ``ctx.params['fap']``; write animation.npz and report.json."""
    import numpy as np

    from faceforge.anatomy.animate import Timings
    from faceforge.anatomy.head_motion import HEAD_FAPS, head_angles, neck_weights
    from faceforge.io.stagefiles import save_json
    from faceforge.mpeg4 import read_fap

    head = BoundHead(ctx.input("fit"), ctx.input("bind"), ctx.config, log=ctx.log)
    mapping, mapping_path = _mapping(ctx)
    track = read_fap(ctx.param("fap"))
    c, jaw, unmapped, faps = track_controls(track, mapping, head)
    turn = bool(ctx.config.get("animate.head_rotation"))
    angles = head_angles(faps) if turn else np.zeros((track.n_frames, 3))
    if turn:
        unmapped = [f for f in unmapped if f not in HEAD_FAPS]
        if np.any(angles):
            ctx.log(f"head rotation (FAPs 48-50): up to {np.degrees(np.abs(angles).max()):.1f} deg")
    lids = head.eyelids(ctx.config)
    if lids is not None:
        unmapped = [f for f in unmapped if f not in lids.faps]
        if lids.faps and np.any(faps[:, [f - 1 for f in lids.faps]]):
            ctx.log(f"eyelids (FAPs {', '.join(map(str, lids.faps))}) on {len(lids.fields)} eye"
                    f"{'s' if len(lids.fields) > 1 else ''}")
    visemes, viseme_frames = visemes_played(track)
    if visemes:
        ctx.log(f"visemes (FAP 1) in {viseme_frames} frames: {', '.join(visemes)}")
    if unmapped:
        ctx.log(f"FAPs without a muscle mapping (ignored): {unmapped}")
    ctx.log(f"{track.n_frames} frames at {track.fps:g} fps on {len(head.rest)} skin vertices")
    timings = Timings()
    # the head turns as a whole about the top of the spine (approximated by the midpoint of the
    # jaw's condyles), the skin below the skull fading out of the turn; after the checks, which
    # look at the skin in the skull's own frame
    weights = None
    if np.any(angles):
        from faceforge.anatomy.head_parts import detached_vertices

        low, high = head.bone_heights()
        span = float(ctx.config.get("animate.neck_fade")) * (high - low)
        weights = neck_weights(head.rest, low, span)
        weights[detached_vertices(head.rest, head.faces, list(head.fdp_vertex.values()))] = 0.0  # another head
    checker = write_frames(ctx, head, track, c, jaw, faps, angles, weights, lids, timings, mapping_path)
    checks = checker.report(skull=lambda i: head.skull_at(jaw[i] if i >= 0 else np.zeros(3)))
    threads = max(head.skin.solver.threads, head.system.threads)   # the step's widest layer
    save_json(ctx.out_dir / "report.json", {
        "fap": str(ctx.param("fap")), "frames": track.n_frames, "fps": track.fps,
        "mapping": mapping_path, "unmapped_faps": unmapped,
        "user_vertices": int(len(head.user_index)), "working_vertices": int(len(head.rest)),
        "per_frame_ms": timings.per_frame_ms(), "threads": threads, "checks": checks.as_dict(),
        "max_contraction": float(c.max()) if c.size else 0.0,
        "eyes_with_lids": len(lids.fields) if lids is not None else 0, "visemes": visemes,
        "max_head_rotation_deg": np.degrees(np.abs(angles).max(axis=0)).tolist() if len(angles) else [0, 0, 0],
        "max_jaw": jaw.max(axis=0).tolist() if len(jaw) else [0, 0, 0]})
    ctx.log(f"{timings.per_frame_ms()['total']:.1f} ms/frame on {threads} thread"
            f"{'s' if threads > 1 else ''}; checks: {'ok' if checks.ok else checks.as_dict()}; "
            f"{checks.folded_edges} skin edges folded (new creases; at most "
            f"{checks.folded_max_per_frame} in one frame)")


ANIMATE = register_stage(Stage(
    name="animate", deps=("fit", "bind"), config_keys=("solver", "skin.stiffness", "skin.carry", "muscle",
                                                "animate"),
    inputs=("fap", "animate_mapping", "animate.fap_mapping"), outputs=("animation.npz", "report.json"),
    version="7", run=run_animate, description="play a FAP track on the bound head (§9)"))


# --------------------------------------------------------------------------- calibrate

def calibration_probes(mapping, head):
    """FAP number -> Probe for every mapped FAP whose FDP(s) the skin has."""
    import numpy as np

    from faceforge.anatomy.calibrate import Probe
    from faceforge.mpeg4 import DIRECTION_VECTORS, fap_record

    probes = {}
    for entry in mapping.entries:
        for fap in entry.faps:
            rec = fap_record(fap)
            if not rec.is_translation:
                continue
            m = entry.measure.get(fap)
            fdp, rel = (m.fdp, m.relative_to) if m is not None else (rec.fdp, None)
            if fdp not in head.fdp_vertex or (rel is not None and rel not in head.fdp_vertex):
                continue
            probes[fap] = Probe(fap, head.fdp_vertex[fdp], -1 if rel is None else head.fdp_vertex[rel],
                                np.asarray(DIRECTION_VECTORS[rec.direction], dtype=float),
                                head.fapu.unit(rec.unit))
    return probes


def requested_values(mapping, config) -> dict:
    """FAP number -> requested FAPU values (half and full typical magnitude, both signs where the
    mapping can produce them)."""
    mags = dict(config.get("animate.calibrate.magnitude"))
    jaw_mag = float(config.get("animate.calibrate.jaw_magnitude"))
    out = {}
    for e in mapping.entries:
        if not (e.positive or e.negative or e.jaw is not None):
            continue                      # nothing to drive (e.g. a pure jaw-coupling entry)
        top = jaw_mag if (e.jaw is not None and e.jaw[0] == "pitch") else float(mags[e.fapu])
        values = [0.5 * top, top]
        two_sided = bool(e.negative) or (e.jaw is not None and e.jaw[0] == "yaw")
        if two_sided:
            values = [-top, -0.5 * top] + values
        out[e.faps[0]] = values
    return out


def run_calibrate(ctx):
    """Fit the mapping's response curves on the bound head; write the mapping and the report."""
    from faceforge.anatomy.animate import static_poses
    from faceforge.anatomy.calibrate import (calibrate_mapping, format_table, measure_coupling,
                                             summarize)
    from faceforge.anatomy.fap_mapping import load_fap_mapping, save_fap_mapping
    from faceforge.io.stagefiles import save_json

    head = BoundHead(ctx.input("fit"), ctx.input("bind"), ctx.config, log=ctx.log)
    template_path = mapping_template_path(ctx.config)
    template = load_fap_mapping(template_path)
    fps = float(ctx.config.get("animate.fps"))
    settle = int(ctx.config.get("animate.calibrate.settle_frames"))

    def simulate(mapping, faps):
        c, jaw = controls(mapping, faps, head)
        return static_poses(head.rig, c, jaw, fps, settle=settle)

    probes = calibration_probes(template, head)
    requested = requested_values(template, ctx.config)
    ctx.log(f"calibrating {len(template.entries)} entries ({len(probes)} FAPs observable), "
            f"{settle} settle frames per pose")
    calibrated, rows = calibrate_mapping(
        template, simulate, head.rest, probes, requested,
        refine=int(ctx.config.get("animate.calibrate.refine")),
        progress=lambda it: ctx.progress(it, total=len(template.entries), desc="FAPs"))
    if 3 in probes:
        calibrated = measure_coupling(calibrated, simulate, head.rest, probes,
                                      value=float(ctx.config.get("animate.calibrate.jaw_magnitude")))
    summary = summarize(rows)
    lips = _lip_opening(calibrated, simulate, head, float(ctx.config.get("animate.calibrate.jaw_magnitude")))
    save_fap_mapping(calibrated, ctx.out_dir / "fap_mapping.yaml",
                     header=f"calibrated by `faceforge calibrate` from {template_path}\n"
                            f"median relative error {summary['all']['median_relative_error']}")
    save_json(ctx.out_dir / "report.json", {
        "summary": summary, "open_jaw_lip_separation": lips,
        "fapu": head.fapu.as_dict(), "jaw_levers": {"pitch": head.levers.pitch, "yaw": head.levers.yaw},
        "rows": [r.as_dict() for r in rows],
        "unobservable_faps": sorted(int(f) for f in template.mapped_faps() if int(f) not in probes)})
    table = format_table(rows)
    med = _percent(summary["all"]["median_relative_error"])
    (ctx.out_dir / "report.txt").write_text(
        table + f"\n\nmedian relative error (lip, jaw, cheek, eyebrow): "
        f"{med}; {summary['all']['within_10_percent']} of "
        f"{summary['all']['count']} rows within 10 %, {summary['all']['saturated']} at full contraction "
        f"(c=max)\n")
    ctx.log(f"median relative error {med} "
            f"(uncalibrated {_percent(summary['all_uncalibrated']['median_relative_error'])})")


def _percent(fraction) -> str:
    """``0.0504`` -> ``'5.0%'``; None (no rows) -> ``'n/a'``."""
    return "n/a" if fraction is None else f"{100 * fraction:.1f}%"


def _lip_opening(mapping, simulate, head, value):
    """open_jaw alone at ``value`` MNS: how far the inner lips part (2.3 - 2.2), in MNS units."""
    import numpy as np

    if "2.2" not in head.fdp_vertex or "2.3" not in head.fdp_vertex:
        return None
    faps = np.zeros((1, 68))
    faps[0, 2] = value
    skin = simulate(mapping, faps)[0]
    a, b = head.fdp_vertex["2.2"], head.fdp_vertex["2.3"]
    gap0 = head.rest[a, 1] - head.rest[b, 1]
    gap = skin[a, 1] - skin[b, 1]
    opened = (gap - gap0) / head.fapu.unit("MNS")
    return {"requested": value, "achieved": float(opened), "relative_error": float(abs(opened - value) / value)}


CALIBRATE = register_stage(Stage(
    # what the bound head (its solver, muscles, guards) and the calibration itself read, not the
    # playback-only keys (head rotation, previews, expression presets): changing those does not
    # cost a recalibration
    name="calibrate", deps=("fit", "bind"), config_keys=(
        "solver", "skin.stiffness", "skin.carry", "muscle", "animate.fap_mapping", "animate.fps",
        "animate.skull_guard", "animate.orientation_guard", "animate.calibrate"),
    inputs=("animate.fap_mapping",), digests={"animate.fap_mapping": mapping_digest_without_presets},
    outputs=("fap_mapping.yaml", "report.json", "report.txt"),
    version="4", run=run_calibrate, description="measure and fit the FAP -> muscle mapping (§9)"))


# --------------------------------------------------------------------------- commands

def _expression_file(app, name: str, intensity: float, seconds: float) -> Path:
    """Write the preset as a FAP file in the workdir (its content keys the cache)."""
    from faceforge.mpeg4 import expression_track, write_fap

    cfg = app.config
    track = expression_track(name, intensity=intensity, fps=float(cfg.get("animate.fps")),
                             seconds=seconds, ramp=float(cfg.get("animate.expression_ramp")))
    path = app.workspace.root / "inputs" / f"expression_{name}_{intensity:g}.fap"
    path.parent.mkdir(parents=True, exist_ok=True)
    write_fap(path, track)
    return path


def _viseme_file(app, text: str) -> Path:
    """Write ``--visemes`` (names separated by commas or spaces) as a FAP file in the workdir
    (:func:`faceforge.mpeg4.viseme_track`; its content keys the cache). An unknown name is a
    one-line error listing the valid ones."""
    import hashlib

    from faceforge.exceptions import FapError, StageError
    from faceforge.mpeg4 import viseme_track, write_fap

    names = [n for n in text.replace(",", " ").split() if n]
    try:
        track = viseme_track(names, fps=float(app.config.get("animate.fps")))
    except FapError as exc:
        raise StageError(f"--visemes: {exc}") from None
    tag = hashlib.sha256(" ".join(names).encode()).hexdigest()[:12]
    path = app.workspace.root / "inputs" / f"visemes_{tag}.fap"
    path.parent.mkdir(parents=True, exist_ok=True)
    write_fap(path, track)
    return path


def export_outputs(app, output: str | None, preview: str | None, preview_frames: str | None) -> None:
    """Write ``-o`` and ``--preview`` from the animate stage's frames."""
    import numpy as np

    from faceforge.exceptions import StageError
    from faceforge.io.frame_stream import open_frames

    # a read-only map of the stage file: an hour-long take is read a chunk at a time
    frames = open_frames(app.workspace.stage_dir("animate") / "animation.npz")
    fps = float(open_frames(app.workspace.stage_dir("animate") / "animation.npz", "fps"))
    mesh = app.params().get("mesh")
    if not mesh:
        raise StageError("no mesh remembered in the workdir; run `faceforge fit MESH` first", app.workspace.root)
    from faceforge.pipeline.stages.fit import user_rotation

    rotation = user_rotation(app.workspace.stage_dir("fit"))
    if output:
        from faceforge.io.export import export_for_mesh, up_axis_of

        written, notes = export_for_mesh(output, frames, mesh, fps, up_axis_of(rotation))
        app.log(f"animate: wrote {written} ({len(frames)} frames, {frames.shape[1]} vertices, {fps:g} fps)")
        for note in notes:
            app.log(f"animate: note: {note}")
    if preview:
        from faceforge.io.mesh import load_mesh
        from faceforge.viz.contact_sheet import contact_sheet, pick_frames

        v, faces, _ = load_mesh(mesh)
        if len(v) != frames.shape[1]:
            raise StageError(f"has {len(v)} vertices but the animation {frames.shape[1]}; rerun `faceforge fit`",
                             mesh)
        try:
            idx = pick_frames(len(frames), int(app.config.get("animate.preview_frames")), preview_frames)
        except ValueError as exc:
            raise StageError(f"--preview-frames: {exc}") from None
        # only the drawn frames are read, turned upright (head space)
        shown = np.stack([np.asarray(frames[i]) @ rotation.T.astype(frames.dtype) for i in idx])
        contact_sheet(preview, shown, faces, range(len(idx)), fps, title=Path(output or "animation").name,
                      focus=True, labels=[f"frame {i}  ({i / fps:.2f} s)" for i in idx])
        app.log(f"animate: wrote {preview}")


@click.command("animate", help="Play an MPEG-4 FAP track or an expression on the bound head (§9).")
@click.option("--fap", "fap", type=click.Path(dir_okay=False, exists=True), default=None,
              help="FAP file (.fap, MPEG-4 v2.0/2.1).")
@click.option("--expression", type=click.Choice(["joy", "sadness", "surprise", "anger", "disgust", "fear"]),
              default=None, help="Play a basic expression instead (ramps in, holds, ramps out).")
@click.option("--intensity", type=click.FloatRange(0.0, 1.0), default=1.0, show_default=True,
              help="Peak strength of --expression.")
@click.option("--seconds", type=click.FloatRange(min=0.1), default=None,
              help="Length of --expression [default: animate.expression_seconds].")
@click.option("--visemes", default=None, metavar="V1,V2,...",
              help="Say a sequence of MPEG-4 visemes instead (p_b_m, f_v, th, t_d, k_g, ch_j_sh, s_z, "
                   "n_l, r, a, e, i, o, u, none), 0.2 s each, cross-fading.")
@click.option("-o", "--output", type=click.Path(), default=None,
              help="Output by suffix: .pc2, .mdd (Blender Mesh Cache), .glb, .usda or .usdc (USD), "
                   "or a folder (OBJ sequence).")
@click.option("--preview", type=click.Path(dir_okay=False), default=None, help="Contact sheet PNG.")
@click.option("--preview-frames", default=None, help="Frames for --preview, e.g. 0,20,40 [default: evenly spaced].")
@click.option("--force", is_flag=True, help="Resimulate even if up to date.")
@click.pass_obj
def animate_command(app, fap, expression, intensity, seconds, visemes, output, preview, preview_frames, force):
    from faceforge.exceptions import StageError

    if sum(x is not None for x in (fap, expression, visemes)) != 1:
        raise StageError("give exactly one of --fap FILE, --expression NAME or --visemes V1,V2,...")
    if output or preview:
        from faceforge.io.export import check_output, protect_inputs

        params = app.workspace.load_params()
        inputs = {"mesh": params.get("mesh"), "landmark file": params.get("landmarks"), "FAP track": fap}
        if output:
            check_output(output, inputs)      # an output it cannot or must not write fails before the simulation
        if preview:
            protect_inputs(preview, {**inputs, "-o output": output})
    if fap is not None:   # a malformed FAP file fails in milliseconds, before the head is loaded
        import warnings

        from faceforge.mpeg4 import read_fap

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")   # the stage reads it again and warns then
            read_fap(fap)
    if preview:
        from faceforge.io.writable import check_writable

        check_writable(preview, "--preview")
    if expression is not None:
        seconds = seconds or float(app.config.get("animate.expression_seconds"))
        fap = _expression_file(app, expression, intensity, seconds)
    if visemes is not None:
        fap = _viseme_file(app, visemes)
    mapping = playback_mapping(app, "animate")
    app.run_stage("animate", params={"fap": str(fap), "animate_mapping": str(mapping)}, force=force)
    export_outputs(app, output, preview, preview_frames)


def playback_mapping(app, command: str) -> Path:
    """The mapping a playback command plays: the workdir's calibration when there is one (said
    so when it is out of date), else the template. Logged as ``<command>: mapping <path>``."""
    calibrated = calibrated_mapping_path(app.workspace.root)
    mapping = calibrated if calibrated.exists() else mapping_template_path(app.config)
    app.log(f"{command}: mapping {mapping}")
    if calibrated.exists():
        _warn_if_stale_calibration(app, command)
    return mapping


def _warn_if_stale_calibration(app, command: str = "animate") -> None:
    """Say so when the calibration animate plays is out of date (the head was refitted, the
    template or the solver settings changed since): it is played anyway (a calibration takes
    minutes; ``faceforge calibrate`` refreshes it)."""
    from faceforge.pipeline.runner import plan

    status = plan(app.workspace, app.config, app.workspace.load_params(), ["calibrate"])[-1]
    if not status.up_to_date:
        app.log(f"{command}: warning: the calibration is out of date ({'; '.join(status.reasons)}); "
                "playing it anyway: `faceforge calibrate` brings it up to date")


@click.command("calibrate", help="Measure how precisely FAPs move the skin and fit the mapping (§9).")
@click.option("--force", is_flag=True, help="Rerun even if up to date.")
@click.pass_obj
def calibrate_command(app, force):
    statuses = app.run_stage("calibrate", force=force)
    out = app.workspace.stage_dir("calibrate")
    app.log((out / "report.txt").read_text())
    ran = any(s.ran and s.stage.name == "calibrate" for s in statuses)
    app.log(f"calibrate: {'wrote' if ran else 'kept'} {out / 'fap_mapping.yaml'} (used by `faceforge animate`)")


register_command(animate_command)
register_command(calibrate_command)
