"""The landmarks stage: the FDP landmarks of the head, found automatically where the user
gave none (issue 26; :mod:`faceforge.landmarks`).

``faceforge landmarks MESH [--landmarks PARTIAL] [-o head.fdp.yaml]`` writes
``<workdir>/landmarks/``:

landmarks.fdp.yaml
    the landmark file ``fit`` uses, in the project's format (vertex id + position, a
    comment per point saying how it was found); a copy of the user's file when that file
    holds every FDP the detector gives.
report.json
    ``source`` (given | completed | detected), the face search (view, score, views tried),
    the face's frame, the mirror plane, and per point: method, confidence, views, spread.
landmarks.png
    front and side renders with each point labelled (written when anything was detected).

``fit`` depends on this stage: with a landmark file next to the mesh (or ``--landmarks``)
that is complete, nothing is detected and ``fit`` reads the user's file itself (its errors
name that file); otherwise ``fit`` reads this stage's file and says the landmarks were
detected.
"""

from __future__ import annotations

import click

from faceforge.pipeline import Stage, register_command, register_stage
from faceforge.pipeline.workdir_guard import check_outside_workdir

#: 2: the rules measure in eye spans on a face smaller than a whole head (the MediaPipe mask, cut heads)
#: 3: the inner and middle brows keep the detector's side position less its outward bias, and the nose's
#: lower edge 9.4/9.5 the detector's point less its bias, both measured on MediaPipe's canonical face
#: 4: lips joined in front (a bridged mask) are told apart by height; a lip that does not roll in gives its edge
#: 5: eyes the mesh does not open (no loop, no socket) are looked at again drawn in (``landmarks.paint_eyes``)
VERSION = "5"


def run(ctx) -> None:
    """Stage body: find (or take) the landmarks, write the file, the report, the picture."""
    import shutil
    from pathlib import Path

    from faceforge.io.stagefiles import atomic_write_bytes, save_json
    from faceforge.landmarks.find import find_landmarks
    from faceforge.landmarks.output import landmark_yaml, report, save_png

    mesh = ctx.param("mesh")
    found = find_landmarks(mesh, ctx.params.get("landmarks"),
                           paint_eyes=bool(ctx.config.get("landmarks.paint_eyes", True)))
    out = Path(ctx.out_dir)
    if found.source == "given":
        shutil.copyfile(found.given_path, out / "landmarks.fdp.yaml")
        save_json(out / "report.json", {"mesh": str(mesh), "source": "given", "given": found.given_path})
        return
    det = found.detection
    det.info.pop("timings", None)   # same inputs, same bytes
    atomic_write_bytes(out / "landmarks.fdp.yaml", landmark_yaml(det, mesh).encode())
    save_json(out / "report.json", {"source": found.source, **report(det, mesh, found.given_path)})
    save_png(out / "landmarks.png", det, found.vertices, found.faces, title=f"landmarks: {Path(mesh).name}")
    n_given = sum(m.startswith("given") for m in det.method)
    what = (f"{len(det.ids) - n_given} FDPs detected" + (f", {n_given} given in {found.given_path}" if n_given else ""))
    ctx.log(f"{what} (the face seen {det.info['search']}, {len(set(v for vs in det.views for v in vs))} views)")


def landmark_file(workdir_stage_dir) -> tuple[str, str]:
    """``(path, source)`` of the landmark file ``fit`` should read, from this stage's folder:
    the user's own file when it was complete, else the stage's ``landmarks.fdp.yaml``."""
    from pathlib import Path

    from faceforge.io.stagefiles import load_json

    rep = load_json(Path(workdir_stage_dir) / "report.json")
    if rep.get("source") == "given":
        return rep["given"], "given"
    return str(Path(workdir_stage_dir) / "landmarks.fdp.yaml"), rep.get("source", "detected")


STAGE = register_stage(Stage(
    name="landmarks", deps=(), config_keys=("landmarks",), inputs=("mesh", "landmarks?"),
    outputs=("landmarks.fdp.yaml", "report.json"), version=VERSION, run=run,
    description="find the FDP landmarks of the head (automatic where none are given)"))


@click.command("landmarks", help="Find the MPEG-4 FDP landmarks of a head mesh automatically.")
@click.argument("mesh", type=click.Path(dir_okay=False))
@click.option("--landmarks", type=click.Path(dir_okay=False), default=None,
              help="A (partial) landmark file whose points are kept [default: <mesh stem>.fdp.yaml "
                   "next to the mesh, if there is one].")
@click.option("-o", "--output", type=click.Path(dir_okay=False), default=None,
              help="Also write the landmark file here (e.g. head.fdp.yaml next to the mesh).")
@click.option("--force", is_flag=True, help="Rerun even if up to date.")
@click.pass_obj
def command(app, mesh, landmarks, output, force):
    from faceforge.io.export import protect_inputs
    from faceforge.io.landmarks import default_landmark_path
    from faceforge.io.stagefiles import atomic_write_bytes

    if landmarks is None:   # the file next to the mesh, if any; else the landmarks are detected
        landmarks = str(default_landmark_path(mesh)) if default_landmark_path(mesh).exists() else None
    if output:              # before any work: never the user's own mesh or landmark file, nor a missing folder
        from faceforge.io.writable import check_writable

        protect_inputs(output, {"mesh": mesh, "landmark file": landmarks})
        check_writable(output, "-o")
        check_outside_workdir(app.workspace, output, "-o")
    app.run_stage("landmarks", params={"mesh": mesh, "landmarks": landmarks}, force=force)
    folder = app.workspace.stage_dir("landmarks")
    if output:
        atomic_write_bytes(output, (folder / "landmarks.fdp.yaml").read_bytes())
        app.log(f"landmarks: wrote {output}")
    app.log(f"landmarks: {folder / 'landmarks.fdp.yaml'}, {folder / 'report.json'}"
            + (f", {folder / 'landmarks.png'}" if (folder / "landmarks.png").exists() else ""))


register_command(command)
