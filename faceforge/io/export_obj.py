"""OBJ sequences: a folder ``NAME/`` holding ``NAME_0001.obj``, ``NAME_0002.obj``, ...

Every file has the input's vertex order and faces (triangles, quads and n-gons kept as
they are, 1-based ``f`` lines without texture or normal indices); coordinates are written
with 9 significant digits, which round-trips float32 exactly. Frame numbers start at 1
and have at least 4 digits (more when there are more than 9999 frames).

The whole folder is written under a temporary name and renamed into place; it gets the
mode ``mkdir`` would give it (the umask), not ``mkdtemp``'s owner-only 0o700. An existing
``NAME/`` is replaced only if it holds nothing but an earlier sequence (``NAME_<digits>.obj``
files); anything else there raises :class:`ExportError` rather than deleting user files.
"""

from __future__ import annotations

import os
import re
import shutil
import tempfile
from pathlib import Path

import numpy as np

from .export_common import ExportError, faces_to_csr, register_exporter, validate_animation
from .frame_stream import release


def _sequence_pattern(name: str) -> re.Pattern[str]:
    return re.compile(re.escape(name) + r"_\d+\.obj")


def _folder_mode() -> int:
    """0o777 minus the process umask, the mode ``mkdir`` would give."""
    mask = os.umask(0o022)
    os.umask(mask)
    return 0o777 & ~mask


def _face_text(indices: np.ndarray, starts: np.ndarray) -> str:
    one_based = (indices + 1).astype(str)
    return "".join("f " + " ".join(one_based[a:b]) + "\n" for a, b in zip(starts[:-1], starts[1:]))


def _vertex_text(positions: np.ndarray) -> str:
    flat = positions.astype(np.float64).ravel().tolist()
    return ("v %.9g %.9g %.9g\n" * positions.shape[0]) % tuple(flat)


def write_obj(path: str | Path, positions: object, faces: object, comment: str = "") -> Path:
    """Write one posed mesh as an OBJ file (the input's vertex order and polygons, as a sequence's
    frame is written), replacing ``path`` atomically.

    positions : (n_verts, 3) float; faces : (m, k) int array or sequence of int sequences, 0-based;
    comment : one header line (without the ``#``).
    """
    from faceforge.io.stagefiles import atomic_write_bytes

    data = np.asarray(positions, dtype=np.float64)
    if data.ndim != 2 or data.shape[1] != 3:
        raise ExportError(f"expected positions (n, 3), got {data.shape}", path)
    indices, starts = faces_to_csr(faces, data.shape[0])
    header = f"# {comment}\n" if comment else ""
    text = header + f"o {Path(path).stem}\n" + _vertex_text(data) + _face_text(indices, starts)
    atomic_write_bytes(Path(path), text.encode("ascii"))
    return Path(path)


def write_obj_sequence(path: str | Path, frames: object, faces: object, fps: float) -> Path:
    """Write one OBJ file per frame into the folder ``path``.

    Parameters
    ----------
    path : path of the folder (no suffix); its name prefixes the files
    frames : (n_frames, n_verts, 3) float
        Positions per frame, model units (written at float32 precision).
    faces : (m, k) int array or sequence of int sequences
        0-based; kept as given (quads stay quads).
    fps : float
        Recorded in each file's header comment.

    Returns
    -------
    Path
        The folder.

    Raises
    ------
    ExportError
        ``path`` is a file, or a folder holding anything but an earlier sequence.
    """
    data = validate_animation(frames, fps)
    indices, starts = faces_to_csr(faces, data.shape[1])
    folder = Path(path)
    name = folder.name
    if not name:
        raise ExportError("an OBJ sequence needs a folder name", folder)
    pattern = _sequence_pattern(name)
    if folder.exists():
        if not folder.is_dir():
            raise ExportError("exists and is not a folder; an OBJ sequence is written to a folder", folder)
        foreign = [p.name for p in folder.iterdir() if not pattern.fullmatch(p.name)]
        if foreign:
            raise ExportError(
                f"folder holds other files ({', '.join(sorted(foreign)[:3])}); choose an empty or new folder", folder
            )
    if not folder.parent.is_dir():
        raise ExportError("parent folder does not exist", folder)
    width = max(4, len(str(data.shape[0])))
    face_text = _face_text(indices, starts)
    clean_leftovers(folder)
    staging = Path(tempfile.mkdtemp(prefix=f".{name}.{os.getpid()}.", suffix=".tmp", dir=folder.parent))
    try:
        staging.chmod(_folder_mode())  # mkdtemp makes it 0o700; a plain mkdir would honour the umask
        for k, positions in enumerate(data):
            header = f"# faceforge OBJ sequence: frame {k + 1} of {data.shape[0]} at {float(fps):g} fps\n"
            text = header + f"o {name}\n" + _vertex_text(positions) + face_text
            (staging / f"{name}_{k + 1:0{width}d}.obj").write_text(text, encoding="ascii")
            if k % 64 == 63:
                release(data)   # a long take read through a file map: keep only a chunk resident
        if folder.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{name}.{os.getpid()}.", suffix=".old", dir=folder.parent))
            folder.rename(old / name)
            staging.rename(folder)
            shutil.rmtree(old)
        else:
            staging.rename(folder)
    finally:
        if staging.exists():
            shutil.rmtree(staging)
    return folder


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError):
        return True
    return True


