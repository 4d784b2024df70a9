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

The calibrate stage writes ``<workdir>/calibrate/``: ``fap_mapping.yaml`` (the mapping with
fitted response curves and measured jaw couplings), ``report.json`` and ``report.txt`` (per FAP:
requested, achieved, relative error). It is cached and upstream of animate, expressions, visemes
and bake, so they always play the head's own mapping: it reruns when the head (fit, bind), the
template or a simulation setting changes, never for a new FAP track. With
``animate.calibrate.enabled: false`` it writes the template mapping as it is.

The mapping template is ``animate.fap_mapping`` (relative paths are resolved against the
current folder, then the repository).
"""

from __future__ import annotations

from pathlib import Path

import click

from faceforge.pipeline import Stage, register_command, register_stage


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


def _mapping(ctx):
    """The mapping to play and its path: the calibrate stage's (an upstream stage of every
    playback stage), with the presets (expressions and visemes) of the template
    (``animate.fap_mapping``): calibration measures the FAP entries only, and a preset edited
    there (or new in a faceforge release) plays without a recalibration. Another mapping file
    given as the ``animate_mapping`` param (tools, tests; the commands never remember one) plays
    as it is, presets included."""
    from dataclasses import replace

    from faceforge.animation.fap_mapping import load_fap_mapping

    given = ctx.params.get("animate_mapping")
    path = Path(given) if given else ctx.input("calibrate") / "fap_mapping.yaml"
    mapping = load_fap_mapping(path)
    if not given or path.resolve() == calibrated_mapping_path(ctx.workdir).resolve():
        template = load_fap_mapping(mapping_template_path(ctx.config))
        mapping = replace(mapping, expressions=template.expressions, visemes=template.visemes)
    return mapping, str(path)


def write_frames(ctx, head, track, c, jaw, faps, angles, weights, lids, timings, mapping_path):
    """Play the track and stream its frames, a chunk at a time, through the lids, the checks,
    the head turn and the user's vertex order into ``animation.npz`` (issue 28: a take's
    memory does not grow with its length). Returns the
    :class:`~faceforge.animation.check_stream.StreamChecker` that saw every frame."""
    import numpy as np

    from faceforge.animation.check_stream import StreamChecker
    from faceforge.animation.head_motion import turn_head
    from faceforge.animation.playback import play, warm_up
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
            if ctx.config.get("animate.quality") == "offline":   # each frame solved to convergence
                from faceforge.animation.statics import SettleSettings, play_converged

                play_converged(head.rig, c, jaw, track.fps, sink, SettleSettings.from_config(ctx.config))
            else:                                                # real time: solver.iterations a frame
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

    from faceforge.animation.controls import track_controls, visemes_played
    from faceforge.animation.head_motion import HEAD_FAPS, head_angles, neck_weights
    from faceforge.animation.playback import Timings
    from faceforge.animation.rig import BoundHead
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
        from faceforge.animation.head_parts import detached_vertices

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
    # the bound head rebuilds the muscles from the template's muscle map on its skull
    # (faceforge.animation.rig.muscle_system): both template files are inputs
    name="animate", deps=("fit", "bind", "calibrate"), config_keys=("solver", "skin.stiffness", "skin.carry", "muscle",
                                                "animate", "template"),
    inputs=("fap", "animate_mapping?", "animate.fap_mapping", "template.skull", "template.muscle_map"),
    outputs=("animation.npz", "report.json"),
    version="8", run=run_animate, description="play a FAP track on the bound head (§9)"))


# --------------------------------------------------------------------------- calibrate

def run_calibrate(ctx):
    """Fit the mapping's response curves on the bound head; write the mapping and the report."""
    from faceforge.animation.calibrate import format_table
    from faceforge.animation.calibrate_head import calibrate_head
    from faceforge.animation.fap_mapping import load_fap_mapping, save_fap_mapping
    from faceforge.animation.rig import BoundHead
    from faceforge.io.stagefiles import save_json

    template_path = mapping_template_path(ctx.config)
    template = load_fap_mapping(template_path)
    if not bool(ctx.config.get("animate.calibrate.enabled")):
        _uncalibrated(ctx, template, template_path)
        return
    head = BoundHead(ctx.input("fit"), ctx.input("bind"), ctx.config, log=ctx.log)
    result = calibrate_head(head, template, ctx.config, log=ctx.log, progress=ctx.progress)
    calibrated, rows, summary, lips, probes = (result.mapping, result.rows, result.summary, result.lips,
                                               result.probes)
    save_fap_mapping(calibrated, ctx.out_dir / "fap_mapping.yaml",
                     header=f"calibrated by `faceforge calibrate` from {template_path}\n"
                            f"median relative error {summary['all']['median_relative_error']}")
    save_json(ctx.out_dir / "report.json", {
        "summary": summary, "open_jaw_lip_separation": lips,
        "fapu": head.fapu.as_dict(), "jaw_levers": {"pitch": head.levers.pitch, "yaw": head.levers.yaw},
        "rows": [r.as_dict() for r in rows], "statics": result.statics,
        "unobservable_faps": sorted(int(f) for f in template.mapped_faps() if int(f) not in probes)})
    table = format_table(rows)
    med = _percent(summary["all"]["median_relative_error"])
    (ctx.out_dir / "report.txt").write_text(
        table + f"\n\nmedian relative error (lip, jaw, cheek, eyebrow): "
        f"{med}; {summary['all']['within_10_percent']} of "
        f"{summary['all']['count']} rows within 10 %, {summary['all']['saturated']} at full contraction "
        f"(c=max)\n")
    st = result.statics or {}
    ctx.log(f"median relative error {med} "
            f"(uncalibrated {_percent(summary['all_uncalibrated']['median_relative_error'])}); "
            f"{st.get('poses')} poses, {st.get('frames')} frames, largest residual {st.get('residual_max', 0):.1e} "
            f"of the diagonal, {st.get('unconverged')} unconverged")


