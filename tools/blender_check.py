"""Open faceforge's animation outputs in real Blender and compare what Blender shows, vertex by vertex.

Runs under a Python that has Blender's ``bpy`` module (``pip install bpy==5.0.1`` into a
separate Python 3.11 venv), or inside Blender itself::

    /tmp/bpy-venv/bin/python tools/blender_check.py MESH.obj OUT.pc2 OUT.mdd OUT.glb OUTDIR \\
        [--reference work/animate/animation.npz] [--frames 0,37,75] [--json result.json]
    blender -b --python-exit-code 1 --python tools/blender_check.py -- MESH.obj OUT.pc2 ...

For every output it builds a fresh scene the way the README tells users to:

* ``.pc2`` / ``.mdd``, twice: ``MESH.obj`` imported with ``bpy.ops.wm.obj_import`` at its
  defaults (Forward -Z, Up Y, which Blender puts on the object as Rotation X = 90 deg) with a
  Mesh Cache modifier at its defaults (Forward +Y, Up +Z, no flip, Frame Start 0, time mode
  Frame); and the same object with its rotation applied (a Z-up Blender object, like the one
  the OBJ was exported from) with the modifier's Forward +Z, Up -Y;
* ``.glb``: ``bpy.ops.import_scene.gltf`` at its defaults (+Y up converted to +Z up);
* ``.usda`` / ``.usdc``: ``bpy.ops.wm.usd_import`` at its defaults (the stage's up axis
  converted to +Z up; the time-sampled points become a Mesh Sequence Cache modifier);
* an OBJ-sequence folder: the frame's file imported like ``MESH.obj``;

sets the scene frame rate to the animation's, goes to the Blender frame that shows
faceforge frame ``k`` (frame ``k`` for all formats, i.e. time ``k / fps``), evaluates the
depsgraph and takes the evaluated vertices in *world* space (what the user sees), turned back
from Blender's Z-up to faceforge's Y-up (``x, y, z = X, Z, -Y``). These are compared with the
expected frames in Blender's vertex order, which must be the user's OBJ order.

The expected frames are ``--reference`` (an ``.npz`` with ``frames`` and ``fps``, such as the
animate stage's ``animation.npz``, or an ``.npy`` of shape (n_frames, n_verts, 3)); without it,
each output read back with faceforge's own reader (``faceforge.io.export``).

Writes one JSON document (stdout, or ``--json``): per output and frame the largest vertex
error in world space (model units), the vertex where it occurs, the tolerance (``--ulps``
float32 ulps of the frame's largest coordinate), and ``max_error_data``, the error with the
object's float32 quarter-turn made exact (what the file and importer did to the vertices). Exit status 0 if every frame matches, 1 if any does
not (or a vertex count differs), 2 for bad arguments.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

#: faceforge (Y up, face +Z) -> Blender (Z up, face -Y) is a rotation of +90 deg about X:
#: (x, y, z) -> (x, -z, y). Rows map Blender world coordinates back to faceforge's.
BLENDER_TO_YUP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


class CheckError(Exception):
    """Bad input to the check (missing file, unknown format, unreadable reference)."""


def _script_argv(argv: list[str]) -> list[str]:
    """Arguments after ``--`` when run inside the ``blender`` binary, else argv[1:]."""
    return argv[argv.index("--") + 1 :] if "--" in argv else argv[1:]


def _parse(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="blender_check.py", description=__doc__.split("\n\n")[0])
    parser.add_argument("mesh", type=Path, help="the user's mesh (.obj) that was animated")
    parser.add_argument("outputs", type=Path, nargs="+",
                        help=".pc2, .mdd, .glb, .usda, .usdc files or OBJ-sequence folders")
    parser.add_argument("--reference", type=Path, help=".npz (frames, fps) or .npy frames (n_frames, n_verts, 3)")
    parser.add_argument("--fps", type=float, help="frames per second [default: the reference's, else the output's]")
    parser.add_argument("--frames", help="faceforge frames to compare, 0-based, e.g. 0,37,75 [default: first, middle, last]")
    parser.add_argument("--ulps", type=float, default=4.0, help="tolerance in float32 ulps of the largest coordinate")
    parser.add_argument("--no-split", action="store_true",
                        help="import MESH with Split by Object / Group off (an OBJ with several `o` sections)")
    parser.add_argument("--object-axes", default="POS_Z,NEG_Y",
                        help="Mesh Cache Forward,Up axes on the Z-up object (the variant 'blender-object')")
    parser.add_argument("--json", type=Path, help="write the result here instead of stdout")
    return parser.parse_args(argv)


def format_of(path: Path) -> str:
    """``pc2``, ``mdd``, ``glb``, ``usd`` or ``objseq`` (a folder), from the output path."""
    if path.is_dir():
        return "objseq"
    suffix = path.suffix.lower()
    if suffix in (".pc2", ".mdd", ".glb"):
        return suffix[1:]
    if suffix in (".usda", ".usdc", ".usd"):
        return "usd"
    raise CheckError(f"{path}: unknown output format {suffix!r}; expected .pc2, .mdd, .glb, .usda, .usdc "
                     "or a folder")


def load_reference(path: Path) -> tuple[np.ndarray, float | None]:
    """Expected frames (n_frames, n_verts, 3) float32 and fps (None for an .npy)."""
    try:
        if path.suffix == ".npz":
            with np.load(path) as data:
                return np.asarray(data["frames"], dtype=np.float32), float(data["fps"])
        return np.asarray(np.load(path), dtype=np.float32), None
    except (OSError, KeyError, ValueError) as exc:
        raise CheckError(f"{path}: cannot read reference frames: {exc}") from None


def read_output(path: Path, fmt: str) -> tuple[np.ndarray, float | None]:
    """An output read back with faceforge's own readers: frames and fps where the file holds it."""
    sys.path.insert(0, str(ROOT))
    from faceforge.io import export

    if fmt == "pc2":
        return export.read_pc2(path)[0], None
    if fmt == "mdd":
        frames, times = export.read_mdd(path)
        return frames, (1.0 / float(times[1] - times[0]) if times.size > 1 else None)
    if fmt == "glb":
        frames, _, times = export.read_glb(path)
        return frames, (1.0 / float(times[1] - times[0]) if times.size > 1 else None)
    if fmt == "usd":
        frames, fps, _, _, _ = export.read_usd(path)
        return frames, fps
    return export.read_obj_sequence(path)[0], None


