"""The ``batch`` command: fit, bind and animate many heads, in parallel and resumable (issue 8).

``faceforge batch heads/*.obj --fap track.fap --jobs 4 --out runs`` or ``faceforge batch
manifest.yaml``; the library is :mod:`faceforge.pipeline.batch`. Batch is not a stage
(it runs the stages of many workdirs), so this module registers a command only.
"""

from __future__ import annotations

import click

from faceforge.pipeline import register_command
from faceforge.pipeline.result_checks import keep_going_option

_EXPRESSIONS = ("joy", "sadness", "surprise", "anger", "disgust", "fear")


@click.command("batch", help="""Run fit, bind and animate for many heads, each in <out>/<name>/.

\b
faceforge batch heads/*.obj --fap track.fap --jobs 4 --out runs
faceforge batch manifest.yaml --scheduler tcp://host:8786

INPUTS are head meshes (landmarks: <mesh stem>.fdp.yaml next to each, found
automatically where there is none) or one manifest (.yaml). A rerun skips stages already done. --config/--set of the faceforge group apply
to every head. Exit status: 0 all heads ok, 1 some failed, 3 the only failures are results that
failed their checks (--keep-going accepts them), 2 bad invocation or manifest.
Writes <out>/batch_report.json.""")
@click.argument("inputs", nargs=-1, required=True, type=click.Path(dir_okay=False))
@click.option("--fap", type=click.Path(dir_okay=False), default=None, help="FAP track played on every head.")
@click.option("--expression", type=click.Choice(_EXPRESSIONS), default=None,
              help="Play a basic expression instead of --fap.")
@click.option("--intensity", type=click.FloatRange(0.0, 1.0), default=None, help="Peak of --expression [1].")
@click.option("--seconds", type=click.FloatRange(min=0.04), default=None,
              help="Length of --expression [default: animate.expression_seconds].")
@click.option("--out", type=click.Path(file_okay=False), default="batch", show_default=True,
              help="Folder of the head workdirs and the report.")
@click.option("-o", "--output-suffix", "output", default=None, metavar="SUFFIX",
              help="Export each animation as <out>/<name>/<name>SUFFIX (.pc2, .mdd, .glb; / for OBJ files).")
@click.option("-j", "--jobs", type=click.IntRange(min=1), default=None,
              help="Local worker processes [default: CPU count]; 1 runs in this process.")
@click.option("--scheduler", default=None, metavar="tcp://HOST:PORT",
              help="Run on this Dask distributed scheduler instead (needs faceforge[dask]).")
@click.option("--plugin", "plugins", multiple=True, metavar="MODULE|FILE.py",
              help="Import this in every worker before running (e.g. extra stages); repeatable.")
@keep_going_option
@click.pass_context
def command(ctx, inputs, fap, expression, intensity, seconds, out, output, jobs, scheduler, plugins):
    import os
    import sys
    import time
    from pathlib import Path

    from faceforge.exceptions import StageError
    from faceforge.io.config import parse_sets
    from faceforge.io.stagefiles import save_json
    from faceforge.pipeline import batch
    from faceforge.pipeline.stage import stage_order

    app = ctx.obj
    root = ctx.find_root().params
    overrides = batch.flatten(parse_sets(root.get("sets") or ()).tree) if root.get("sets") else {}
    config_file = os.path.abspath(root["config_file"]) if root.get("config_file") else None
    shared = batch.SharedOptions(fap=fap, expression=expression,
                                 intensity=1.0 if intensity is None else intensity, seconds=seconds,
                                 output=output, overrides=overrides, config_file=config_file,
                                 plugins=tuple(os.path.abspath(p) if p.endswith(".py") else p for p in plugins))
    batch.import_plugins(shared.plugins)
    stage_order(shared.targets)          # every stage registered (plugins included), before any work
    manifests = [p for p in inputs if batch.is_manifest(p)]
    if manifests and len(inputs) > 1:
        raise StageError("give either one manifest or head meshes, not both", manifests[0])
    if manifests:
        given = [k for k, v in (("fap", fap), ("expression", expression), ("intensity", intensity),
                                ("seconds", seconds), ("output", output)) if v is not None]
        heads = batch.load_manifest(manifests[0], out, shared, given)
    else:
        heads = batch.jobs_from_meshes(list(inputs), out, shared)

    if app.keep_going:
        from dataclasses import replace

        heads = [replace(h, keep_going=True) for h in heads]
    n = min(jobs or os.cpu_count() or 1, len(heads))
    executor = f"dask {scheduler}" if scheduler else (f"processes x{n}" if n > 1 else "in-process")
    app.log(f"batch: {len(heads)} heads -> {Path(out).absolute()} ({executor})")
    from tqdm import tqdm

    bar = tqdm(total=len(heads), desc="heads", unit="head", file=sys.stderr, disable=not app.progress,
               dynamic_ncols=True)

    finished = {}

    def on_result(result):
        finished[result.workdir] = result
        line = f"{result.name}: {result.status} in {result.seconds:.1f} s" + (f": {result.error}" if result.error else "")
        if app.verbosity >= 0 or result.error:
            bar.write(line, file=sys.stderr)
        bar.update(1)

    start = time.perf_counter()
    interrupted = False
    try:
        results = batch.run_batch(heads, n_jobs=jobs, scheduler=scheduler, on_result=on_result)
    except KeyboardInterrupt:
        interrupted = True
        results = [finished.get(h.workdir) or batch.HeadResult(h.name, h.workdir, h.mesh, status="interrupted",
                                                               error="interrupted") for h in heads]
    finally:
        bar.close()
    report = batch.batch_report(results, out, time.perf_counter() - start, executor)
    Path(out).mkdir(parents=True, exist_ok=True)
    path = save_json(Path(out) / batch.REPORT_NAME, report)
    if app.verbosity >= 0:
        click.echo(batch.format_summary(results))
        click.echo(f"report: {path}")
    if interrupted:
        click.echo("faceforge: batch interrupted; run the same command again to resume", err=True)
        ctx.exit(130)
    if report["failed"]:
        failed = [r for r in results if r.status == "failed"]
        ctx.exit(3 if all(r.failed_checks for r in failed) else 1)


register_command(command)
