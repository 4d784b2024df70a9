"""Point caches for Blender's Mesh Cache modifier: PC2 and MDD.

Both store only vertex positions (float32), one block per frame, in the vertex order of
the mesh they deform; faces are not stored. See :mod:`faceforge.io.export` for how to set
the modifier up in Blender.

PC2 (little endian)::

    char[12] "POINTCACHE2\\0"; int32 version = 1; int32 n_points;
    float32 start_frame; float32 sampling (frames per sample); int32 n_samples;
    float32 xyz[n_samples][n_points][3]

MDD (big endian)::

    int32 n_frames; int32 n_points; float32 times[n_frames] (seconds);
    float32 xyz[n_frames][n_points][3]
"""

from __future__ import annotations

import itertools

from pathlib import Path

import numpy as np

from .export_common import (
    ExportError,
    atomic_write_bytes,
    faces_to_csr,
    read_bytes,
    register_exporter,
    validate_animation,
)

PC2_SIGNATURE = b"POINTCACHE2\0"
_PC2_HEADER = np.dtype(
    [
        ("signature", "S12"),
        ("version", "<i4"),
        ("n_points", "<i4"),
        ("start", "<f4"),
        ("sampling", "<f4"),
        ("n_samples", "<i4"),
    ]
)


def write_pc2(path: str | Path, frames: object, faces: object, fps: float, *, start_frame: float = 0.0) -> Path:
    """Write a PC2 point cache.

    Parameters
    ----------
    path : path ending in ``.pc2``
    frames : (n_frames, n_verts, 3) float
        Positions per frame, model units, stored as float32.
    faces : faces of the mesh, or None (validated against ``n_verts`` when given; not stored)
    fps : float
        Not stored by PC2 (it counts in frames, sampling = 1 frame per sample); the Blender
        scene's frame rate must equal it. Validated.
    start_frame : float
        Header start frame (Blender's Mesh Cache ignores it in its default "Frame" time mode).

    Returns
    -------
    Path
    """
    data = validate_animation(frames, fps)
    if faces is not None:
        faces_to_csr(faces, data.shape[1])
    header = np.zeros((), dtype=_PC2_HEADER)
    header["signature"] = PC2_SIGNATURE
    header["version"] = 1
    header["n_points"] = data.shape[1]
    header["start"] = start_frame
    header["sampling"] = 1.0
    header["n_samples"] = data.shape[0]
    return atomic_write_bytes(path, itertools.chain([header.tobytes()], _chunks(data, "<f4")))


def _chunks(data, dtype):
    """The bytes of ``data (F, n, 3)`` as ``dtype``, 64 frames at a time, made as they are
    written (a long take, e.g. a map of the stage file, is never copied whole)."""
    from faceforge.io.frame_stream import release

    for start in range(0, len(data), 64):
        yield data[start:start + 64].astype(dtype, copy=False).tobytes()
        release(data)


def read_pc2(path: str | Path) -> tuple[np.ndarray, float, float]:
    """Read a PC2 file.

    Returns
    -------
    frames : (n_samples, n_points, 3) float32
    start_frame : float
    sampling : float
        Frames per sample.

    Raises
    ------
    ExportError
        Wrong signature or a size that disagrees with the header.
    """
    raw = read_bytes(path, "PC2 cache")
    if len(raw) < _PC2_HEADER.itemsize or raw[:12] != PC2_SIGNATURE:
        raise ExportError("not a PC2 file (no POINTCACHE2 header)", path)
    header = np.frombuffer(raw, dtype=_PC2_HEADER, count=1)[0]
    n_points, n_samples = int(header["n_points"]), int(header["n_samples"])
    body = raw[_PC2_HEADER.itemsize :]
    if n_points < 0 or n_samples < 0 or len(body) != n_points * n_samples * 12:
        raise ExportError(f"size {len(raw)} bytes disagrees with the header ({n_samples} x {n_points} points)", path)
    frames = np.frombuffer(body, dtype="<f4").reshape(n_samples, n_points, 3).astype(np.float32)
    return frames, float(header["start"]), float(header["sampling"])


def write_mdd(path: str | Path, frames: object, faces: object, fps: float) -> Path:
    """Write an MDD point cache (big endian, times ``i / fps`` seconds from 0).

    Parameters are those of :func:`write_pc2` (without ``start_frame``).
    """
    data = validate_animation(frames, fps)
    if faces is not None:
        faces_to_csr(faces, data.shape[1])
    n_frames, n_points = data.shape[:2]
    times = (np.arange(n_frames, dtype=np.float64) / float(fps)).astype(">f4")
    header = np.array([n_frames, n_points], dtype=">i4")
    return atomic_write_bytes(path, itertools.chain([header.tobytes(), times.tobytes()], _chunks(data, ">f4")))


def read_mdd(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Read an MDD file.

    Returns
    -------
    frames : (n_frames, n_points, 3) float32
    times : (n_frames,) float32, seconds
    """
    raw = read_bytes(path, "MDD cache")
    if len(raw) < 8:
        raise ExportError("not an MDD file (shorter than its header)", path)
    n_frames, n_points = (int(x) for x in np.frombuffer(raw[:8], dtype=">i4"))
    expected = 8 + 4 * n_frames + 12 * n_frames * n_points
    if n_frames < 0 or n_points < 0 or len(raw) != expected:
        raise ExportError(f"size {len(raw)} bytes disagrees with the header ({n_frames} x {n_points} points)", path)
    times = np.frombuffer(raw, dtype=">f4", count=n_frames, offset=8).astype(np.float32)
    frames = np.frombuffer(raw, dtype=">f4", offset=8 + 4 * n_frames).reshape(n_frames, n_points, 3)
    return frames.astype(np.float32), times


register_exporter(".pc2", write_pc2)
register_exporter(".mdd", write_mdd)
