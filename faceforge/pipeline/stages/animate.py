"""The animate stage: FAP playback on the bound head (paper §9).

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
folder of OBJ files) and ``--preview sheet.png`` (a contact sheet), :mod:`faceforge.pipeline.outputs`.
Exports are not cached: a new ``-o`` reuses the simulated frames.

The mapping played is the calibrate stage's (:mod:`faceforge.pipeline.stages.calibrate`) with the
template's presets (:func:`faceforge.pipeline.mapping.stage_mapping`).
"""

from __future__ import annotations

from pathlib import Path

import click

from faceforge.pipeline import Stage, register_command, register_stage
from faceforge.pipeline.result_checks import keep_going_option
from faceforge.pipeline.workdir_guard import check_outside_workdir


def run_animate(ctx):
    """Simulate the FAP track in ``ctx.params['fap']``; write animation.npz and report.json. The
    track is read a block of frames at a time (:class:`~faceforge.mpeg4.fap_stream.FapFile`):
    once to check it, once for its summary, once to play it."""
    import numpy as np

    from faceforge.animation.control_stream import ControlBlocks
    from faceforge.animation.eyeballs import GAZE_FAPS, eye_pieces
    from faceforge.animation.head_motion import HEAD_FAPS
    from faceforge.animation.playback import Timings
    from faceforge.animation.rig import BoundHead
    from faceforge.animation.statics import SettleSettings
    from faceforge.animation.take import play_take, take_weights
    from faceforge.exceptions import StageError
    from faceforge.io.frame_stream import FrameNpzWriter, open_frames
    from faceforge.io.stagefiles import save_json
    from faceforge.mpeg4.fap_stream import FapFile
    from faceforge.pipeline.mapping import stage_mapping

    head = BoundHead(ctx.input("fit"), ctx.input("bind"), ctx.config, log=ctx.log, cache=ctx.workdir / "cache")
    mapping, mapping_path = stage_mapping(ctx)
    fap = FapFile(ctx.param("fap"))
    turn = bool(ctx.config.get("animate.head_rotation"))
    source = ControlBlocks(fap, mapping, head, turn)
    summary = source.summary()
    unmapped = summary.unmapped
    if turn:
        unmapped = [f for f in unmapped if f not in HEAD_FAPS]
        if np.any(summary.max_angles):
            ctx.log(f"head rotation (FAPs 48-50): up to {np.degrees(summary.max_angles.max()):.1f} deg")
    lids = head.eyelids(ctx.config)
    if lids is not None:
        unmapped = [f for f in unmapped if f not in lids.faps]
        if lids.faps and np.any(summary.moving[[f - 1 for f in lids.faps]]):
            ctx.log(f"eyelids (FAPs {', '.join(map(str, lids.faps))}) on {len(lids.fields)} eye"
                    f"{'s' if len(lids.fields) > 1 else ''}")
    eyes = None
    if np.any(summary.moving[[f - 1 for f in GAZE_FAPS]]):
        eyes = eye_pieces(head.rest, head.faces, head.landmarks)
        if eyes:
            unmapped = [f for f in unmapped if f not in GAZE_FAPS]
            ctx.log(f"eyeballs (FAPs 23-26) on {len(eyes)} eyeball piece{'s' if len(eyes) > 1 else ''}")
    if summary.visemes:
        ctx.log(f"visemes (FAP 1) in {summary.viseme_frames} frames: {', '.join(summary.visemes)}")
    if unmapped:
        ctx.log(f"FAPs without a muscle mapping (ignored): {unmapped}")
    ctx.log(f"{fap.n_frames} frames at {fap.fps:g} fps on {len(head.rest)} skin vertices")
    timings = Timings()
    weights = take_weights(head, summary, float(ctx.config.get("animate.neck_fade")))
    offline = (SettleSettings.from_config(ctx.config) if ctx.config.get("animate.quality") == "offline"
               else None)   # each frame solved to convergence
    bar = ctx.progress(None, total=source.n_frames, desc="frames")
    with FrameNpzWriter(ctx.out_dir / "animation.npz", source.n_frames, len(head.user_index)) as writer:
        try:
            checker = play_take(head, source, writer, weights=weights, lids=lids, timings=timings,
                                offline=offline, bar=bar, log=ctx.log, eyes=eyes)
        except FloatingPointError as exc:
            raise StageError(f"{exc}: the simulation diverged on this track (mapping {mapping_path}); "
                             "try more solver.iterations or a larger muscle.damping", ctx.param("fap")) from None
        finally:
            bar.close()
        writer.close(fps=np.float64(source.fps), contractions=writer.SPOOLED,
                     controls=np.asarray(head.controls, dtype=str), jaw=writer.SPOOLED)
    jaw = open_frames(ctx.out_dir / "animation.npz", "jaw")   # a map: the few frames the skull test reads
    checks = checker.report(skull=lambda i: head.skull_at(np.asarray(jaw[i]) if i >= 0 else np.zeros(3)))
    threads = max(head.skin.solver.threads, head.system.threads)   # the step's widest layer
    save_json(ctx.out_dir / "report.json", {
        "fap": str(ctx.param("fap")), "frames": fap.n_frames, "fps": fap.fps,
        "mapping": mapping_path, "unmapped_faps": unmapped,
        "user_vertices": int(len(head.user_index)), "working_vertices": int(len(head.rest)),
        "per_frame_ms": timings.per_frame_ms(), "threads": threads, "checks": checks.as_dict(),
        "max_contraction": summary.max_contraction,
        "eyes_with_lids": len(lids.fields) if lids is not None else 0, "eyeballs_turned": len(eyes or {}),
        "visemes": summary.visemes,
        "max_head_rotation_deg": np.degrees(summary.max_angles).tolist(),
        "max_jaw": summary.max_jaw.tolist()})
    ctx.log(f"{timings.per_frame_ms()['total']:.1f} ms/frame on {threads} thread"
            f"{'s' if threads > 1 else ''}; checks: {'ok' if checks.ok else checks.as_dict()}; "
            f"{checks.folded_edges} skin edges folded (new creases; at most "
            f"{checks.folded_max_per_frame} in one frame)")


