"""Animation exporters, chosen by the output path's suffix.

=============  ===========================================  =================================
``-o`` path    format                                       module
=============  ===========================================  =================================
``x.pc2``      PC2 point cache (little endian, float32)     :mod:`faceforge.io.export_cache`
``x.mdd``      MDD point cache (big endian, float32)        :mod:`faceforge.io.export_cache`
``x.glb``      glTF binary, morph targets + weights anim.   :mod:`faceforge.io.export_gltf`
``x.usda``     USD text, a mesh with time-sampled points    :mod:`faceforge.io.export_usd`
``x.usdc``     USD binary (crate), the same (``usd-core``)  :mod:`faceforge.io.export_usd`
``x`` (none)   folder ``x/`` of ``x_0001.obj``, ...          :mod:`faceforge.io.export_obj`
=============  ===========================================  =================================

Every writer has the signature ``write_<fmt>(path, frames, faces, fps) -> Path`` with
``frames (n_frames, n_verts, 3)`` in the input mesh's units and vertex order, ``faces`` as
a ``(m, k)`` array or a list of polygons (quads allowed; :func:`polygons_from_fan` recovers
them from ``load_mesh``'s triangles and ``MeshInfo.face_source``), and writes to a temporary name
renamed into place. :data:`EXPORTERS` is the suffix registry (a plain dict each format
module fills with one line); :func:`export_animation` dispatches through it.

Opening the results in Blender
------------------------------
Measured in Blender 4.5.15 by ``tools/blender_check.py`` (``benchmarks/results/blender_check.json``):
every format below shows faceforge's frames in the user's vertex order, the vertex data exact
(glTF: within float32 rounding of the shape-key mix). faceforge works in the MPEG-4 frame: +Y
up, the face looks along +Z (glTF's convention too); Blender is Z-up. Faceforge frame ``k``
(0-based, time ``k / fps``) is Blender frame ``k`` for the caches and glTF (and the file
``NAME_{k+1:04d}.obj`` of a sequence): set the scene's frame
rate to ``fps`` (before a glTF import), Start to 0 and End to ``n_frames - 1``.

* ``.glb``: File > Import > glTF 2.0 at its defaults. The importer turns +Y up into Z-up
  itself; the animation is one shape key per frame (``frame_0002`` ...) with animated values.
  At a fractional scene rate (29.97) Blender 4.5 keys time ``t`` at ``t * fps * fps_base``
  instead of ``t * fps / fps_base``, 0.2 % late: prefer integer rates.
* ``.pc2`` / ``.mdd`` on the OBJ imported with File > Import > Wavefront OBJ at its defaults
  (Forward -Z, Up Y; Blender 4.x puts the turn on the object, Rotation X = 90 deg, and keeps
  the vertices as in the file): add a Mesh Cache modifier, pick the file, keep its defaults
  (Forward +Y, Up +Z, no flip, Frame Start 0, time mode Frame). An OBJ with several ``o``
  sections must be imported with Split by Object off, or each part is renumbered.
* ``.pc2`` / ``.mdd`` on a Z-up Blender object (the one the OBJ was exported from with
  Blender's defaults, or an import after Object > Apply > Rotation): set the modifier's
  Forward Axis to **+Z** and Up Axis to **-Y**. (Forward -Z / Up +Y, the OBJ exporter's
  pair, lays the head on its back.)
* Mesh Cache time mode: keep "Frame". "Time" is right for MDD (its times are ``k / fps``)
  but not for PC2: Blender 4.5 then shows sample ``frame / fps**2`` (it divides by the
  frame rate twice), i.e. the head barely moves. The PC2 header (start 0, 1 frame per
  sample) follows the format's definition; "Frame" mode ignores it.
* ``.usda`` / ``.usdc``: File > Import > Universal Scene Description at its defaults. The
  importer turns the stage's up axis into Z-up and the time-sampled points into a Mesh
  Sequence Cache modifier; ``metersPerUnit = 1`` keeps one mesh unit one Blender unit (the
  vertex data exact, like the point caches).
* OBJ sequence: every file imports as its own object like the OBJ above; Blender has no
  built-in sequence importer, but the folder is what sequence add-ons and other tools read.
* Vertices that no face uses are dropped by Blender's OBJ and glTF importers (faceforge
  keeps them): :func:`blender_notes` says so when an export has any.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from . import export_cache, export_gltf, export_obj, export_usd  # noqa: F401  (each registers its suffixes)
from .export_cache import read_mdd, read_pc2, write_mdd, write_pc2
from .export_common import EXPORTERS, ExportError, polygons_from_fan, register_exporter, unused_vertices
from .export_gltf import parse_glb, read_glb, write_glb
from .export_obj import read_obj_sequence, write_obj_sequence
from .export_usd import read_usd, up_axis_of, write_usda, write_usdc

#: suffixes whose writers take the user's ``up_axis`` ("Y" or "Z")
UP_AXIS_SUFFIXES = (".usda", ".usdc", ".usd")


def valid_suffixes() -> str:
    """The registered suffixes as a human-readable list for error messages."""
    named = sorted(s for s in EXPORTERS if s)
    extra = ", or no suffix (a folder of OBJ files)" if "" in EXPORTERS else ""
    return ", ".join(named) + extra


def exporter_for(path: str | Path):
    """The writer registered for ``path``'s suffix (case-insensitive).

    Raises
    ------
    ExportError
        Unknown suffix; the message lists the valid ones.
    """
    suffix = Path(path).suffix.lower()
    try:
        return EXPORTERS[suffix]
    except KeyError:
        raise ExportError(f"unknown output format {suffix!r}; valid: {valid_suffixes()}", path) from None


def _same_file(a: Path, b: Path) -> bool:
    """``a`` and ``b`` name one file (or folder): the same inode when both exist, else the
    same absolute path after resolving links."""
    try:
        if a.exists() and b.exists():
            return a.samefile(b)
    except OSError:
        pass
    return a.resolve() == b.resolve()


def protect_inputs(path: str | Path, inputs: Mapping[str, str | Path | None]) -> None:
    """Refuse an output path that is one of the user's input files or a folder holding one
    (an OBJ-sequence folder replaces what it names).

    Parameters
    ----------
    path : the output path.
    inputs : what each input is called in the message -> its path; ``None`` entries are skipped.

    Raises
    ------
    ExportError
    """
    out = Path(path)
    for what, given in inputs.items():
        if not given:
            continue
        given = Path(given)
        if _same_file(out, given):
            raise ExportError(f"is your {what}; faceforge never overwrites its inputs: choose another "
                              "output path", path)
        if any(_same_file(out, parent) for parent in given.absolute().parents):
            raise ExportError(f"holds your {what} ({given.name}); faceforge never overwrites its inputs: "
                              "choose another output path", path)


def check_output(path: str | Path, inputs: Mapping[str, str | Path | None] | None = None) -> None:
    """Fail early (before any simulation) on an output the export could not write or must not
    write: one of ``inputs`` (see :func:`protect_inputs`), an unknown suffix, a folder that does
    not exist or is not writable (a cache, or an OBJ sequence's folder, is written into it), or
    binary USD without ``usd-core``. Raises ExportError."""
    from faceforge.io.writable import check_folder

    protect_inputs(path, inputs or {})
    exporter_for(path)
    check_folder(path, "-o", ExportError)
    if Path(path).suffix.lower() in (".usdc", ".usd"):
        export_usd.require_usd_core(path)


def blender_notes(path: str | Path, faces, n_verts: int) -> list[str]:
    """What of an export will not survive Blender's importers, as lines for the user's log.

    Blender 4.5's OBJ and glTF importers drop vertices that no face uses (measured with
    ``tools/blender_check.py``). faceforge keeps them, in the user's order, so:

    * ``.pc2`` / ``.mdd`` on a re-imported OBJ: the Mesh Cache modifier finds fewer vertices
      than the cache and does nothing ("Vertex count mismatch");
    * ``.glb`` / OBJ sequence: every vertex after the first loose one has a smaller index in
      Blender than in the user's mesh.

    Parameters
    ----------
    path : the output path (its suffix picks the message)
    faces : (m, k) int array or sequence of int sequences, 0-based
    n_verts : int

    Returns
    -------
    list of str
        Empty when every vertex is used by a face.
    """
    loose = unused_vertices(faces, n_verts)
    if loose.size == 0:
        return []
    count = "1 vertex" if loose.size == 1 else f"{loose.size} vertices"
    which = f"{count} (first: index {loose[0]}) used by no face"
    if Path(path).suffix.lower() in (".pc2", ".mdd"):
        return [f"{which}; Blender's OBJ importer drops them, so a Mesh Cache on the re-imported mesh "
                "reports 'Vertex count mismatch': apply the cache to the object the mesh was exported "
                "from, or delete loose vertices before `faceforge fit`"]
    return [f"{which}; Blender's importers drop them, so the vertices after index {loose[0]} "
            "have smaller numbers in Blender than in your mesh"]


def export_animation(path: str | Path, frames, faces, fps: float, up_axis: str = "Y") -> Path:
    """Write ``frames`` with the exporter chosen by ``path``'s suffix.

    Parameters
    ----------
    path : path
        ``.pc2``, ``.mdd``, ``.glb``, or a folder path without a suffix (OBJ sequence).
    frames : (n_frames, n_verts, 3) float
        Positions per frame in the input mesh's units and vertex order.
    faces : (m, k) int array or sequence of int sequences
        The input mesh's faces, 0-based.
    fps : float
        Frames per second.
    up_axis : "Y" or "Z"
        The up axis of the frames' coordinates, for the formats that record one (USD).

    Returns
    -------
    Path
        What was written.
    """
    writer = exporter_for(path)
    if Path(path).suffix.lower() in UP_AXIS_SUFFIXES:
        return writer(path, frames, faces, fps, up_axis=up_axis)
    return writer(path, frames, faces, fps)


def export_for_mesh(path: str | Path, frames, mesh: str | Path, fps: float,
                    up_axis: str = "Y") -> tuple[Path, list[str]]:
    """Write ``frames`` of the user's ``mesh`` with its own polygons (quads, n-gons kept).

    frames : (n_frames, n_verts, 3) float in ``mesh``'s vertex order; mesh : the input mesh
    file (read again for its polygons); up_axis : of the mesh's frame (:func:`up_axis_of`).
    Returns (what was written, :func:`blender_notes`).
    Raises ExportError naming ``mesh`` when its vertex count is not the animation's.
    """
    from .mesh import load_mesh

    vertices, faces, info = load_mesh(mesh)
    if len(vertices) != frames.shape[1]:
        raise ExportError(f"has {len(vertices)} vertices but the animation {frames.shape[1]}; "
                          "rerun `faceforge fit`", mesh)
    polygons = polygons_from_fan(faces, info.face_source)
    written = export_animation(path, frames, polygons, fps, up_axis)
    return written, blender_notes(path, polygons, frames.shape[1])


__all__ = [
    "EXPORTERS",
    "ExportError",
    "blender_notes",
    "check_output",
    "protect_inputs",
    "export_animation",
    "export_for_mesh",
    "exporter_for",
    "parse_glb",
    "polygons_from_fan",
    "read_glb",
    "read_mdd",
    "read_obj_sequence",
    "read_pc2",
    "read_usd",
    "register_exporter",
    "up_axis_of",
    "valid_suffixes",
    "write_glb",
    "write_mdd",
    "write_obj_sequence",
    "write_pc2",
    "write_usda",
    "write_usdc",
]
