"""What a playback command writes from a stage's frames: ``-o`` exports and ``--preview`` sheets.

Exports are not cached: a new ``-o`` reads the simulated frames of the animate (or arkit) stage
through a read-only map of its file (:func:`faceforge.io.frame_stream.open_frames`), so an
hour-long take is read a chunk at a time.
"""

from __future__ import annotations

from pathlib import Path


def preview_face(app, first, stage: str = "animate"):
    """(region (n,) bool or None, track name) of a --preview: the face's box from the fit's
    landmarks (:func:`faceforge.viz.contact_sheet.face_region`; the user's vertex order, head
    frame ``first (n, 3)``), so a turning head is framed by its face, and the played track's
    file name from the animate stage's report."""
    import json

    import numpy as np

    from faceforge.io.stagefiles import load_npz
    from faceforge.viz.contact_sheet import face_region

    region, track = None, "animation"
    try:
        fit = load_npz(app.workspace.stage_dir("fit") / "fit.npz")
        u2i = np.asarray(fit["skin_user_to_internal"], dtype=np.int64)
        lm = dict(zip(fit["skin_landmark_ids"], fit["skin_landmark_positions"]))
        if len(u2i) == len(first):
            inner = np.zeros((int(u2i.max()) + 1, 3))
            inner[u2i] = first
            region = face_region(inner, lm)
            region = None if region is None else region[u2i]
        report = json.loads((app.workspace.stage_dir(stage) / "report.json").read_text())
        track = Path(str(report.get("fap", track))).name
    except (OSError, KeyError, ValueError) as exc:   # an older workdir: the moving part, untitled
        app.log(f"animate: preview framed by its motion ({exc})")
    return region, track


def export_outputs(app, output: str | None, preview: str | None, preview_frames: str | None,
                   stage: str = "animate") -> None:
    """Write ``-o`` and ``--preview`` from the frames of ``stage`` (animate, or arkit)."""
    import numpy as np

    from faceforge.exceptions import StageError
    from faceforge.io.frame_stream import open_frames

    # a read-only map of the stage file: an hour-long take is read a chunk at a time
    frames = open_frames(app.workspace.stage_dir(stage) / "animation.npz")
    fps = float(open_frames(app.workspace.stage_dir(stage) / "animation.npz", "fps"))
    mesh = app.params().get("mesh")
    if not mesh:
        raise StageError("no mesh remembered in the workdir; run `faceforge fit MESH` first", app.workspace.root)
    from faceforge.fit.orientation import user_rotation

    rotation = user_rotation(app.workspace.stage_dir("fit"))
    if output:
        from faceforge.io.export import export_for_mesh, up_axis_of

        written, notes = export_for_mesh(output, frames, mesh, fps, up_axis_of(rotation))
        app.log(f"animate: wrote {written} ({len(frames)} frames, {frames.shape[1]} vertices, {fps:g} fps)")
        for note in notes:
            app.log(f"animate: note: {note}")
    if preview:
        from faceforge.io.mesh import load_mesh
        from faceforge.viz.contact_sheet import contact_sheet, pick_frames

        v, faces, _ = load_mesh(mesh)
        if len(v) != frames.shape[1]:
            raise StageError(f"has {len(v)} vertices but the animation {frames.shape[1]}; rerun `faceforge fit`",
                             mesh)
        try:
            idx = pick_frames(len(frames), int(app.config.get("animate.preview_frames")), preview_frames)
        except ValueError as exc:
            raise StageError(f"--preview-frames: {exc}") from None
        # only the drawn frames are read, turned upright (head space)
        shown = np.stack([np.asarray(frames[i]) @ rotation.T.astype(frames.dtype) for i in idx])
        first = np.asarray(frames[0]) @ rotation.T.astype(frames.dtype)
        region, track = preview_face(app, first, stage)
        contact_sheet(preview, shown, faces, range(len(idx)), fps, focus=region is None, region=region,
                      panel=3.0, dpi=120, labels=[f"frame {i}  ({i / fps:.2f} s)" for i in idx],
                      title=f"{track}" + (f" -> {Path(output).name}" if output else ""))
        app.log(f"animate: wrote {preview}")
