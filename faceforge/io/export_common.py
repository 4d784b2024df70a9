"""Shared pieces of the animation exporters: the suffix registry, validation, atomic writes.

Each format module fills :data:`EXPORTERS` with one line at its bottom; the public entry
point is :mod:`faceforge.io.export`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from faceforge.exceptions import FaceforgeError

#: output suffix (lower case, with the dot; ``""`` = a folder) -> ``write(path, frames, faces, fps)``
EXPORTERS: dict[str, Callable[..., Path]] = {}


class ExportError(FaceforgeError):
    """An animation cannot be written (unknown format, unwritable or occupied path) or read back."""


def register_exporter(suffix: str, writer: Callable[..., Path]) -> None:
    """Make ``writer`` the exporter for output paths ending in ``suffix`` (``""``: folders)."""
    EXPORTERS[suffix.lower()] = writer


def validate_animation(frames: object, fps: float) -> np.ndarray:
    """Check an animation and return it as float32.

    Parameters
    ----------
    frames : (n_frames, n_verts, 3) array-like of float
        Vertex positions per frame, model units; n_frames >= 1, n_verts >= 1, all finite.
    fps : float
        Frames per second, finite and > 0.

    Returns
    -------
    (n_frames, n_verts, 3) float32, C-contiguous

    Raises
    ------
    ValueError
        Naming the offending shape or value.
    """
    from faceforge.io.frame_stream import release

    array = np.asarray(frames)
    if array.ndim != 3 or array.shape[2] != 3 or array.shape[0] < 1 or array.shape[1] < 1:
        raise ValueError(f"frames must be (n_frames >= 1, n_verts >= 1, 3), got shape {array.shape}")
    if not np.issubdtype(array.dtype, np.floating) and not np.issubdtype(array.dtype, np.integer):
        raise ValueError(f"frames must be numeric, got dtype {array.dtype}")
    for start in range(0, array.shape[0], 64):   # by chunks: a long take may be a map of a file
        part = array[start:start + 64]
        if not np.all(np.isfinite(part)):
            bad = np.argwhere(~np.isfinite(part))[0]
            raise ValueError(f"frames must be finite; frame {start + bad[0]}, vertex {bad[1]} is not")
        release(array)
    if not (isinstance(fps, (int, float, np.floating, np.integer)) and math.isfinite(fps) and fps > 0):
        raise ValueError(f"fps must be finite and > 0, got {fps!r}")
    return np.ascontiguousarray(array, dtype=np.float32)


def faces_to_csr(faces: object, n_verts: int) -> tuple[np.ndarray, np.ndarray]:
    """Polygon faces (triangles, quads, n-gons, mixed) as compressed rows.

    Parameters
    ----------
    faces : (m, k) int array-like, or a sequence of int sequences (lengths may differ)
        0-based vertex indices, each face >= 3 corners.
    n_verts : int

    Returns
    -------
    indices : (sum of face sizes,) int64
    starts : (m + 1,) int64
        Face ``i`` is ``indices[starts[i]:starts[i + 1]]``.

    Raises
    ------
    ValueError
        A face with fewer than 3 corners or an index outside ``[0, n_verts)``.
    """
    if isinstance(faces, np.ndarray) and faces.ndim == 2:
        rows: Sequence = faces
        sizes = np.full(faces.shape[0], faces.shape[1], dtype=np.int64)
        indices = np.asarray(faces, dtype=np.int64).ravel()
    else:
        rows = [np.asarray(face, dtype=np.int64).ravel() for face in faces]  # type: ignore[union-attr]
        sizes = np.array([len(r) for r in rows], dtype=np.int64)
        indices = np.concatenate(rows) if rows else np.zeros(0, dtype=np.int64)
    if sizes.size and sizes.min() < 3:
        raise ValueError(f"face {int(np.argmin(sizes))} has {int(sizes.min())} corners; faces need >= 3")
    if indices.size and (indices.min() < 0 or indices.max() >= n_verts):
        raise ValueError(f"face indices must lie in [0, {n_verts}), got range [{indices.min()}, {indices.max()}]")
    starts = np.zeros(sizes.size + 1, dtype=np.int64)
    np.cumsum(sizes, out=starts[1:])
    return indices, starts


def unused_vertices(faces: object, n_verts: int) -> np.ndarray:
    """Vertices that no face uses ("loose" vertices).

    Parameters
    ----------
    faces : (m, k) int array-like, or a sequence of int sequences
        0-based.
    n_verts : int

    Returns
    -------
    (u,) int64, ascending
    """
    indices, _ = faces_to_csr(faces, n_verts)
    used = np.zeros(n_verts, dtype=bool)
    used[indices] = True
    return np.flatnonzero(~used)


def triangulate(indices: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """Fan-triangulate CSR polygons: ``(v0, vi, vi+1)``.

    Returns
    -------
    (sum(size - 2), 3) int64
    """
    sizes = np.diff(starts)
    n_tris = sizes - 2
    face_of_tri = np.repeat(np.arange(sizes.size), n_tris)
    tri_starts = np.concatenate([[0], np.cumsum(n_tris)[:-1]]) if sizes.size else np.zeros(0, dtype=np.int64)
    corner = np.arange(face_of_tri.size) - np.repeat(tri_starts, n_tris)
    first = starts[face_of_tri]
    return np.stack(
        [indices[first], indices[first + corner + 1], indices[first + corner + 2]], axis=1
    ).astype(np.int64)


def polygons_from_fan(faces: object, face_source: object) -> list[tuple[int, ...]]:
    """Undo a fan triangulation: recover the input's polygons (quads, n-gons).

    Parameters
    ----------
    faces : (m, 3) int
        Triangles ``(c0, ci, ci+1)`` of each polygon, consecutive, as :func:`triangulate`
        and ``faceforge.io.mesh.load_mesh`` produce them.
    face_source : (m,) int
        Polygon index of each triangle (``MeshInfo.face_source``), non-decreasing from 0.

    Returns
    -------
    list of tuples of int
        One polygon per source index, corners in the original order.

    Raises
    ------
    ValueError
        If the triangles are not such a fan (so the polygons cannot be recovered).
    """
    faces = np.asarray(faces, dtype=np.int64)
    source = np.asarray(face_source, dtype=np.int64)
    if faces.ndim != 2 or faces.shape[1] != 3 or source.shape != (faces.shape[0],):
        raise ValueError(f"faces must be (m, 3) and face_source (m,); got {faces.shape} and {source.shape}")
    if source.size and (source[0] != 0 or np.any(np.diff(source) < 0) or np.any(np.diff(source) > 1)):
        raise ValueError("face_source must count polygons 0, 1, 2, ... with their triangles consecutive")
    bounds = np.flatnonzero(np.diff(source)) + 1
    polygons = []
    for group in np.split(faces, bounds) if source.size else []:
        fan_ok = np.all(group[:, 0] == group[0, 0]) and np.all(group[1:, 1] == group[:-1, 2])
        if not fan_ok:
            raise ValueError(f"triangles of polygon {len(polygons)} are not a fan (c0, ci, ci+1)")
        polygons.append(tuple(int(x) for x in (*group[0], *group[1:, 2])))
    return polygons


def atomic_write_bytes(path: str | Path, chunks: Sequence[bytes] | bytes) -> Path:
    """Write bytes to a temporary file next to ``path`` and rename it into place.

    An interrupted write never leaves a partial file at ``path``.

    Raises
    ------
    ExportError
        The folder does not exist or is not writable, or ``path`` is a folder.
    """
    path = Path(path)
    if path.is_dir():
        raise ExportError("is a folder, expected a file path", path)
    from faceforge.io.stagefiles import atomic_write_bytes as write

    try:
        return write(path, chunks, make_parents=False)
    except OSError as exc:
        raise ExportError(f"cannot write here: {exc.strerror or exc}", path) from None


def read_bytes(path: str | Path, what: str) -> bytes:
    """Read a file for one of the readers; a missing file is an :class:`ExportError`."""
    try:
        return Path(path).read_bytes()
    except OSError as exc:
        raise ExportError(f"cannot read {what}: {exc.strerror or exc}", path) from None
