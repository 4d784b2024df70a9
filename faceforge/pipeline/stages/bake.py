"""The bake stage (issue 27): named blendshapes from the muscle simulation.

``faceforge bake [-o head.glb|head.usda|shapes.npz] [--shapes arkit|visemes|expressions|all]``
settles one pose per named shape on the bound head and writes ``<workdir>/bake/``:

shapes.npz
    ``names (k,)``, ``made (k,) bool``, ``neutral (n_user, 3) float32`` and ``shapes (k, n_user, 3)
    float32`` in the user's vertex order and frame (a shape not made is the neutral), per shape
    ``contractions (k, m)`` (columns ``controls (m,)``), ``jaw (k, 3)``, ``lids (k, 68)`` (the
    eyelid FAPs laid over it) and ``gaze (k, 4)`` (the eye pieces' turns, radians: yaw L, pitch L,
    yaw R, pitch R): what ``animate --arkit`` plays.
report.json
    per shape: made or why not, the solve's controls, FAP targets requested and achieved, the
    peak displacement, the physical checks at full weight, approximations; the left/right
    mirror agreement; the Jacobian's and the solve's seconds.
shapes.png
    a contact sheet of the shapes made.

ARKit shapes come from ``templates/arkit_mapping.yaml`` (``--mapping``), solved per head
(:mod:`faceforge.blendshapes.bake`); visemes and expressions are the FAP mapping's presets played
as ``faceforge visemes`` / ``expressions`` settle them. ``-o`` writes the GLB (one morph target per
shape, named as ARKit names them in ``extras.targetNames``; the shapes not made are empty targets
so that every engine finds its 52 slots, and are listed in ``extras.notMade``), USD
(``UsdSkelBlendShape``s) or a copy of the npz.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import click

from faceforge.pipeline import Stage, register_command, register_stage
from faceforge.pipeline.result_checks import keep_going_option
from faceforge.pipeline.workdir_guard import check_outside_workdir

KINDS = ("arkit", "visemes", "expressions")
#: the bake's own bounds on settling a pose (run_bake)
BAKE_TOLERANCE, BAKE_MAX_FRAMES = 1e-4, 60


def run_bake(ctx):
    """Settle each selected shape, check it, write shapes.npz, report.json, shapes.png."""
    from dataclasses import replace

    import numpy as np

    from faceforge.animation.rig import BoundHead
    from faceforge.blendshapes.arkit import load_arkit_mapping
    from faceforge.blendshapes.head import bake_head
    from faceforge.animation.statics import SettleSettings
    from faceforge.geometry.mirror import Mirror
    from faceforge.io.stagefiles import load_npz, save_json, save_npz
    from faceforge.pipeline.mapping import stage_mapping

    kinds = Path(ctx.param("bake_shapes")).read_text().split()
    specs = load_arkit_mapping(ctx.param("arkit_mapping")) if "arkit" in kinds else {}
    head = BoundHead(ctx.input("fit"), ctx.input("bind"), ctx.config, log=ctx.log, cache=ctx.workdir / "cache")
    mapping, mapping_path = stage_mapping(ctx)
    lids = head.eyelids(ctx.config)
    mirror = Mirror.from_arrays(load_npz(ctx.input("fit") / "fit.npz"))
    symmetric = mirror is not None
    s = SettleSettings.from_config(ctx.config)
    # a baked pose stops at 1e-4 of the diagonal a frame and 60 frames at the most (animate.statics
    # when stricter): measured on MakeHuman, 30% fewer frames than 5e-5 / 150 and every shape's
    # FAP error within 0.01 of theirs (the two poses that reach 60 frames oscillate, jaw thrust/yaw)
    s = replace(s, tolerance=max(s.tolerance, BAKE_TOLERANCE), max_frames=min(s.max_frames, BAKE_MAX_FRAMES))
    out = bake_head(head, mapping, specs, kinds, float(ctx.config.get("animate.fps")),
                    s, lids if lids is not None and lids.fields else None,
                    symmetric=symmetric, log=ctx.log,
                    mirror=mirror if ctx.config.get("bake.mirror_shapes") else None,
                    split=tuple(ctx.config.get("bake.split_pairs") or ()))
    save_npz(ctx.out_dir / "shapes.npz", **out.arrays)
    save_json(ctx.out_dir / "report.json", {"mapping": mapping_path, **({"arkit_mapping": str(
        ctx.param("arkit_mapping"))} if specs else {}), **out.report})
    _sheet(ctx.out_dir / "shapes.png", head, out.frames, list(map(str, out.arrays["names"])),
           np.asarray(out.arrays["made"]))


def _sheet(path, head, frames, names, made) -> None:
    """The neutral face and the shapes made, smooth-shaded, framed on the face (above the lowest
    bone, the front half of the head), the mouth's inside dark as the expressions sheet draws it."""
    import numpy as np

    from faceforge.anatomy.tissue import units_per_mm
    from faceforge.viz.head_sheet import cavity
    from faceforge.viz.shape_sheet import shape_sheet

    idx = [i for i, m in enumerate(made) if m]
    rest = head.rest
    region = (rest[:, 1] >= head.bone_heights()[0]) & (rest[:, 2] >= np.median(rest[:, 2]))
    shape_sheet(path, np.concatenate([rest[None], frames[idx]]), head.faces, ["neutral"] + [names[i] for i in idx],
                region=region, title="baked shapes at full weight (faceforge bake)",
                dim=cavity(head, units_per_mm(head.landmarks)))