def clean_leftovers(folder: str | Path) -> list[Path]:
    """Remove what a killed :func:`write_obj_sequence` to ``folder`` left beside it: its
    staging folder ``.<name>.<pid>.<random>.tmp`` and the ``.old`` folder holding the previous
    sequence while it was being replaced (put back first when ``folder`` itself is missing, so
    the user's earlier sequence is not lost). Folders of a process still running are kept;
    ``.<name>.<random>.tmp`` of faceforge versions before the pid was in the name are removed.
    Returns the removed paths."""
    folder = Path(folder)
    name, parent = folder.name, folder.parent
    if not name or not parent.is_dir():
        return []
    pattern = re.compile(r"\." + re.escape(name) + r"\.(?:(\d+)\.)?[A-Za-z0-9_]{8}\.(tmp|old)")
    removed = []
    for entry in sorted(parent.iterdir(), key=lambda p: p.name):
        m = pattern.fullmatch(entry.name)
        if m is None or not entry.is_dir() or (m.group(1) and _alive(int(m.group(1)))):
            continue
        if m.group(2) == "old" and (entry / name).is_dir() and not folder.exists():
            (entry / name).rename(folder)      # killed between moving the old sequence aside and the new in
        shutil.rmtree(entry, ignore_errors=True)
        removed.append(entry)
    return removed


def read_obj_sequence(path: str | Path) -> tuple[np.ndarray, list[tuple[int, ...]]]:
    """Read a sequence written by :func:`write_obj_sequence` (any OBJ with ``v``/``f`` lines).

    Returns
    -------
    frames : (n_frames, n_verts, 3) float32
        In file-number order.
    faces : list of tuples of int
        0-based faces of the first file (the others must match).

    Raises
    ------
    ExportError
        No files, or files that disagree in vertex count or faces.
    """
    folder = Path(path)
    pattern = re.compile(re.escape(folder.name) + r"_(\d+)\.obj")
    files = sorted(
        (int(m.group(1)), p) for p in folder.glob("*.obj") if (m := pattern.fullmatch(p.name)) is not None
    ) if folder.is_dir() else []
    if not files:
        raise ExportError(f"no {folder.name}_NNNN.obj files", folder)
    frames, faces = [], None
    for _, file in files:
        vertices, polys = [], []
        for line in file.read_text(encoding="ascii").splitlines():
            tokens = line.split()
            if not tokens:
                continue
            if tokens[0] == "v":
                vertices.append([float(x) for x in tokens[1:4]])
            elif tokens[0] == "f":
                polys.append(tuple(int(t.split("/")[0]) - 1 for t in tokens[1:]))
        if faces is None:
            faces = polys
        elif polys != faces or len(vertices) != len(frames[0]):
            raise ExportError("faces or vertex count differ from the first file", file)
        frames.append(np.array(vertices, dtype=np.float64))
    return np.stack(frames).astype(np.float32), faces or []


register_exporter("", write_obj_sequence)
