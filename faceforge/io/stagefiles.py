"""Stage files: npz (never pickled), JSON and YAML, each written atomically.

Every writer writes to a temporary file beside the target and renames it into
place (``os.replace``), so a reader never sees half a file. Readers raise
:class:`~faceforge.exceptions.StageError` naming the file when it is missing or
malformed. numpy is imported inside the npz functions only.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Any, Mapping

from faceforge.exceptions import StageError


def _file_mode() -> int:
    """0o666 minus the process umask (mkstemp alone would give 0o600)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return 0o666 & ~mask


def atomic_write_bytes(path: str | Path, data, make_parents: bool = True) -> Path:
    """Write ``data`` (bytes, or an iterable of byte chunks) to ``path`` through a temporary
    file next to it and ``os.replace``, with the usual file mode (umask), fsynced: a reader
    never sees half a file. ``make_parents``: create missing folders (else ``OSError``)."""
    path = Path(path)
    if make_parents:
        path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        os.fchmod(fd, _file_mode())
        with os.fdopen(fd, "wb") as fh:
            for chunk in [data] if isinstance(data, (bytes, bytearray, memoryview)) else data:
                fh.write(chunk)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
    return path


def _plain(value: Any) -> Any:
    """Convert numpy scalars/arrays and Paths into JSON/YAML-safe Python values."""
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, Path):
        return str(value)
    if hasattr(value, "tolist") and type(value).__module__ == "numpy":
        return value.tolist()
    return value


def save_json(path: str | Path, data: Any) -> Path:
    """Write ``data`` as indented, key-sorted UTF-8 JSON (numpy values converted)."""
    text = json.dumps(_plain(data), indent=2, sort_keys=True, allow_nan=False) + "\n"
    return atomic_write_bytes(path, text.encode("utf-8"))


def load_json(path: str | Path) -> Any:
    """Read a JSON file; missing or malformed files raise :class:`StageError`."""
    path = Path(path)
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise StageError("file not found", path) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise StageError(f"cannot read: {exc}", path) from None
    except json.JSONDecodeError as exc:
        raise StageError(f"malformed JSON: {exc.msg}", path, exc.lineno) from None


def save_yaml(path: str | Path, data: Any, header: str = "") -> Path:
    """Write ``data`` as block-style YAML (insertion order kept), with an optional ``# header``."""
    import yaml

    text = yaml.safe_dump(_plain(data), sort_keys=False, default_flow_style=False, allow_unicode=True)
    if header:
        text = "".join(f"# {line}\n" for line in header.splitlines()) + text
    return atomic_write_bytes(path, text.encode("utf-8"))


def yaml_safe_load(text: str) -> Any:
    """``yaml.safe_load`` through libyaml's C parser when PyYAML has it (the muscle map parses
    ten times faster); the same documents, the same errors (``yaml.YAMLError`` with marks)."""
    import yaml

    return yaml.load(text, Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))


def load_yaml(path: str | Path) -> Any:
    """Read a YAML file with the safe loader; errors name the file and line."""
    import yaml

    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise StageError("file not found", path) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise StageError(f"cannot read: {exc}", path) from None
    try:
        return yaml_safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        line = None if mark is None else mark.line + 1
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise StageError(f"malformed YAML: {problem}", path, line) from None


def save_npz(path: str | Path, **arrays: Any) -> Path:
    """Write arrays to an uncompressed ``.npz``; object arrays are refused (no pickle).

    Parameters
    ----------
    path : output file; numpy appends nothing (the name is kept as given).
    **arrays : name -> array-like of a numeric, bool or fixed-width string dtype.
    """
    import io

    import numpy as np

    converted = {}
    for name, value in arrays.items():
        array = np.asarray(value)
        if array.dtype.hasobject:
            raise ValueError(f"save_npz: array {name!r} has dtype object, which would need pickle")
        converted[name] = array
    buffer = io.BytesIO()
    np.savez(buffer, **converted)
    return atomic_write_bytes(path, buffer.getvalue())


def load_npz(path: str | Path) -> dict:
    """Read every array of an ``.npz`` into a dict, with ``allow_pickle=False``."""
    import zipfile

    import numpy as np

    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            return {name: data[name] for name in data.files}
    except FileNotFoundError:
        raise StageError("file not found", path) from None
    except (OSError, ValueError, zipfile.BadZipFile) as exc:
        raise StageError(f"not a readable npz file: {exc}", path) from None