BAKE = register_stage(Stage(
    name="bake", deps=("fit", "bind", "calibrate"),
    # the bound head rebuilds the muscles from the template (faceforge.animation.rig.muscle_system)
    # not the playback-only keys (head rotation, previews, presets' timing): they cost no rebake
    config_keys=("bake", "solver", "skin.stiffness", "skin.carry", "skin.carry_radius_mm",
                 "skin.join_insertions", "skin.cheek_tether", "skin.lid_hold", "skin.lid_hold_sink", "skin.commissure_fold_deg", "skin.fold_deg", "skin.proxy_fold_limit", "skin.lip_contact_mm",
                 "bind.cheek_muscles", "muscle", "template", "animate.fap_mapping",
                 "animate.fps", "animate.skull_guard", "animate.orientation_guard", "animate.statics",
                 "animate.eyelids", "animate.eyelid_reach", "animate.eyelid_depth", "animate.eyelid_fold_deg", "animate.eyelid_jaw_hold", "animate.eyelid_relative", "animate.jaw_glide",
                 "animate.jaw_glide_slope", "animate.chin_path"),
    inputs=("bake_shapes", "arkit_mapping", "animate_mapping?", "animate.fap_mapping", "template.skull",
            "template.muscle_map"),
    # version 14: the sheet draws the mouth's inside dark; 15: through a z-buffer (viz.zbuffer)
    outputs=("shapes.npz", "report.json", "shapes.png"), version="16", run=run_bake,
    description="named blendshapes (ARKit-52, visemes, expressions) from the muscle simulation"))


def bake_params(app, shapes: str, mapping: str | None) -> dict:
    """The bake stage's params: the selection written to ``<workdir>/inputs/bake_<shapes>.txt`` (its
    content keys the cache), the ARKit mapping and the FAP mapping played."""
    from faceforge.blendshapes.arkit import default_mapping_path
    from faceforge.pipeline.mapping import playback_mapping

    kinds = KINDS if shapes == "all" else (shapes,)
    sel = app.workspace.root / "inputs" / f"bake_{shapes}.txt"
    sel.parent.mkdir(parents=True, exist_ok=True)
    if not sel.exists() or sel.read_text() != " ".join(kinds):
        sel.write_text(" ".join(kinds))
    playback_mapping(app, "bake")
    return {"bake_shapes": str(sel), "arkit_mapping": str(Path(mapping) if mapping else default_mapping_path()),
            "animate_mapping": None}   # forgets one an older faceforge remembered


