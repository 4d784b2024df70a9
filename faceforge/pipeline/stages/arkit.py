"""ARKit weight tracks through the muscles, and ARKit curves out (issue 27).

``faceforge animate --arkit take.csv -o out.pc2`` plays an ARKit weight track (a Live Link Face
CSV, a plain CSV or JSON of name -> weight per frame: :func:`faceforge.blendshapes.curves.read_weights`)
on the bound head: each frame's controls are the weighted sum of the baked shapes' controls
(contractions, jaw DOFs, eyelid FAPs; ``faceforge bake``, brought up to date first), clipped to
their ranges, and simulated like any track. The rig is not additive, so the drive is corrected
``animate.arkit_rounds`` times first (:func:`faceforge.blendshapes.weights_take.refine_drive`: each
round plays the take and reads its frames back against the baked shapes as ``--curves`` does) until
the played face reads back as the take's weights. Writes ``<workdir>/arkit/animation.npz`` (the
animate stage's format, plus ``weights (F, k)`` and ``names``, and the corrected ``drive (F, j)``
over the made shapes ``drive_shapes``) and ``report.json`` (``rounds``: each round's read-back error).

``animate ... --curves out.csv|json`` solves per-frame ARKit weights of the track just played
against the baked shapes (:func:`faceforge.blendshapes.curves.solve_weights`, bounded least
squares in [0, 1]) and writes them; with ``-o x.glb`` (or ``x.usda``) the file carries the named
targets (USD blend shapes) and that weights animation instead of one target per frame.

Both options are added to the ``animate`` command from here (:func:`extend_animate`: two click
options and a callback around the command's own), so the animate stage module knows nothing of
blendshapes and the import direction stays one way (arkit -> animate).
"""

from __future__ import annotations

from pathlib import Path

import click

from faceforge.pipeline import Stage, register_stage


def run_arkit(ctx):
    """Play the take in ``ctx.params['arkit_take']`` through the baked shapes' controls."""
    import numpy as np

    from faceforge.animation.playback import Timings
    from faceforge.animation.rig import BoundHead
    from faceforge.animation.statics import SettleSettings
    from faceforge.blendshapes.curves import read_weights
    from faceforge.blendshapes.weights_take import play_weights, played_readback, refine_drive
    from faceforge.exceptions import StageError
    from faceforge.io.frame_stream import FrameNpzWriter, open_frames
    from faceforge.io.stagefiles import load_npz, save_json
    from faceforge.pipeline.mapping import stage_mapping

    take = ctx.param("arkit_take")
    names, weights, fps = read_weights(take)
    baked = load_npz(ctx.input("bake") / "shapes.npz")
    head = BoundHead(ctx.input("fit"), ctx.input("bind"), ctx.config, log=ctx.log, cache=ctx.workdir / "cache")
    mapping, _ = stage_mapping(ctx)
    if [str(c) for c in baked["controls"]] != list(head.controls):
        raise StageError("the bake's controls are not this head's; rerun `faceforge bake`", ctx.input("bake"))
    index = {str(n): i for i, n in enumerate(baked["names"])}
    made = np.asarray(baked["made"], dtype=bool)
    cols = [j for j, n in enumerate(names) if n in index and made[index[n]]]
    ignored = [n for j, n in enumerate(names) if j not in cols and np.any(weights[:, j] > 0)]
    if ignored:
        ctx.log(f"shapes not made on this head (their weights are ignored): {', '.join(ignored)}")
    ctx.log(f"{len(weights)} frames at {fps:g} fps, {len(cols)} shapes")
    timings = Timings()
    offline = SettleSettings.from_config(ctx.config) if ctx.config.get("animate.quality") == "offline" else None
    lids = head.eyelids(ctx.config)
    drive, rows = weights[:, cols], [index[names[j]] for j in cols]
    rounds, errors = int(ctx.config.get("animate.arkit_rounds")), []
    if rounds:               # every made shape a column: the correction may drive any of them
        rows = [int(i) for i in np.flatnonzero(made)]
        target = np.zeros((len(weights), len(rows)))
        target[:, [rows.index(index[names[j]]) for j in cols]] = weights[:, cols]
        scratch = ctx.out_dir / "round.npz"
        play_back = played_readback(head, fps, baked, rows, mapping, scratch, lids=lids, offline=offline,
                                    ridge=float(ctx.config.get("curves.ridge")),
                                    smooth=float(ctx.config.get("curves.smooth")))
        drive, errors = refine_drive(play_back, target, rounds, log=ctx.log)
        scratch.unlink(missing_ok=True)
    bar = ctx.progress(None, total=len(weights), desc="frames")
    with FrameNpzWriter(ctx.out_dir / "animation.npz", len(weights), len(head.user_index)) as writer:
        try:
            checker = play_weights(head, drive, fps, baked, rows, mapping, writer, lids=lids, timings=timings,
                                   offline=offline, bar=bar, log=ctx.log)
        finally:
            bar.close()
        writer.close(fps=np.float64(fps), contractions=writer.SPOOLED, controls=np.asarray(head.controls, dtype=str),
                     jaw=writer.SPOOLED, weights=weights, names=np.asarray(names),
                     **({"drive": drive, "drive_shapes": baked["names"][rows]} if rounds else {}))
    jaws = open_frames(ctx.out_dir / "animation.npz", "jaw")   # a map: the few frames the skull test reads
    checks = checker.report(skull=lambda i: head.skull_at(np.asarray(jaws[i]) if i >= 0 else np.zeros(3)))
    save_json(ctx.out_dir / "report.json", {
        "take": str(take), "frames": len(weights), "fps": fps, "shapes": [names[j] for j in cols],
        "ignored": ignored, "rounds": errors, "per_frame_ms": timings.per_frame_ms(), "checks": checks.as_dict()})
    ctx.log(f"{timings.per_frame_ms()['total']:.1f} ms/frame; checks: {'ok' if checks.ok else checks.as_dict()}")


