"""The bind stage: skin constraints, anchors and influence map (paper §8).

Reads the fit stage's folder, cuts the lips where they are joined
(:mod:`faceforge.skin.mouth`), binds every skin vertex to a muscle or the
skull by ray casting (:mod:`faceforge.skin.binding`) and computes the
influence map (:mod:`faceforge.skin.influence`). Writes:

``bind.npz``
    :meth:`faceforge.skin.head.BoundSkin.as_arrays`: the working skin
    (``vertices``, ``faces``; the first ``n_user`` vertices are the user's, in
    order, appended vertex ``n_user + i`` duplicates ``duplicate_source[i]``),
    the anchors (``anchor_*``, ``status``, ``body_names``), ``lip_sides``,
    ``influence``, ``geodesic``, ``front``, ``parts`` (the pieces that ride a bone
    rigidly, :func:`faceforge.skin.parts.rigid_parts`). The skin constraint topology is a
    pure function of ``faces`` (:func:`faceforge.skin.layer.skin_topology`), so it
    is rebuilt by whoever assembles the model, not stored.
``report.json``
    fractions bound to muscle / cranium / mandible / nothing by region, rays
    that missed, the mouth cut, the influence normalisation.
``influence.png``
    front and side views of the skin coloured by influence (Fig. 9).
"""

from __future__ import annotations

import click

from faceforge.pipeline import Stage, register_command, register_stage
from faceforge.pipeline.stages.fit import compile_solver_ahead


def load_fit(fit_dir):
    """The fitted head from the fit stage's ``fit.npz`` (see :func:`head_from_fit_arrays`)."""
    from faceforge.exceptions import StageError
    from faceforge.io.stagefiles import load_npz

    path = fit_dir / "fit.npz"
    if not path.exists():
        raise StageError("fit.npz missing: run `faceforge fit` first", path)
    d = load_npz(path)
    missing = [k for k in _NEEDED if k not in d]
    if missing:
        raise StageError(f"fit.npz lacks {', '.join(missing)}", path)
    return head_from_fit_arrays(d)


_NEEDED = ("skin_vertices", "skin_faces", "skin_landmark_ids", "skin_landmark_positions")


def head_from_fit_arrays(d: dict) -> dict:
    """The fitted head from the fit stage's arrays.

    Arrays read (see :mod:`faceforge.pipeline.stages.fit`): ``skin_vertices (n, 3)``,
    ``skin_faces (m, 3)`` (the fit's internal skin), ``cranium_vertices``/``cranium_faces``,
    ``mandible_vertices``/``mandible_faces``, ``skin_landmark_ids (L,) str``,
    ``skin_landmark_positions (L, 3)``, and the muscles as CSR blocks:
    ``muscle_names (k,) str``, ``muscle_vertex_start (k+1,)``, ``muscle_vertices``,
    ``muscle_face_start (k+1,)``, ``muscle_faces`` (ids local to each muscle), and
    ``muscle_layers (k,)`` when present (else every muscle is in one layer and the
    nearest hit wins).

    Returns
    -------
    dict with ``vertices``, ``faces``, ``landmarks`` {fdp: (3,)}, ``cranium``,
    ``mandible`` ((v, f) or None) and ``muscles`` [(name, layer, v, f)].
    """
    import numpy as np

    def part(name):
        if f"{name}_vertices" in d and len(d[f"{name}_vertices"]):
            return d[f"{name}_vertices"], d[f"{name}_faces"]
        return None

    muscles = []
    if "muscle_names" in d:
        vs, fs = d["muscle_vertex_start"], d["muscle_face_start"]
        layers = d["muscle_layers"] if "muscle_layers" in d else np.zeros(len(d["muscle_names"]), np.int64)
        for i, name in enumerate(d["muscle_names"]):
            muscles.append((str(name), int(layers[i]),
                            d["muscle_vertices"][vs[i]:vs[i + 1]], d["muscle_faces"][fs[i]:fs[i + 1]]))
    landmarks = {str(k): p for k, p in zip(d["skin_landmark_ids"], d["skin_landmark_positions"])}
    from faceforge.geometry.mirror import Mirror

    return {"vertices": d["skin_vertices"], "faces": d["skin_faces"], "landmarks": landmarks,
            "cranium": part("cranium"), "mandible": part("mandible"), "muscles": muscles,
            "mirror": Mirror.from_arrays(d)}


