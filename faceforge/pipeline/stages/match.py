"""The match stage: the muscle pose of a sculpted or scanned expression of the head (issue 25 item 2).

``faceforge match POSED [-o matched.obj]`` takes a posed copy of the user's mesh (the same vertices
in the same order, frame and units: a sculpted shape key, a scan registered to the head, an
expression of another rig on this topology), solves the muscle contractions and jaw pose whose
settled skin best reproduces its displacement (:class:`faceforge.blendshapes.match.FieldMatcher`:
a Jacobian of every muscle and jaw DOF, a bounded least-squares solve, Gauss-Newton refinements
through the simulation) and writes ``<workdir>/match/``:

match.npz
    ``target``, ``matched`` (n_user, 3) float32: the posed mesh given and the settled one, in the
    user's order and frame; ``controls (q,)``, ``x (q,)``: the solve's controls and values
    (contractions in [0, max], jaw pitch and yaw in rad, protrusion in the head's units);
    ``contractions (m,)`` in the head's column order (``columns``), ``jaw (3,)``.
match.png
    the neutral face, the target and the matched pose, smooth-shaded, each with its heat map.
report.json
    the agreement (cosine of the two displacement fields, magnitude ratio |matched| / |target|,
    issue 25's bounds), the relative residual after each solve step, the controls used (jaw in
    degrees and mm), the largest motion of target and result in mm, the physical checks of the
    matched pose, the seconds.

The eyelids are kinematic: their FAPs 19-22 are solved with the muscles and laid over the pose as
playback lays them (``animate.eyelids``; the report gives them as ``lid.19`` ... in IRISD).
Depends on fit and bind only: the solve uses the template mapping's muscles and jaw limits, not
the calibrated gains.
"""

from __future__ import annotations

from pathlib import Path

import click

from faceforge.pipeline import Stage, register_command, register_stage
from faceforge.pipeline.result_checks import keep_going_option
from faceforge.pipeline.workdir_guard import check_outside_workdir

#: a target whose median vertex is farther than this share of the head's diagonal from the
#: head's is not this head posed (another vertex order, scale, frame or mesh)
FAR = 0.05


def read_target(path, neutral, rigid: bool = False):
    """The displacement ``(n_user, 3)`` of the posed mesh at ``path`` from ``neutral (n_user, 3)``
    (the user's mesh) and the rigid motion (4, 4) of its still part (:func:`faceforge.geometry.rigid.
    still_part_motion`), taken out of the displacement when ``rigid``; a one-line error when it is
    not the head posed."""
    import numpy as np

    from faceforge.exceptions import StageError
    from faceforge.geometry.rigid import still_part_motion
    from faceforge.io.mesh import load_mesh

    v, _, _ = load_mesh(path)
    if len(v) != len(neutral):
        raise StageError(f"has {len(v)} vertices, the head {len(neutral)}: the target must be the head's own mesh "
                         "posed (the same vertices in the same order)", path)
    v = np.asarray(v, dtype=float)
    motion, _ = still_part_motion(neutral, v)
    aligned = (v - motion[:3, 3]) @ motion[:3, :3]    # back onto the head: the still part's motion undone
    delta = (aligned if rigid else v) - neutral
    diagonal = float(np.linalg.norm(np.ptp(neutral, axis=0)))

    def far(d):
        return float(np.median(np.linalg.norm(d, axis=1))) / diagonal

    if far(delta) > FAR:
        hint = ("it lies on the head once its head motion is taken out: give --rigid" if not rigid and
                far(aligned - neutral) <= FAR else "the same vertex order, frame and units are needed")
        raise StageError(f"is not the head posed: its vertices lie a median {far(delta):.0%} of the head's size from "
                         f"the head's ({hint})", path)
    if np.abs(delta).max() <= 1e-9 * diagonal:
        raise StageError("is the head at rest: nothing to match", path)
    return delta, motion


def run_match(ctx):
    """Solve the muscle pose of ``ctx.params['match_target']``; write match.npz, match.png, report.json."""
    import numpy as np

    from faceforge.animation.fap_mapping import load_fap_mapping
    from faceforge.animation.rig import BoundHead
    from faceforge.animation.statics import SettleSettings
    from faceforge.blendshapes.match import GOOD_COSINE, GOOD_RATIO, FieldMatcher, match_posed
    from faceforge.io.stagefiles import save_json, save_npz
    from faceforge.pipeline.mapping import mapping_template_path
    from faceforge.viz.head_sheet import head_sheet

    target_path = ctx.param("match_target")
    head = BoundHead(ctx.input("fit"), ctx.input("bind"), ctx.config, log=ctx.log, cache=ctx.workdir / "cache")
    neutral = head.to_user(head.rest[None])[0]
    rigid = bool(ctx.config.get("match.rigid"))
    delta, motion = read_target(target_path, neutral, rigid)
    mapping = load_fap_mapping(mapping_template_path(ctx.config))
    matcher = FieldMatcher(head, mapping, float(ctx.config.get("animate.fps")), SettleSettings.from_config(ctx.config),
                           lids=head.eyelids(ctx.config))
    m, report = match_posed(head, matcher, delta, motion, rigid, log=ctx.log)
    save_json(ctx.out_dir / "report.json", {"target": str(target_path), **report})
    target_work = head.rest.copy()
    target_work[head.user_index] = (neutral + delta) @ head.user_rotation.T      # user = head @ R
    head_sheet(ctx.out_dir / "match.png", head, np.stack([head.rest, target_work, m.frame]),
               ["neutral", "target", f"matched (cosine {m.cosine:.2f}, size x{m.ratio:.2f})"],
               f"{Path(target_path).name} matched by the muscles", cols=3)
    save_npz(ctx.out_dir / "match.npz", target=(neutral + delta).astype(np.float32),
             matched=(neutral + m.field).astype(np.float32), controls=np.asarray(matcher.names, dtype=str),
             x=m.x, contractions=m.contractions, columns=np.asarray(head.controls, dtype=str), jaw=m.jaw)
    shown = report["controls"]
    ctx.log(f"cosine {m.cosine:.3f}, size x{m.ratio:.3f} ({'within' if m.good else 'outside'} cosine >= "
            f"{GOOD_COSINE}, size {GOOD_RATIO[0]}-{GOOD_RATIO[1]}); "
            + ", ".join(f"{n} {v:g}" for n, v in sorted(shown.items(), key=lambda kv: -abs(kv[1]))[:6]))