ARKIT = register_stage(Stage(
    name="arkit", deps=("fit", "bind", "calibrate", "bake"),
    config_keys=("solver", "skin.stiffness", "skin.carry", "skin.carry_radius_mm", "skin.join_insertions", "skin.cheek_tether",
                 "skin.lid_hold", "skin.lid_hold_sink", "skin.commissure_fold_deg", "skin.fold_deg", "skin.proxy_fold_limit", "skin.lip_contact_mm", "bind.cheek_muscles", "muscle", "animate", "template",
                 "curves"),
    inputs=("arkit_take", "animate_mapping?", "animate.fap_mapping", "template.skull", "template.muscle_map"),
    outputs=("animation.npz", "report.json"),
    version="11", run=run_arkit, description="play an ARKit weight track through the baked shapes' muscles"))


def write_curves(app, stage: str, curves: str | None, output: str | None) -> bool:
    """Solve the ARKit weights of ``<workdir>/<stage>/animation.npz`` against the baked shapes,
    write them to ``curves`` (.csv Live Link Face, .json) and, when ``output`` is a .glb, the GLB
    of the named targets with that weights animation. Returns whether ``output`` was written.
    Logs the round trip: the shapes mixed by the weights against the simulated frames."""
    import json

    import numpy as np

    from faceforge.blendshapes.curves import near_duplicates, reproduction_error, solve_weights, write_weights
    from faceforge.io.stagefiles import load_npz
    from faceforge.pipeline.stages.bake import bake_params, export_shapes

    app.run_stage("bake", params=bake_params(app, "arkit", None))
    baked = load_npz(app.workspace.stage_dir("bake") / "shapes.npz")
    anim = load_npz(app.workspace.stage_dir(stage) / "animation.npz")
    made = np.asarray(baked["made"], dtype=bool)
    names = [str(n) for n, m in zip(baked["names"], made) if m]
    shapes = baked["shapes"][made]
    frames, fps = anim["frames"], float(anim["fps"])
    w = solve_weights(frames, baked["neutral"], shapes, ridge=float(app.config.get("curves.ridge")),
                      smooth=float(app.config.get("curves.smooth")))
    err, peak = reproduction_error(frames, baked["neutral"], shapes, w)
    app.log(f"animate: curves: {len(names)} shapes x {len(frames)} frames; the mixed shapes reproduce the "
            f"simulated frames to {err:.1%} RMS of the motion (largest vertex error {peak:.4g} units)")
    twins = near_duplicates(baked["neutral"], shapes, names)
    if twins:
        app.log("animate: curves: near-duplicate shapes (a small change of the motion can move weight from one to the "
                "other; cosine of their displacements): "
                + ", ".join(f"{x}/{y} {c:+.3f}" for x, y, c in twins))
    report = app.workspace.stage_dir(stage) / "report.json"
    turn = json.loads(report.read_text()).get("max_head_rotation_deg", [0, 0, 0]) if report.exists() else [0]
    if max(turn, default=0) > 0:
        app.log(f"animate: note: the track turns the head (FAPs 48-50, up to {max(turn):.1f} deg), which no "
                "blendshape makes: the curves fit it as best they can (for the face alone, play it with "
                "--set animate.head_rotation=false)")
    if curves:
        app.log(f"animate: wrote {write_weights(curves, names, w, fps)}")
    if output and Path(output).suffix.lower() in (".glb", ".usda", ".usd"):
        full = np.zeros((len(w), len(made)))
        full[:, made] = w
        app.log(f"animate: wrote {export_shapes(app, output, weights=full, fps=fps)} "
                f"({int(made.size)} named targets, {len(w)} frames of weights)")
        return True
    return False