ANIMATE = register_stage(Stage(
    # the bound head rebuilds the muscles from the template's muscle map on its skull
    # (faceforge.animation.rig.muscle_system): both template files are inputs
    name="animate", deps=("fit", "bind", "calibrate"), config_keys=("solver", "skin.stiffness", "skin.carry", "skin.carry_radius_mm",
                                                                    "skin.join_insertions", "skin.cheek_tether",
                                                                    "skin.lid_hold", "skin.lid_hold_sink", "skin.commissure_fold_deg", "skin.fold_deg", "skin.proxy_fold_limit", "skin.lip_contact_mm", "bind.cheek_muscles", "muscle",
                                                "animate", "template"),
    inputs=("fap", "animate_mapping?", "animate.fap_mapping", "template.skull", "template.muscle_map"),
    outputs=("animation.npz", "report.json"),
    version="15", run=run_animate, description="play a FAP track on the bound head (§9)"))


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
@keep_going_option
@click.pass_obj
def animate_command(app, fap, expression, intensity, seconds, visemes, output, preview, preview_frames, force):
    from faceforge.exceptions import StageError

    if sum(x is not None for x in (fap, expression, visemes)) != 1:
        raise StageError("give exactly one of --fap FILE, --expression NAME or --visemes V1,V2,...")
    check_outside_workdir(app.workspace, output, "-o")
    check_outside_workdir(app.workspace, preview, "--preview")
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

        from faceforge.mpeg4.fap_stream import FapFile

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")   # the stage reads it again and warns then
            FapFile(fap)                      # checked a block at a time (a long take is not held)
    if preview:
        from faceforge.io.writable import check_writable

        check_writable(preview, "--preview")
    if expression is not None:
        seconds = seconds or float(app.config.get("animate.expression_seconds"))
        fap = _expression_file(app, expression, intensity, seconds)
    if visemes is not None:
        fap = _viseme_file(app, visemes)
    from faceforge.pipeline.mapping import playback_mapping
    from faceforge.pipeline.outputs import export_outputs

    playback_mapping(app, "animate")
    app.run_stage("animate", params={"fap": str(fap), "animate_mapping": None}, force=force)   # forgets an old one
    export_outputs(app, output, preview, preview_frames)


register_command(animate_command)