def run(ctx):
    """Bind the fitted head in ``ctx.input("fit")``; write bind.npz, report.json, influence.png."""
    from faceforge.skin.head import bind_head
    from faceforge.skin.rules import match_insertions
    from faceforge.skin.influence import save_influence_png
    from faceforge.io.stagefiles import save_json, save_npz

    head = load_fit(ctx.input("fit"))
    insertions = tuple(str(n) for n in ctx.config.get("bind.insertions"))
    names = [str(m[0]) for m in head["muscles"]]
    for key in ("bind.insertions", "bind.brow_muscles", "bind.brow_raisers", "bind.cheek_muscles",
                "bind.ala_muscles"):
        _, unknown = match_insertions(tuple(str(n) for n in (ctx.config.get(key) or ())), names)
        if unknown:   # a map of one's own may lack the template's brow depressors (or a typo): say so, go on
            ctx.log(f"warning: {key}: no muscle {', '.join(unknown)} in the fitted map; "
                    f"ignored (muscles: {', '.join(sorted(names))})")
    ctx.log(f"binding {len(head['vertices'])} skin vertices to {len(head['muscles'])} muscles and the skull")
    bound = bind_head(head["vertices"], head["faces"], head["landmarks"], head["cranium"],
                      head["mandible"], head["muscles"],
                      float(ctx.config.get("bind.max_ray_distance")), insertions=insertions,
                      lips_to_ring=bool(ctx.config.get("bind.lips_to_ring")),
                      modiolus_radius=float(ctx.config.get("bind.modiolus_radius")), mirror=head["mirror"],
                      commissure_radius=float(ctx.config.get("bind.commissure_radius")),
                      vermilion=float(ctx.config.get("bind.vermilion_reach")),
                      vermilion_depth_mm=float(ctx.config.get("bind.vermilion_depth_mm")),
                      brow_band_mm=float(ctx.config.get("bind.brow_band_mm")),
                      brow_muscles=tuple(str(n) for n in ctx.config.get("bind.brow_muscles")),
                      brow_shared_mm=float(ctx.config.get("bind.brow_shared_mm")),
                      brow_raisers=tuple(str(n) for n in (ctx.config.get("bind.brow_raisers") or ())),
                      forehead_bone_mm=float(ctx.config.get("bind.forehead_bone_mm")),
                      nose_on_bone=bool(ctx.config.get("bind.nose_on_bone")),
                      normal_rounds=int(ctx.config.get("bind.normal_rounds")),
                      cheek_mm=float(ctx.config.get("bind.cheek_mm")),
                      cheek_muscles=tuple(str(n) for n in ctx.config.get("bind.cheek_muscles")),
                      ala_mm=float(ctx.config.get("bind.ala_mm")),
                      ala_muscles=tuple(str(n) for n in (ctx.config.get("bind.ala_muscles") or ())))
    front = bound.report["regions"]["face_front"]["fraction"]["bound"]
    ctx.log(f"mouth: {bound.report['mouth']['action']}; face front bound: {100 * front:.1f}%")
    rigid = bound.report.get("rigid_parts", {})
    if any(rigid.values()):
        ctx.log(f"rigid pieces (eyeballs, teeth): {rigid['on_cranium']} vertices ride the cranium, "
                f"{rigid['on_mandible']} the mandible")
    save_npz(ctx.out_dir / "bind.npz", **bound.as_arrays())
    save_json(ctx.out_dir / "report.json", bound.report)
    save_influence_png(ctx.out_dir / "influence.png", bound.cut.vertices, bound.cut.faces,
                       bound.weights, title="influence of the musculoskeletal structure (Fig. 9)")


STAGE = register_stage(Stage(
    name="bind", deps=("fit",), config_keys=("bind",),
    outputs=("bind.npz", "report.json", "influence.png"), version="12", run=run,
    description="bind the skin to muscles and bone, influence map (§8)", background=compile_solver_ahead))


@click.command("bind", help="Bind the skin to the fitted muscles and skull (paper §8).")
@click.option("--force", is_flag=True, help="Rerun even if up to date.")
@click.pass_obj
def command(app, force):
    app.run_stage("bind", force=force)
    report = app.workspace.stage_dir("bind") / "report.json"
    app.log(f"bind report: {report}")


register_command(command)