def _arkit_or_curves(app, orig, arkit, curves, kw):
    """The ``animate`` command with ``--arkit`` / ``--curves`` (module docstring); ``orig`` its own
    callback, ``kw`` its other arguments."""
    from faceforge.exceptions import StageError
    from faceforge.pipeline.outputs import export_outputs
    from faceforge.pipeline.stages.bake import bake_params
    from faceforge.pipeline.workdir_guard import check_outside_workdir

    output, preview = kw.get("output"), kw.get("preview")
    if arkit is not None and any(kw.get(k) is not None for k in ("fap", "expression", "visemes")):
        raise StageError("give exactly one of --fap FILE, --expression NAME or --visemes V1,V2,..., "
                         "or --arkit FILE")
    if curves and Path(curves).suffix.lower() not in (".csv", ".json"):
        raise StageError("--curves writes .csv or .json", curves)
    for path, option in ((output, "-o"), (preview, "--preview"), (curves, "--curves")):
        check_outside_workdir(app.workspace, path, option)
    shapes_out = bool(curves) and bool(output) and Path(output).suffix.lower() in (".glb", ".usda", ".usd")
    from faceforge.io.export import check_output, protect_inputs

    params = app.workspace.load_params()
    inputs = {"mesh": params.get("mesh"), "landmark file": params.get("landmarks"), "FAP track": kw.get("fap"),
              "ARKit take": arkit}
    if curves:                # checked before anything runs, like -o and --preview
        from faceforge.io.writable import check_writable

        protect_inputs(curves, {**inputs, "-o output": output, "--preview": preview})
        check_writable(curves, "--curves")   # (a missing folder failed after the simulation and the bake)
    if arkit is None:
        orig(**{**kw, "output": None if shapes_out else output})
        write_curves(app, "animate", curves, output if shapes_out else None)
        return
    from faceforge.blendshapes.curves import read_weights

    if output:
        check_output(output, inputs)
    if preview:
        protect_inputs(preview, {**inputs, "-o output": output})
    read_weights(arkit)       # a bad take fails before anything runs
    app.run_stage("arkit", params={**bake_params(app, "arkit", None), "arkit_take": str(arkit)},
                  force=kw.get("force", False))
    if curves:
        write_curves(app, "arkit", curves, output if shapes_out else None)
    export_outputs(app, None if shapes_out else output, preview, kw.get("preview_frames"), stage="arkit")


def extend_animate(command) -> None:
    """Add ``--arkit FILE`` and ``--curves FILE`` to the click ``animate`` command (in place)."""
    import functools

    if any(p.name == "arkit" for p in command.params):
        return
    at = next((i for i, p in enumerate(command.params) if p.name == "output"), len(command.params))
    command.params[at:at] = [
        click.Option(["--arkit"], type=click.Path(dir_okay=False, exists=True), default=None,
                     help="Play ARKit blendshape weights instead (Live Link Face CSV, or CSV/JSON of name -> "
                          "weight per frame) through the muscles of the baked shapes (`faceforge bake`)."),
        click.Option(["--curves"], type=click.Path(dir_okay=False), default=None,
                     help="Also write the track's per-frame ARKit weights (.csv Live Link Face, .json), "
                          "solved against the baked shapes; with -o x.glb (or .usda) the file carries the "
                          "named shapes + weights.")]
    orig = command.callback

    @functools.wraps(orig)
    def callback(arkit=None, curves=None, **kw):
        if arkit is None and curves is None:
            return orig(**kw)
        return _arkit_or_curves(click.get_current_context().obj, orig, arkit, curves, kw)

    command.callback = callback


def _extend():
    from faceforge.pipeline.stages.animate import animate_command

    extend_animate(animate_command)


_extend()
