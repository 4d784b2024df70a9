"""Animation exporters, chosen by the output path's suffix.

=============  ===========================================  =================================
``-o`` path    format                                       module
=============  ===========================================  =================================
``x.pc2``      PC2 point cache (little endian, float32)     :mod:`faceforge.io.export_cache`
``x.mdd``      MDD point cache (big endian, float32)        :mod:`faceforge.io.export_cache`
``x.glb``      glTF binary, morph targets + weights anim.   :mod:`faceforge.io.export_gltf`
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
faceforge works in the MPEG-4 frame: +Y up, the face looks along +Z (glTF's convention too).
Blender is Z-up.

* ``.glb``: File > Import > glTF 2.0. The importer converts +Y up to Z-up itself; the
  animation is one shape key per frame with animated values. Nothing to set.
* ``.pc2`` / ``.mdd``: import the *same mesh* that was animated (same vertex order) with
  File > Import > Wavefront OBJ, keeping its defaults (Forward -Z, Up Y), then add a
  Mesh Cache modifier and pick the file. The caches hold raw +Y-up coordinates, so the
  modifier's axes must undo what the importer did:

  - Blender 3.0+ (the C++ OBJ importer) puts the Y-up to Z-up conversion on the *object*
    (Rotation X = 90 deg) and leaves the vertices raw: keep the Mesh Cache defaults
    (Forward Axis +Y, Up Axis +Z, i.e. no conversion).
  - If the conversion was baked into the vertices (the legacy Python importer, or after
    Object > Apply > Rotation), set the modifier's Forward Axis to -Z and Up Axis to +Y,
    the same pair as the OBJ importer.

  In the modifier's default "Frame" time mode, cache sample ``i`` is shown at scene frame
  ``Frame Start + i`` (the header's start frame and MDD times are ignored), so set the
  modifier's Frame Start to the scene's first frame and the scene's frame rate to ``fps``.
* OBJ sequence: every file imports as its own object (same axes as above); Blender has no
  built-in sequence importer, but the folder is what sequence add-ons and other tools read.
"""

from __future__ import annotations

from pathlib import Path

from . import export_cache, export_gltf, export_obj  # noqa: F401  (each registers its suffixes)
from .export_cache import read_mdd, read_pc2, write_mdd, write_pc2
from .export_common import EXPORTERS, ExportError, polygons_from_fan, register_exporter
from .export_gltf import parse_glb, read_glb, write_glb
from .export_obj import read_obj_sequence, write_obj_sequence


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


def export_animation(path: str | Path, frames, faces, fps: float) -> Path:
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

    Returns
    -------
    Path
        What was written.
    """
    return exporter_for(path)(path, frames, faces, fps)


__all__ = [
    "EXPORTERS",
    "ExportError",
    "export_animation",
    "exporter_for",
    "parse_glb",
    "polygons_from_fan",
    "read_glb",
    "read_mdd",
    "read_obj_sequence",
    "read_pc2",
    "register_exporter",
    "valid_suffixes",
    "write_glb",
    "write_mdd",
    "write_obj_sequence",
    "write_pc2",
]
