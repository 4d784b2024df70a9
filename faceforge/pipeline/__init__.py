"""Stages, the stage cache and the runner (issue 2).

Adding a stage and its command (one file, ``faceforge/pipeline/stages/<name>.py``)::

    \"\"\"The bind stage: skin constraints and anchors (paper §8).\"\"\"
    import click

    from faceforge.pipeline import Stage, register_command, register_stage


    def run(ctx):                                   # ctx: StageContext
        from faceforge.io.stagefiles import load_npz, save_json, save_npz   # heavy imports here
        fit = load_npz(ctx.input("fit") / "fit.npz")
        reach = ctx.config.get("bind.max_ray_distance")     # read only keys under config_keys
        for _ in ctx.progress(range(10), desc="anchors"):
            ...
        save_npz(ctx.out_dir / "bind.npz", anchors=...)
        save_json(ctx.out_dir / "report.json", {...})


    STAGE = register_stage(Stage(
        name="bind", deps=("fit",), config_keys=("bind",),   # a bind.* change reruns bind
        inputs=(), outputs=("bind.npz", "report.json"), version="1", run=run,
        description="bind the skin to muscles and bone (§8)"))


    @click.command("bind", help="Bind the skin to muscles and bone (§8).")
    @click.option("--force", is_flag=True, help="Rerun even if up to date.")
    @click.pass_obj
    def command(app, force):
        app.run_stage("bind", force=force)


    register_command(command)

``app`` is the CLI's :class:`faceforge.cli.App`: ``app.run_stage(name, params={...},
force=...)`` remembers ``params`` (input paths; those named in a stage's
``inputs`` are made absolute) in ``<workdir>/faceforge.yaml``, brings the stage and
everything upstream up to date, and returns the statuses; ``app.workspace.stage_dir(name)``
is where a stage's files are. Deps are looked up by name when a stage runs, so
module order does not matter.
"""

from faceforge.pipeline.stage import (
    COMMANDS,
    STAGES,
    Stage,
    StageContext,
    discover,
    downstream,
    get_stage,
    register_command,
    register_stage,
    stage_order,
)

__all__ = [
    "COMMANDS", "STAGES", "Stage", "StageContext", "discover", "downstream", "get_stage",
    "register_command", "register_stage", "stage_order",
]
