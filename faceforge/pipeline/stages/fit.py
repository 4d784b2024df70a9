"""The fit stage: skull and muscle map morphed into the user's skin (§7).

``faceforge fit skin.obj [--landmarks skin.fdp.yaml]`` writes ``<workdir>/fit/``:

fit.npz (no pickle; head space, mesh units)
    ``skin_vertices (n,3)``, ``skin_faces (m,3)``: the internal (checked, merged) skin;
    ``skin_user_to_internal (n_user,)``: internal vertex of each of the user's vertices;
    ``cranium_vertices``, ``cranium_faces``, ``mandible_vertices``, ``mandible_faces``;
    ``landmark_ids (k,) str``, ``landmark_positions (k,3)``: fitted bone landmarks;
    ``skin_landmark_ids (s,) str``, ``skin_landmark_positions (s,3)``: snapped skin landmarks;
    ``given_landmark_ids``, ``given_landmark_positions``: the positions the file gives, unsnapped
    (the FAPU are measured on these: a pupil of an eyeless mesh is not on the skin);
    ``target_ids``, ``target_positions``: the bone-landmark targets (tissue depth, refit);
    ``jaw_<axis>_point (3,)``, ``jaw_<axis>_direction (3,)`` for each template jaw axis;
    ``muscle_names (q,) str``, ``muscle_vertices (sum,3)``, ``muscle_vertex_start (q+1,)``,
    ``muscle_faces (sum,3)`` (muscle-local ids), ``muscle_face_start (q+1,)``, ``muscle_thickness (q,)``;
    ``muscle_map_names (r,)``, ``muscle_map_points (sum,3)``, ``muscle_map_start (r+1,)``:
    every point of the morphed muscle map; ``similarity (4,4)``: the initial alignment;
    ``user_rotation (3,3)``: ``R`` of :func:`faceforge.geometry.orientation.frame_rotation`,
    head space = the user's coordinates ``@ R.T`` (identity for a +Y-up head facing +Z);
    a skin of more vertices than ``fit.simulation_vertices``: the ``skin_*`` arrays are its
    simulation proxy, plus ``skin_embed_*`` and ``skin_user_faces`` (:mod:`faceforge.fit.proxy`).

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

VERSION = "11"


def run(ctx) -> None:
    """Stage body: read mesh + landmarks + template, fit, write fit.npz, report.json, fit.png."""
    import time

    from faceforge.fit.files import fit_files
    from faceforge.fit.template import load_template
    from faceforge.pipeline.stages.landmarks import landmark_file

    t0 = time.perf_counter()
    mesh_path = ctx.param("mesh")
    lm_path, source = landmark_file(ctx.input("landmarks"))
    if source != "given":
        ctx.log(f"no complete landmark file for {mesh_path}: using the {source} landmarks {lm_path}")
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


def write_outputs(out_dir, result, report, extra) -> None:
    """fit.npz, report.json and fit.png into ``out_dir``."""
    from faceforge.fit.report import npz_arrays
    from faceforge.viz.fit import save_fit_png
    from faceforge.io.stagefiles import save_json, save_npz

    import numpy as np

    from faceforge.fit.files import given_positions

    checked, lm = extra["checked"], extra["landmarks"]
    out_dir = Path(out_dir)
    given = given_positions(extra.get("raw_landmarks"), extra["orientation"].rotation)
    save_npz(out_dir / "fit.npz", user_rotation=extra["orientation"].rotation,
             given_landmark_ids=np.asarray(list(given), dtype=str),
             given_landmark_positions=np.asarray(list(given.values()), dtype=float).reshape(-1, 3),
             **npz_arrays(result, checked.vertices, checked.faces, checked.user_to_internal, lm,
                          extra["template"].layers),
             **({} if extra.get("simulation") is None else extra["simulation"].arrays()))
    save_json(out_dir / "report.json", report)
    from faceforge.fit.muscles import fitted_muscle_map
    from faceforge.io.stagefiles import save_yaml

    save_yaml(out_dir / "muscle_map.yaml",
              fitted_muscle_map(extra["template"].specs, result.muscle_points),
              header="the template muscle map carried into this head by the fit (points in head units);\n"
                     "load with faceforge.anatomy.muscles.muscle_map.load_muscle_map(path, fitted skull)")
    layers = [("cranium", result.cranium, result.cranium_faces, (0.93, 0.91, 0.84)),
              ("mandible", result.mandible, result.mandible_faces, (0.88, 0.86, 0.78))]
    layers += [(n, v, f, (0.78, 0.25, 0.22)) for n, v, f in result.muscles]
    targets = np.vstack([result.targets, result.enhancement_targets])
    save_fit_png(out_dir / "fit.png", checked.vertices, checked.faces, layers, points=targets,
                 title=f"fit: {Path(report['mesh']['path']).name} ({len(result.targets)} landmark and "
                       f"{len(result.enhancement_targets)} enhancement targets)")


def compile_solver_ahead(log) -> None:
    """``Stage.background`` of fit and bind: on a fresh install the solver's kernels compile in
    a background process while they run (:mod:`faceforge.pbd.compile_ahead`)."""
    from faceforge.pbd.compile_ahead import start

    start(log)


STAGE = register_stage(Stage(
    name="fit", deps=("landmarks",), config_keys=("fit", "template"),
    inputs=("mesh", "landmarks?", "template.skull", "template.muscle_map"),
    outputs=("fit.npz", "report.json", "fit.png", "muscle_map.yaml"), version=VERSION, run=run,
    description="fit the skull and muscle map into the skin (§7)", background=compile_solver_ahead))


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

    if landmarks is None:   # the file next to the mesh, if any; else the landmarks are detected
        landmarks = str(default_landmark_path(mesh)) if default_landmark_path(mesh).exists() else None
    if orientation is not None:
        app.add_sets(f"fit.orientation={orientation}")
    statuses = app.run_stage("fit", params={"mesh": mesh, "landmarks": landmarks}, force=force)
    if any(s.ran and s.stage.name == "fit" for s in statuses):
        app.log(f"fit: wrote {app.workspace.stage_dir('fit')}")


register_command(command)