def sequence_file(folder: Path, frame: int) -> Path:
    """The OBJ file of 0-based ``frame`` in a sequence folder (files are numbered from 1)."""
    pattern = re.compile(re.escape(folder.name) + r"_(\d+)\.obj")
    for file in folder.iterdir():
        match = pattern.fullmatch(file.name)
        if match and int(match.group(1)) == frame + 1:
            return file
    raise CheckError(f"{folder}: no file for frame {frame + 1}")


def pick_frames(spec: str | None, n_frames: int) -> list[int]:
    """Frames from ``"0,37,75"``, or first, middle and last."""
    if spec is None:
        return sorted({0, (n_frames - 1) // 2, n_frames - 1})
    frames = [int(x) for x in spec.split(",") if x.strip()]
    bad = [k for k in frames if not 0 <= k < n_frames]
    if bad:
        raise CheckError(f"--frames {bad} outside 0..{n_frames - 1}")
    return frames


# --- inside Blender --------------------------------------------------------------------------


def _new_scene(fps: float):
    """An empty scene whose frame rate is ``fps`` (fractional rates via fps_base)."""
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.fps = max(1, round(fps))
    scene.render.fps_base = 1.0 if float(fps).is_integer() else scene.render.fps / fps
    return scene


def _import_obj(path: Path, split: bool = True):
    """Import an OBJ at the importer's defaults (``split=False``: Split by Object / Group off);
    returns the one mesh object it made."""
    import bpy

    before = set(bpy.data.objects)
    options = {} if split else {"use_split_objects": False, "use_split_groups": False}
    bpy.ops.wm.obj_import(filepath=str(path), **options)
    made = [ob for ob in bpy.data.objects if ob not in before and ob.type == "MESH"]
    if len(made) != 1:
        hint = "; an OBJ with several `o` sections needs Split by Object off (--no-split)" if split else ""
        raise CheckError(f"{path}: Blender's OBJ importer made {len(made)} mesh objects, expected 1{hint}")
    return made[0]


def _import_one(path: Path, importer, what: str):
    """Run a Blender importer at its defaults; the one mesh object it made."""
    import bpy

    before = set(bpy.data.objects)
    importer(filepath=str(path))
    made = [ob for ob in bpy.data.objects if ob not in before and ob.type == "MESH"]
    if len(made) != 1:
        raise CheckError(f"{path}: Blender's {what} importer made {len(made)} mesh objects, expected 1")
    return made[0]


def _import_glb(path: Path):
    import bpy

    return _import_one(path, bpy.ops.import_scene.gltf, "glTF")


def _import_usd(path: Path):
    import bpy

    return _import_one(path, bpy.ops.wm.usd_import, "USD")


def _evaluated_yup(obj) -> tuple[np.ndarray, np.ndarray]:
    """The evaluated mesh's vertices in world space as faceforge's Y-up, (n_verts, 3) float64 each.

    Returns
    -------
    world : through the object's matrix as Blender stores it (float32: a 90 deg rotation
        carries cos = -4.4e-8, i.e. errors up to 4.4e-8 x the largest coordinate)
    data : through the same matrix snapped to whole numbers when it is a pure axis swap within
        1e-6, which isolates what the file and the importer did to the vertex data
    """
    import bpy

    depsgraph = bpy.context.evaluated_depsgraph_get()
    evaluated = obj.evaluated_get(depsgraph)
    mesh = evaluated.to_mesh()
    try:
        co = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
        mesh.vertices.foreach_get("co", co)
    finally:
        evaluated.to_mesh_clear()
    co = co.reshape(-1, 3).astype(np.float64)
    matrix = np.array(evaluated.matrix_world, dtype=np.float64)
    snapped = np.round(matrix)
    if not np.allclose(matrix, snapped, atol=1e-6):
        snapped = matrix
    world, data = (co @ m[:3, :3].T + m[:3, 3] for m in (matrix, snapped))
    return world @ BLENDER_TO_YUP.T, data @ BLENDER_TO_YUP.T


def _goto(scene, frame: int, fps: float, fmt: str) -> float:
    """Set the scene to where faceforge frame ``frame`` must be shown; returns that Blender frame.

    Mesh Cache in "Frame" time mode shows sample ``scene frame - Frame Start`` (Frame Start 0),
    an OBJ sequence has no timing: both frame ``frame``. A glTF key at time ``t`` belongs at
    Blender frame ``t * render.fps / render.fps_base``: frame ``frame`` when the scene runs at
    ``fps``. (Blender 4.5's glTF importer keys it at ``t * render.fps * render.fps_base``, the
    same for integer rates, 0.2 % late for 29.97 fps: a fractional rate fails this check.)
    """
    target = float(frame)
    if fmt == "glb":
        target = frame / fps * scene.render.fps / scene.render.fps_base
    whole = int(np.floor(target))
    scene.frame_set(whole, subframe=target - whole)
    return target


def compare(blender: np.ndarray, data: np.ndarray, expected: np.ndarray, ulps: float) -> dict:
    """Vertex-by-vertex comparison in the user's order.

    Parameters
    ----------
    blender, data : (n_verts, 3) float
        Blender's vertices in world space and with the object's axis swap made exact (see
        :func:`_evaluated_yup`), model units, Y up.
    expected : (n_verts, 3) float
    ulps : float
        Tolerance in float32 ulps of the largest coordinate of ``expected``; applies to ``blender``.
    """
    if blender.shape != expected.shape:
        return {"ok": False, "error": f"Blender has {blender.shape[0]} vertices, expected {expected.shape[0]} "
                "(Blender's OBJ and glTF importers drop vertices that no face uses)"}
    expected = expected.astype(np.float64)
    error = np.abs(blender - expected).max(axis=1)
    worst = int(np.argmax(error))
    tolerance = ulps * float(np.spacing(np.float32(np.abs(expected).max())))
    return {
        "max_error": float(error[worst]),
        "worst_vertex": worst,
        "max_error_data": float(np.abs(data - expected).max()),
        "tolerance": tolerance,
        "ok": bool(error[worst] <= tolerance),
    }


#: How each format is opened. A point cache is tried on two objects: the OBJ as Blender's
#: importer brings it in (Y-up vertices, the quarter turn on the object: Mesh Cache defaults),
#: and a Z-up Blender object such as the one the OBJ was exported from (here: the import with
#: its rotation applied to the vertices), where the modifier must turn the Y-up cache: Forward
#: +Z, Up -Y.
VARIANTS = {
    "pc2": ("obj-import", "blender-object"),
    "mdd": ("obj-import", "blender-object"),
    "glb": ("gltf-import",),
    "usd": ("usd-import",),
    "objseq": ("obj-import",),
}


def _z_up_object(obj) -> None:
    """Bake the object's rotation into its vertices (a Z-up mesh with an identity transform)."""
    import bpy

    bpy.ops.object.select_all(action="DESELECT")
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj
    bpy.ops.object.transform_apply(location=False, rotation=True, scale=False)


def check_output(mesh: Path, output: Path, fmt: str, variant: str, expected: np.ndarray, fps: float,
                 frames: list[int], ulps: float, object_axes: tuple[str, str] = ("POS_Z", "NEG_Y"),
                 split: bool = True) -> dict:
    """Open one output in a fresh Blender scene and compare the chosen frames; the JSON record."""
    scene = _new_scene(fps)
    settings: dict = {}
    obj = None
    if fmt in ("pc2", "mdd"):
        obj = _import_obj(mesh, split)
        settings["obj_import"] = "defaults (forward -Z, up Y)" + ("" if split else ", Split by Object/Group off")
        if variant == "blender-object":
            _z_up_object(obj)
            settings["object"] = "rotation applied (Z-up vertices, like the object the OBJ was exported from)"
        modifier = obj.modifiers.new("faceforge", "MESH_CACHE")
        modifier.cache_format = fmt.upper()
        modifier.filepath = str(output)
        if variant == "blender-object":
            modifier.forward_axis, modifier.up_axis = object_axes
        settings["mesh_cache"] = {k: getattr(modifier, k) for k in
                                  ("forward_axis", "up_axis", "time_mode", "frame_start", "frame_scale",
                                   "interpolation", "deform_mode")}
        settings["mesh_cache"]["flip_axis"] = [bool(a) for a in modifier.flip_axis]
    elif fmt == "glb":
        obj = _import_glb(output)
        settings = {"gltf_import": "defaults (+Y up converted to +Z up)"}
    elif fmt == "usd":
        obj = _import_usd(output)
        settings = {"usd_import": "defaults (stage up axis converted to +Z up)",
                    "modifiers": [m.type for m in obj.modifiers]}
    else:
        settings = {"obj_import": "defaults (forward -Z, up Y), one file per frame"}
    settings["scene_fps"] = scene.render.fps / scene.render.fps_base
    records = []
    for k in frames:
        if fmt == "objseq":
            scene = _new_scene(fps)
            obj = _import_obj(sequence_file(output, k))
        blender_frame = _goto(scene, k, fps, fmt)
        record = {"frame": k, "blender_frame": blender_frame}
        record.update(compare(*_evaluated_yup(obj), expected[k], ulps))
        records.append(record)
    return {"output": str(output), "format": fmt, "variant": variant, "settings": settings, "frames": records,
            "ok": all(r["ok"] for r in records)}


def run(args: argparse.Namespace) -> dict:
    """The whole check; the JSON document."""
    import bpy

    if not args.mesh.is_file() or args.mesh.suffix.lower() != ".obj":
        raise CheckError(f"{args.mesh}: expected the user's .obj mesh")
    formats = [format_of(p) if p.exists() else None for p in args.outputs]
    missing = [str(p) for p, f in zip(args.outputs, formats) if f is None]
    if missing:
        raise CheckError(f"{missing[0]}: no such output")
    reference, ref_fps = load_reference(args.reference) if args.reference else (None, None)
    axes = tuple(args.object_axes.split(","))
    if len(axes) != 2 or not all(re.fullmatch("(POS|NEG)_[XYZ]", a) for a in axes) or axes[0][-1] == axes[1][-1]:
        raise CheckError(f"--object-axes {args.object_axes!r}: expected two different axes like POS_Z,NEG_Y")
    results = []
    for output, fmt in zip(args.outputs, formats):
        if fmt == "usd" and reference is not None:   # bpy has no pxr: Blender's import is the reader
            stored, out_fps = reference, None
        else:
            stored, out_fps = read_output(output, fmt)
        expected = stored if reference is None else reference
        fps = args.fps or ref_fps or out_fps
        if fps is None:
            raise CheckError(f"{output}: the file does not say its frame rate; pass --fps or --reference .npz")
        frames = pick_frames(args.frames, expected.shape[0])
        for variant in VARIANTS[fmt]:
            record = check_output(args.mesh, output, fmt, variant, expected, fps, frames, args.ulps, axes,
                                  not args.no_split)
            record["n_frames"] = int(stored.shape[0])
            if stored.shape[0] != expected.shape[0]:
                record["ok"] = False
                record["error"] = f"the file holds {stored.shape[0]} frames, the reference {expected.shape[0]}"
            results.append(record)
    return {
        "blender": bpy.app.version_string,
        "command": "blender_check.py " + " ".join(_script_argv(sys.argv)),
        "mesh": str(args.mesh),
        "reference": str(args.reference) if args.reference else "each output read by faceforge.io.export",
        "ulps": args.ulps,
        "results": results,
        "ok": all(r["ok"] for r in results),
    }


def main(argv: list[str]) -> int:
    args = _parse(_script_argv(argv))
    try:
        import bpy  # noqa: F401
    except ImportError:
        print("blender_check.py: no bpy here; run it with a Python that has Blender's bpy module "
              "or inside `blender -b --python`", file=sys.stderr)
        return 2
    try:
        result = run(args)
    except CheckError as exc:
        print(f"blender_check.py: {exc}", file=sys.stderr)
        return 2
    text = json.dumps(result, indent=1)
    if args.json:
        args.json.write_text(text + "\n")
    else:
        print(text)
    return 0 if result["ok"] else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv))
