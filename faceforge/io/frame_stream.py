"""Animation frames streamed to and from a stage file, a take's memory independent of its length.

A 10,000-frame take held every frame several times over (float64 from the simulation, the
lids, the checks, the head turn, the user's order, float32 for the file) and peaked at
4.9 GB, 0.46 MB a frame (issue 28). The animate stage now writes its frames chunk by chunk
(:class:`FrameNpzWriter`) and the exporters read them through a read-only map of the file
(:func:`open_frames`), a chunk at a time (:func:`iter_chunks`).

The file stays an ordinary ``.npz`` (``np.load`` reads it, ``frames`` included): its members
are stored uncompressed, so the ``frames`` member's data is a plain run of bytes in the zip
and can be mapped in place.
"""

from __future__ import annotations

import zipfile
from pathlib import Path
from typing import Iterator

import numpy as np

from faceforge.exceptions import StageError

#: frames per chunk of the streamed passes (a few MB for the largest sample head)
CHUNK = 64


class FrameNpzWriter:
    """Write ``frames (F, n, 3) float32`` into an ``.npz`` chunk by chunk, then the other
    (small) arrays. ``F`` and ``n`` are given up front (the ``.npy`` header comes first).

    Use as a context manager; :meth:`write` takes ``(k, n, 3)`` chunks in order, and
    :meth:`close` (or leaving the ``with``) checks that exactly ``F`` frames came and adds
    ``arrays``. An exception inside the ``with`` leaves a partial file (the stage's temp
    folder is removed by the runner)."""

    def __init__(self, path: str | Path, n_frames: int, n_verts: int, dtype=np.float32):
        self.path = Path(path)
        self.shape = (int(n_frames), int(n_verts), 3)
        self.dtype = np.dtype(dtype)
        self.written = 0
        self._spools: dict = {}   # name -> [temporary file, dtype, row shape, rows]
        self._zip = zipfile.ZipFile(self.path, "w", compression=zipfile.ZIP_STORED, allowZip64=True)
        self._member = self._zip.open("frames.npy", "w", force_zip64=True)
        np.lib.format.write_array_header_1_0(
            self._member, {"descr": np.lib.format.dtype_to_descr(self.dtype), "fortran_order": False,
                           "shape": self.shape})

    def write(self, chunk: np.ndarray) -> None:
        """Append ``chunk (k, n, 3)`` (cast to the file's dtype)."""
        chunk = np.ascontiguousarray(chunk, dtype=self.dtype)
        if chunk.ndim != 3 or chunk.shape[1:] != self.shape[1:]:
            raise ValueError(f"chunk must be (k, {self.shape[1]}, 3), got {chunk.shape}")
        if self.written + len(chunk) > self.shape[0]:
            raise ValueError(f"more than the {self.shape[0]} frames announced")
        self._member.write(chunk.tobytes())
        self.written += len(chunk)

    #: a value of :meth:`close` standing for the rows given to :meth:`spool` under that name
    SPOOLED = object()

    def spool(self, name: str, rows: np.ndarray) -> None:
        """Append ``rows (k, ...)`` to the array ``name``, kept in a temporary file beside the
        output (not in memory) until :meth:`close` writes it (``name=FrameNpzWriter.SPOOLED``):
        per-frame tables (contractions, jaw DOFs) of a long take."""
        import tempfile

        rows = np.ascontiguousarray(rows)
        if name not in self._spools:
            self._spools[name] = [tempfile.TemporaryFile(dir=self.path.parent), rows.dtype, rows.shape[1:], 0]
        spool = self._spools[name]
        if rows.dtype != spool[1] or rows.shape[1:] != spool[2]:
            raise ValueError(f"{name}: rows {rows.dtype} {rows.shape[1:]} after {spool[1]} {spool[2]}")
        spool[0].write(rows.tobytes())
        spool[3] += len(rows)

    def close(self, **arrays) -> None:
        """Finish ``frames`` and add ``arrays`` (name -> array, or :data:`SPOOLED`) as members
        ``name.npy``, in the order given (bytes as ``np.savez`` writes them)."""
        self._member.close()
        if self.written != self.shape[0]:
            self._close_all()
            raise ValueError(f"{self.written} frames written, {self.shape[0]} announced")
        for name, value in arrays.items():
            with self._zip.open(f"{name}.npy", "w", force_zip64=True) as fh:
                if value is self.SPOOLED:
                    self._copy_spool(name, fh)
                else:
                    np.lib.format.write_array(fh, np.asanyarray(value), allow_pickle=False)
        self._close_all()

    def _copy_spool(self, name: str, fh) -> None:
        """Write the spooled array ``name`` (its ``.npy`` header, then its rows) to ``fh``."""
        import shutil

        tmp, dtype, row_shape, n = self._spools[name]
        header = {"descr": np.lib.format.dtype_to_descr(dtype), "fortran_order": False,
                  "shape": (n, *row_shape)}
        np.lib.format.write_array_header_1_0(fh, header)   # the version np.save picks for a small header
        tmp.seek(0)
        shutil.copyfileobj(tmp, fh, 1 << 20)

    def _close_all(self) -> None:
        for spool in self._spools.values():
            spool[0].close()
        self._zip.close()

    def __enter__(self) -> "FrameNpzWriter":
        return self

    def __exit__(self, kind, *rest) -> None:
        if kind is not None:
            self._member.close()
            self._close_all()