def export_shapes(app, output: str, weights=None, fps: float = 25.0, names_only=None) -> Path:
    """Write the bake's shapes to ``output`` by suffix: .glb (named morph targets), .usda (USD
    blend shapes), .npz (a copy of shapes.npz). ``weights (F, k)``: an animation of the targets.
    ``names_only``: the shapes to write (default all)."""
    import numpy as np

    from faceforge.exceptions import StageError
    from faceforge.io.export_shapes import read_obj_uvs, write_shapes_glb, write_shapes_usda
    from faceforge.io.export import polygons_from_fan, up_axis_of
    from faceforge.io.mesh import load_mesh
    from faceforge.io.stagefiles import load_npz
    from faceforge.fit.orientation import user_rotation

    src = app.workspace.stage_dir("bake") / "shapes.npz"
    suffix = Path(output).suffix.lower()
    if suffix == ".npz":
        Path(output).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(src, output)
        return Path(output)
    d = load_npz(src)
    names = [str(n) for n in d["names"]]
    keep = [i for i, n in enumerate(names) if names_only is None or n in names_only]
    mesh = app.workspace.load_params().get("mesh")
    if not mesh:
        raise StageError("no mesh remembered in the workdir; run `faceforge fit MESH` first", app.workspace.root)
    v, faces, info = load_mesh(mesh)
    if len(v) != d["neutral"].shape[0]:
        raise StageError(f"has {len(v)} vertices but the bake {d['neutral'].shape[0]}; rerun `faceforge fit`", mesh)
    polygons = polygons_from_fan(faces, info.face_source)
    base = np.asarray(v, dtype=np.float32)
    shapes = base + (d["shapes"][keep] - d["neutral"])       # the user's own neutral + the deltas
    sel = [names[i] for i in keep]
    if suffix == ".glb":
        return write_shapes_glb(output, base, shapes, sel, polygons, uvs=read_obj_uvs(mesh, len(v)),
                                weights=weights, fps=fps, name=Path(mesh).stem,
                                not_made=[names[i] for i in keep if not d["made"][i]])
    if suffix in (".usda", ".usd"):
        return write_shapes_usda(output, base, shapes, sel, polygons, weights=weights, fps=fps,
                                 up_axis=up_axis_of(user_rotation(app.workspace.stage_dir("fit"))))
    raise StageError(f"bake writes .glb, .usda or .npz, not {suffix or 'a folder'}", output)


@click.command("bake", help="Bake named blendshapes (ARKit-52, visemes, expressions) from the muscles.")
@click.option("-o", "--output", type=click.Path(dir_okay=False), default=None,
              help="Also write the shapes: .glb (named morph targets), .usda (USD blend shapes) or .npz.")
@click.option("--shapes", type=click.Choice(["arkit", "visemes", "expressions", "all"]), default="arkit",
              show_default=True, help="Which shapes to bake.")
@click.option("--mapping", type=click.Path(dir_okay=False, exists=True), default=None,
              help="ARKit -> pose mapping [default: templates/arkit_mapping.yaml].")
@click.option("--force", is_flag=True, help="Rebake even if up to date.")
@keep_going_option
@click.pass_obj
def bake_command(app, output, shapes, mapping, force):
    from faceforge.exceptions import StageError

    if output and Path(output).suffix.lower() not in (".glb", ".usda", ".usd", ".npz"):
        raise StageError("bake writes .glb, .usda or .npz", output)
    check_outside_workdir(app.workspace, output, "-o")
    if output:
        from faceforge.io.export import protect_inputs

        params = app.workspace.load_params()
        protect_inputs(output, {"mesh": params.get("mesh"), "landmark file": params.get("landmarks"),
                                "ARKit mapping": mapping})
        from faceforge.io.writable import check_writable

        check_writable(output, "-o")   # a missing folder failed after the bake (issue 28)
    if shapes in ("arkit", "all"):
        from faceforge.blendshapes.arkit import default_mapping_path, load_arkit_mapping

        load_arkit_mapping(mapping or default_mapping_path())     # a bad mapping fails before anything runs
    params = bake_params(app, shapes, mapping)
    app.run_stage("bake", params=params, force=force)
    out = app.workspace.stage_dir("bake")
    app.log(f"bake: {out / 'shapes.npz'}, {out / 'report.json'}, {out / 'shapes.png'}")
    if output:
        app.log(f"bake: wrote {export_shapes(app, output)}")


register_command(bake_command)