def _uncalibrated(ctx, template, template_path) -> None:
    """``animate.calibrate.enabled: false``: the template mapping as it is, and a report saying so."""
    from faceforge.animation.fap_mapping import save_fap_mapping
    from faceforge.io.stagefiles import save_json

    save_fap_mapping(template, ctx.out_dir / "fap_mapping.yaml",
                     header=f"not calibrated (animate.calibrate.enabled: false): {template_path} as it is")
    save_json(ctx.out_dir / "report.json", {"calibrated": False, "summary": None, "rows": []})
    (ctx.out_dir / "report.txt").write_text("not calibrated (animate.calibrate.enabled: false): the template "
                                            "mapping plays as it is\n")
    ctx.log("calibration off (animate.calibrate.enabled: false): playing the template mapping")


def _percent(fraction) -> str:
    """``0.0504`` -> ``'5.0%'``; None (no rows) -> ``'n/a'``."""
    return "n/a" if fraction is None else f"{100 * fraction:.1f}%"


CALIBRATE = register_stage(Stage(
    # what the bound head (its solver, muscles, guards) and the calibration itself read, not the
    # playback-only keys (head rotation, previews, expression presets): changing those does not
    # cost a recalibration
    name="calibrate", deps=("fit", "bind"), config_keys=(
        "solver", "skin.stiffness", "skin.carry", "muscle", "animate.fap_mapping", "animate.fps",
        "animate.skull_guard", "animate.orientation_guard", "animate.calibrate", "animate.jaw_glide",
        "animate.jaw_glide_slope", "animate.statics", "template"),
    inputs=("animate.fap_mapping", "animate.calibrate.magnitudes", "template.skull", "template.muscle_map"),
    digests={"animate.fap_mapping": mapping_digest_without_presets},
    outputs=("fap_mapping.yaml", "report.json", "report.txt"),
    version="5", run=run_calibrate, description="measure and fit the FAP -> muscle mapping (§9)"))


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


def _preview_face(app, first, stage: str = "animate"):
    """(region (n,) bool or None, track name) of a --preview: the face's box from the fit's
    landmarks (:func:`faceforge.viz.contact_sheet.face_region`; the user's vertex order, head
    frame ``first (n, 3)``), so a turning head is framed by its face, and the played track's
    file name from the animate stage's report."""
    import json

    import numpy as np

    from faceforge.io.stagefiles import load_npz
    from faceforge.viz.contact_sheet import face_region

    region, track = None, "animation"
    try:
        fit = load_npz(app.workspace.stage_dir("fit") / "fit.npz")
        u2i = np.asarray(fit["skin_user_to_internal"], dtype=np.int64)
        lm = dict(zip(fit["skin_landmark_ids"], fit["skin_landmark_positions"]))
        if len(u2i) == len(first):
            inner = np.zeros((int(u2i.max()) + 1, 3))
            inner[u2i] = first
            region = face_region(inner, lm)
            region = None if region is None else region[u2i]
        report = json.loads((app.workspace.stage_dir(stage) / "report.json").read_text())
        track = Path(str(report.get("fap", track))).name
    except (OSError, KeyError, ValueError) as exc:   # an older workdir: the moving part, untitled
        app.log(f"animate: preview framed by its motion ({exc})")
    return region, track


def export_outputs(app, output: str | None, preview: str | None, preview_frames: str | None,
                   stage: str = "animate") -> None:
    """Write ``-o`` and ``--preview`` from the frames of ``stage`` (animate, or arkit)."""
    import numpy as np

    from faceforge.exceptions import StageError
    from faceforge.io.frame_stream import open_frames

    # a read-only map of the stage file: an hour-long take is read a chunk at a time
    frames = open_frames(app.workspace.stage_dir(stage) / "animation.npz")
    fps = float(open_frames(app.workspace.stage_dir(stage) / "animation.npz", "fps"))
    mesh = app.params().get("mesh")
    if not mesh:
        raise StageError("no mesh remembered in the workdir; run `faceforge fit MESH` first", app.workspace.root)
    from faceforge.fit.orientation import user_rotation

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
        first = np.asarray(frames[0]) @ rotation.T.astype(frames.dtype)
        region, track = _preview_face(app, first, stage)
        contact_sheet(preview, shown, faces, range(len(idx)), fps, focus=region is None, region=region,
                      panel=3.0, dpi=120, labels=[f"frame {i}  ({i / fps:.2f} s)" for i in idx],
                      title=f"{track}" + (f" -> {Path(output).name}" if output else ""))
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
    playback_mapping(app, "animate")
    app.run_stage("animate", params={"fap": str(fap), "animate_mapping": None}, force=force)   # forgets an old one
    export_outputs(app, output, preview, preview_frames)


def playback_mapping(app, command: str) -> Path:
    """The mapping a playback command plays: the calibrate stage's, brought up to date first (a
    cached stage upstream of every playback stage; ``animate.calibrate.enabled: false`` makes it
    the template as it is). Logged as ``<command>: mapping <path>``."""
    calibrated = calibrated_mapping_path(app.workspace.root)
    on = bool(app.config.get("animate.calibrate.enabled"))
    app.log(f"{command}: mapping {calibrated}" + ("" if on else " (uncalibrated template, animate.calibrate.enabled: false)"))
    return calibrated


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