def open_frames(path: str | Path, name: str = "frames") -> np.ndarray:
    """The ``name`` array of the ``.npz`` at ``path`` as a read-only ``np.memmap`` when it is
    stored uncompressed (as :class:`FrameNpzWriter` and ``np.savez`` store it), else loaded.
    Raises :class:`StageError` naming the file when it is unreadable."""
    path = Path(path)
    try:
        with zipfile.ZipFile(path) as zf:
            info = zf.getinfo(f"{name}.npy")
            if info.compress_type != zipfile.ZIP_STORED:
                with np.load(path, allow_pickle=False) as data:
                    return data[name]
            with open(path, "rb") as fh:
                fh.seek(info.header_offset)
                local = fh.read(30)
                if local[:4] != b"PK\x03\x04":
                    raise ValueError("bad local header")
                skip = int.from_bytes(local[26:28], "little") + int.from_bytes(local[28:30], "little")
                fh.seek(info.header_offset + 30 + skip)
                version = np.lib.format.read_magic(fh)
                read_header = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                               else np.lib.format.read_array_header_2_0)
                shape, fortran, dtype = read_header(fh)
                offset = fh.tell()
        if fortran or dtype.hasobject:
            raise ValueError("not a plain C-order array")
        if int(np.prod(shape)) == 0:
            return np.zeros(shape, dtype)
        return np.memmap(path, dtype=dtype, mode="r", offset=offset, shape=shape)
    except FileNotFoundError:
        raise StageError("file not found", path) from None
    except KeyError:
        raise StageError(f"has no {name!r} array", path) from None
    except (OSError, ValueError, zipfile.BadZipFile) as exc:
        raise StageError(f"not a readable npz file: {exc}", path) from None


def release(frames) -> None:
    """Drop the pages of the file map under ``frames`` (a map from :func:`open_frames`, or a
    view of one) from this process's memory: they are clean and are read again if touched.
    Exporters call it after each chunk, so reading a long take does not leave it all
    resident (the pages of a map count in the peak RSS). No-op for an ordinary array."""
    import mmap

    node = frames
    while node is not None:
        mm = getattr(node, "_mmap", None)
        if mm is not None:
            if hasattr(mm, "madvise") and hasattr(mmap, "MADV_DONTNEED"):
                mm.madvise(mmap.MADV_DONTNEED)
            return
        node = getattr(node, "base", None)


def iter_chunks(frames: np.ndarray, chunk: int = CHUNK) -> Iterator[np.ndarray]:
    """``frames[i:i + chunk]`` for i = 0, chunk, ... (views: a map reads only that part)."""
    for start in range(0, len(frames), chunk):
        yield frames[start:start + chunk]
