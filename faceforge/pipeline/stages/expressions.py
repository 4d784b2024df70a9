"""The expressions stage: the six basic expressions on the bound head, side by side (paper Fig. 10).

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

Each pose is reached as ``calibrate`` reaches its probes (:func:`faceforge.anatomy.animate.
static_poses`: eased in, then held for ``animate.calibrate.settle_frames`` frames), with the
eyelids (``animate.eyelids``) laid over it.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import click

from faceforge.pipeline import Stage, register_command, register_stage


def run_expressions(ctx):
    """Settle each preset, check it, draw the sheet."""
    import numpy as np

    from faceforge.anatomy.animate import check_animation, static_poses
    from faceforge.io.stagefiles import save_json, save_npz
    from faceforge.mpeg4.expressions import EXPRESSIONS
    from faceforge.pipeline.stages.animate import BoundHead, _mapping, controls
    from faceforge.viz.contact_sheet import contact_sheet

    head = BoundHead(ctx.input("fit"), ctx.input("bind"), ctx.config, log=ctx.log)
    mapping, mapping_path = _mapping(ctx)
    missing = [name for name in EXPRESSIONS if name not in mapping.expressions]
    if missing:
        from faceforge.exceptions import StageError

        raise StageError(f"the mapping has no preset for {', '.join(missing)}", mapping_path)
    names = ["neutral", *EXPRESSIONS]
    faps = np.stack([np.zeros(68), *(mapping.expressions[n] for n in EXPRESSIONS)])
    c, jaw = controls(mapping, faps, head)
    settle = int(ctx.config.get("animate.calibrate.settle_frames"))
    ctx.log(f"{len(EXPRESSIONS)} expressions, {settle} settle frames each")
    poses = static_poses(head.rig, c, jaw, float(ctx.config.get("animate.fps")), settle=settle)
    lids = head.eyelids(ctx.config)
    if lids is not None:
        poses = lids.apply(poses, faps)
    report = {"mapping": mapping_path, "expressions": {}}
    for i, name in enumerate(names):
        checks = check_animation(head.rest, poses[i:i + 1], head.faces,
                                 skull=lambda k, j=jaw[i]: head.skull_at(j if k >= 0 else np.zeros(3)))
        report["expressions"][name] = {"checks": checks.as_dict(), "max_contraction": float(c[i].max(initial=0.0)),
                                       "jaw": jaw[i].tolist()}
        if not checks.ok:
            ctx.log(f"{name}: checks {checks.as_dict()}")
    contact_sheet(ctx.out_dir / "expressions.png", poses, head.faces, range(len(names)), 1.0,
                  cols=4, panel=3.2, labels=names, region=head.rest[:, 1] >= head.bone_heights()[0],
                  title="the six basic expressions (template presets, full intensity)")
    save_npz(ctx.out_dir / "expressions.npz", names=np.asarray(names), poses=head.to_user(poses).astype(np.float32),
             contractions=c, controls=np.asarray(head.controls, dtype=str), jaw=jaw)
    save_json(ctx.out_dir / "report.json", report)


EXPRESSIONS_STAGE = register_stage(Stage(
    name="expressions", deps=("fit", "bind"),
    config_keys=("solver", "skin.stiffness", "skin.carry", "muscle", "animate"),
    inputs=("animate_mapping", "animate.fap_mapping"),
    outputs=("expressions.png", "expressions.npz", "report.json"),
    version="1", run=run_expressions, description="the six basic expressions, side by side (Fig. 10)"))


@click.command("expressions", help="Settle the head into the six basic expressions and draw them side by side.")
@click.option("-o", "--output", type=click.Path(dir_okay=False), default=None,
              help="Also copy the sheet (PNG) here.")
@click.option("--force", is_flag=True, help="Rerun even if up to date.")
@click.pass_obj
def expressions_command(app, output, force):
    from faceforge.exceptions import StageError
    from faceforge.pipeline.stages.animate import playback_mapping

    if output and not str(output).lower().endswith(".png"):
        raise StageError("the sheet is a PNG: give -o a .png path", output)
    mapping = playback_mapping(app, "expressions")
    app.run_stage("expressions", params={"animate_mapping": str(mapping)}, force=force)
    sheet = app.workspace.stage_dir("expressions") / "expressions.png"
    if output:
        Path(output).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(sheet, output)
        sheet = Path(output)
    app.log(f"expressions: wrote {sheet}")


register_command(expressions_command)