MATCH_STAGE = register_stage(Stage(
    name="match", deps=("fit", "bind"),
    config_keys=("match", "solver", "skin.stiffness", "skin.carry", "skin.carry_radius_mm", "skin.join_insertions",
                 "skin.cheek_tether", "skin.lid_hold", "skin.lid_hold_sink", "skin.commissure_fold_deg", "skin.fold_deg", "skin.proxy_fold_limit",
                 "skin.lip_contact_mm", "bind.cheek_muscles", "muscle", "animate", "template"),
    inputs=("match_target", "animate.fap_mapping", "template.skull", "template.muscle_map"),
    # version 4: the sheet through a z-buffer (viz.zbuffer)
    outputs=("match.npz", "match.png", "report.json"),
    version="5", run=run_match, description="the muscle pose of a posed copy of the head"))


@click.command("match", help="Find the muscle contractions and jaw pose that reproduce a posed copy of the head.")
@click.argument("target", type=click.Path(dir_okay=False, exists=True))
@click.option("-o", "--output", type=click.Path(dir_okay=False), default=None,
              help="Also write the matched pose as a mesh (.obj keeps your polygons; .ply, .off, .stl, .glb).")
@click.option("--rigid/--no-rigid", default=None,
              help="Take the target's head motion out first (a scan whose whole head moved); remembered "
                   "[default: off].")
@click.option("--force", is_flag=True, help="Rerun even if up to date.")
@keep_going_option
@click.pass_obj
def match_command(app, target, output, rigid, force):
    from faceforge.exceptions import StageError

    if rigid is not None:
        app.add_sets(f"match.rigid={'true' if rigid else 'false'}")

    check_outside_workdir(app.workspace, output, "-o")
    params = app.workspace.load_params()
    if output:
        from faceforge.io.export import protect_inputs
        from faceforge.io.writable import check_writable

        suffix = Path(output).suffix.lower()
        if suffix not in (".obj", ".ply", ".off", ".stl", ".glb"):
            raise StageError(f"match writes .obj, .ply, .off, .stl or .glb, not {suffix or 'a folder'}", output)
        protect_inputs(output, {"mesh": params.get("mesh"), "landmark file": params.get("landmarks"),
                                "target": target})
        check_writable(output, "-o")
    mesh = params.get("mesh")
    if mesh and Path(mesh).is_file():   # a target that is not the head posed fails before the head is built
        from faceforge.io.mesh import load_mesh

        read_target(target, load_mesh(mesh)[0], bool(app.config.get("match.rigid")))
    app.run_stage("match", params={"match_target": str(target)}, force=force)
    out = app.workspace.stage_dir("match")
    app.log(f"match: {out / 'report.json'}, {out / 'match.png'}")
    if output:
        app.log(f"match: wrote {_export(app, out / 'match.npz', output, params.get('mesh'))}")


def _export(app, npz: Path, output: str, mesh) -> Path:
    """The matched pose as a mesh at ``output``: the user's polygons for .obj (their mesh read again),
    its triangles otherwise."""
    from faceforge.exceptions import StageError
    from faceforge.io.export import polygons_from_fan
    from faceforge.io.export_obj import write_obj
    from faceforge.io.mesh import load_mesh, save_mesh
    from faceforge.io.stagefiles import load_npz

    if not mesh:
        raise StageError("no mesh remembered in the workdir; run `faceforge fit MESH` first", app.workspace.root)
    matched = load_npz(npz)["matched"].astype(float)
    v, faces, info = load_mesh(mesh)
    if len(v) != len(matched):
        raise StageError(f"has {len(v)} vertices but the match {len(matched)}; rerun `faceforge fit`", mesh)
    if Path(output).suffix.lower() == ".obj":
        return write_obj(output, matched, polygons_from_fan(faces, info.face_source),
                         comment=f"faceforge match of {Path(mesh).name}")
    return save_mesh(output, matched, faces)


register_command(match_command)
