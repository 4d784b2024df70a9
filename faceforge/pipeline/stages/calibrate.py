"""The calibrate stage: the head's own FAP -> muscle mapping (paper §9).

``faceforge calibrate`` writes ``<workdir>/calibrate/``: ``fap_mapping.yaml`` (the mapping with
fitted response curves and measured jaw couplings), ``report.json`` and ``report.txt`` (per FAP:
requested, achieved, relative error). It is cached and upstream of animate, expressions, visemes,
bake and arkit, so they always play the head's own mapping: it reruns when the head (fit, bind),
the template or a simulation setting changes, never for a new FAP track. With
``animate.calibrate.enabled: false`` it writes the template mapping as it is.
"""

from __future__ import annotations

import click

from faceforge.pipeline import Stage, register_command, register_stage
from faceforge.pipeline.mapping import mapping_digest_without_presets, mapping_template_path


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
    config = without_lip_contact(ctx.config)
    head = BoundHead(ctx.input("fit"), ctx.input("bind"), config, log=ctx.log, cache=ctx.workdir / "cache")
    result = calibrate_head(head, template, config, log=ctx.log, progress=ctx.progress)
    calibrated, rows, summary, lips, probes = (result.mapping, result.rows, result.summary, result.lips,
                                               result.probes)
    save_fap_mapping(calibrated, ctx.out_dir / "fap_mapping.yaml",
                     header=f"calibrated by `faceforge calibrate` from {template_path}\n"
                            f"median relative error {summary['all']['median_relative_error']}")
    save_json(ctx.out_dir / "report.json", {
        "summary": summary, "open_jaw_lip_separation": lips,
        "fapu": head.fapu.as_dict(), "jaw_levers": {"pitch": head.levers.pitch, "yaw": head.levers.yaw},
        "rows": [r.as_dict() for r in rows], "statics": result.statics, "mirrored_entries": result.mirrored,
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


def without_lip_contact(config):
    """``config`` read through with ``skin.lip_contact_mm`` 0: the calibration fits the muscles'
    mapping with the lips free. A lip FAP's entry drives the inner and the outer lip point together
    and is fitted to their mean; with the contact on, a raised lower lip's inner point is stopped by
    the upper lip (106 of 150 MNS on the MakeHuman sample) while the outer one is not, and the fit
    drove the outer point to 188 (docs/notes/lips17.md). Stopped by the other lip is what contact
    means in playback, not a weak muscle to drive harder. Every other key is read from ``config``
    itself (so a stage's record of what it read stays whole)."""
    return _Overridden(config, {"skin.lip_contact_mm": 0.0})


class _Overridden:
    """A config whose ``get`` answers ``values`` (key -> value) for those keys and defers the rest."""

    def __init__(self, config, values: dict):
        self._config, self._values = config, dict(values)

    def get(self, key, *args, **kwargs):
        return self._values[key] if key in self._values else self._config.get(key, *args, **kwargs)

    def __getattr__(self, name):
        return getattr(self._config, name)


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
    # cost a recalibration; nor does the lips' contact (skin.lip_contact_mm: calibrated without it,
    # :func:`without_lip_contact`)
    name="calibrate", deps=("fit", "bind"), config_keys=(
        "solver", "skin.stiffness", "skin.carry", "skin.carry_radius_mm",
        "skin.join_insertions", "skin.cheek_tether", "skin.lid_hold", "skin.lid_hold_sink", "skin.commissure_fold_deg", "skin.fold_deg", "skin.proxy_fold_limit",
        "bind.cheek_muscles", "muscle", "animate.fap_mapping", "animate.fps",
        "animate.skull_guard", "animate.orientation_guard", "animate.calibrate", "animate.jaw_glide",
        "animate.jaw_glide_slope", "animate.chin_path", "animate.statics", "template"),
    inputs=("animate.fap_mapping", "animate.calibrate.magnitudes", "template.skull", "template.muscle_map"),
    digests={"animate.fap_mapping": mapping_digest_without_presets},
    outputs=("fap_mapping.yaml", "report.json", "report.txt"),
    version="9", run=run_calibrate, description="measure and fit the FAP -> muscle mapping (§9)"))


@click.command("calibrate", help="Measure how precisely FAPs move the skin and fit the mapping (§9).")
@click.option("--force", is_flag=True, help="Rerun even if up to date.")
@click.pass_obj
def calibrate_command(app, force):
    statuses = app.run_stage("calibrate", force=force)
    out = app.workspace.stage_dir("calibrate")
    app.log((out / "report.txt").read_text())
    ran = any(s.ran and s.stage.name == "calibrate" for s in statuses)
    app.log(f"calibrate: {'wrote' if ran else 'kept'} {out / 'fap_mapping.yaml'} (used by `faceforge animate`)")


register_command(calibrate_command)
