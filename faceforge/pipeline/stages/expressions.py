"""The sheet stages: the six basic expressions (paper Fig. 10) and the fourteen visemes on the
bound head, side by side.

``faceforge expressions [-o sheet.png]`` settles the head into each of the six presets of the
mapping (joy, sadness, anger, fear, disgust, surprise; the template's presets, as ``animate``
plays them) at full intensity, and writes ``<workdir>/expressions/``:

expressions.png
    the neutral face and the six expressions (two rows), front view, the head framed without
    its neck.
expressions.npz
    ``names (7,)``, ``poses (7, n_user, 3) float32`` in the user's vertex order and frame
    (the neutral face first), ``contractions (7, m)``, ``controls (m,)``, ``jaw (7, 3)``.
report.json
    per expression: the physical checks (inverted triangles, skin inside the skull, folded
    edges), its largest contraction and jaw opening.

``faceforge visemes [-o sheet.png]`` does the same for the mapping's ``visemes`` table (p_b_m
... u, those it has) into ``<workdir>/visemes/`` (``visemes.png``, five columns;
``visemes.npz``; ``report.json``).

Each pose is eased in from rest and held until the skin stops moving (:func:`faceforge.animation.
statics.settle`, ``animate.statics``; the report gives the frames and the residual), with the
eyelids (``animate.eyelids``) laid over it.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import click

from faceforge.pipeline import Stage, register_command, register_stage
from faceforge.pipeline.result_checks import keep_going_option
from faceforge.pipeline.workdir_guard import check_outside_workdir


def run_expressions(ctx):
    """Settle each of the six expression presets, check it, draw the sheet."""
    from faceforge.mpeg4.expressions import EXPRESSIONS

    def rows(mapping, mapping_path):
        missing = [name for name in EXPRESSIONS if name not in mapping.expressions]
        if missing:
            from faceforge.exceptions import StageError

            raise StageError(f"the mapping has no preset for {', '.join(missing)}", mapping_path)
        return {name: mapping.expressions[name] for name in EXPRESSIONS}

    _preset_sheet(ctx, "expressions", rows, cols=2,
                  title="the six basic expressions (template presets, full intensity)")


def run_visemes(ctx):
    """Settle each viseme of the mapping's table, check it, draw the sheet."""
    from faceforge.mpeg4.visemes import VISEMES

    def rows(mapping, mapping_path):
        if not mapping.visemes:
            from faceforge.exceptions import StageError

            raise StageError("the mapping has no visemes table", mapping_path)
        missing = [name for name in VISEMES if name not in mapping.visemes]
        if missing:
            ctx.log(f"the mapping has no shape for {', '.join(missing)}: left out")
        return {name: mapping.visemes[name] for name in VISEMES if name in mapping.visemes}

    _preset_sheet(ctx, "visemes", rows, cols=3, title="the MPEG-4 visemes (template shapes)")


def _preset_sheet(ctx, stem: str, rows, cols: int, title: str) -> None:
    """The shared body of the sheet stages: ``rows(mapping, path) -> {name: (68,) FAPs}`` (in
    sheet order) are settled after the neutral face, checked, and written as ``<stem>.png``,
    ``<stem>.npz`` (``names``, ``poses`` in the user's order, ``contractions``, ``controls``,
    ``jaw``) and ``report.json`` (per pose: checks, largest contraction, jaw DOFs)."""
    import numpy as np

    from faceforge.animation.checks import check_animation
    from faceforge.io.stagefiles import save_json, save_npz
    from faceforge.animation.controls import controls
    from faceforge.animation.rig import BoundHead
    from faceforge.pipeline.mapping import stage_mapping
    from faceforge.viz.head_sheet import head_sheet

    head = BoundHead(ctx.input("fit"), ctx.input("bind"), ctx.config, log=ctx.log, cache=ctx.workdir / "cache")
    mapping, mapping_path = stage_mapping(ctx)
    presets = rows(mapping, mapping_path)
    names = ["neutral", *presets]
    faps = np.stack([np.zeros(68), *presets.values()])
    c, jaw = controls(mapping, faps, head)
    poses, settled = settled_poses(head, c, jaw, ctx.config)
    statics = settled.as_dict()
    ctx.log(f"{len(presets)} {stem}, each held until it converged: {statics['frames_per_pose_median']:g} frames "
            f"(median), residual at most {statics['residual_max']:.1e} of the diagonal, {statics['unconverged']} "
            "unconverged")
    lids = head.eyelids(ctx.config)
    if lids is not None:
        poses = lids.apply(poses, faps, jaw)
    report = {"mapping": mapping_path, "statics": statics, stem: {}}
    for i, name in enumerate(names):
        checks = check_animation(head.rest, poses[i:i + 1], head.faces, inside_at_rest=head.inside_at_rest(),
                                 skull=lambda k, j=jaw[i]: head.skull_at(j if k >= 0 else np.zeros(3)))
        head.check_carried(checks, poses[i:i + 1])
        report[stem][name] = {"checks": checks.as_dict(), "max_contraction": float(c[i].max(initial=0.0)),
                              "jaw": jaw[i].tolist(), "frames": settled.frames[i],
                              "residual": settled.residual[i], "converged": settled.converged[i]}
        if not checks.ok:
            ctx.log(f"{name}: checks {checks.as_dict()}")
    head_sheet(ctx.out_dir / f"{stem}.png", head, poses, names, title, cols)
    save_npz(ctx.out_dir / f"{stem}.npz", names=np.asarray(names), poses=head.to_user(poses).astype(np.float32),
             contractions=c, controls=np.asarray(head.controls, dtype=str), jaw=jaw)
    save_json(ctx.out_dir / "report.json", report)


def settled_poses(head, c, jaw, config):
    """The held poses (k, n, 3) of controls ``c`` (k, m) and ``jaw`` (k, 3), each from rest and
    solved until the skin stops moving (:func:`faceforge.animation.statics.settle`,
    ``animate.statics``), and how they settled (a :class:`~faceforge.animation.statics.SettleStats`,
    a pose each)."""
    from faceforge.animation.statics import SettleSettings, SettleStats, settle

    stats = SettleStats()
    poses = settle(head.rig, c, jaw, float(config.get("animate.fps")), SettleSettings.from_config(config),
                   stats=stats)
    head.rig.reset()
    return poses, stats


_SHEET_STAGE = dict(deps=("fit", "bind", "calibrate"),
                    config_keys=("solver", "skin.stiffness", "skin.carry", "skin.carry_radius_mm",
                                 "skin.join_insertions", "skin.cheek_tether", "skin.lid_hold", "skin.lid_hold_sink", "skin.commissure_fold_deg", "skin.fold_deg", "skin.proxy_fold_limit", "skin.lip_contact_mm",
                                 "bind.cheek_muscles", "muscle", "animate", "template"),
                    inputs=("animate_mapping?", "animate.fap_mapping", "template.skull", "template.muscle_map"))

# versions 12 / 11: the sheets' faces drawn through a z-buffer (viz.zbuffer)
EXPRESSIONS_STAGE = register_stage(Stage(
    name="expressions", **_SHEET_STAGE, outputs=("expressions.png", "expressions.npz", "report.json"),
    version="13", run=run_expressions, description="the six basic expressions, side by side (Fig. 10)"))

VISEMES_STAGE = register_stage(Stage(
    name="visemes", **_SHEET_STAGE, outputs=("visemes.png", "visemes.npz", "report.json"),
    version="12", run=run_visemes, description="the fourteen MPEG-4 visemes, side by side"))


def _sheet_command(stem: str, help_text: str):
    """The command of a sheet stage: ``faceforge <stem> [-o sheet.png] [--force]``."""

    @click.command(stem, help=help_text)
    @click.option("-o", "--output", type=click.Path(dir_okay=False), default=None,
                  help="Also copy the sheet (PNG) here.")
    @click.option("--force", is_flag=True, help="Rerun even if up to date.")
    @keep_going_option
    @click.pass_obj
    def command(app, output, force):
        from faceforge.exceptions import StageError
        from faceforge.pipeline.mapping import playback_mapping

        if output and not str(output).lower().endswith(".png"):
            raise StageError("the sheet is a PNG: give -o a .png path", output)
        check_outside_workdir(app.workspace, output, "-o")
        playback_mapping(app, stem)
        app.run_stage(stem, params={"animate_mapping": None}, force=force)   # forgets an old one
        sheet = app.workspace.stage_dir(stem) / f"{stem}.png"
        if output:
            Path(output).parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(sheet, output)
            sheet = Path(output)
        app.log(f"{stem}: wrote {sheet}")

    return command


expressions_command = _sheet_command(
    "expressions", "Settle the head into the six basic expressions and draw them side by side.")
visemes_command = _sheet_command(
    "visemes", "Settle the head into the fourteen MPEG-4 visemes and draw them side by side.")
register_command(expressions_command)
register_command(visemes_command)
