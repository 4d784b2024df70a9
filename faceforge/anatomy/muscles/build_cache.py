"""The built muscles of a fitted head kept on disk between commands (issues 25 and 27: time).

Every command that plays a fitted head (calibrate, bake, animate, expressions, match, arkit)
rebuilds its muscles from the template and the fitted points
(:func:`faceforge.animation.rig.muscle_system`): the template skull read and checked, the muscle
map projected onto it, every action line projected onto the layers under it, the hexahedral
sheets morphed -- about 3 s of CPU on the MakeHuman sample, the same work with the same result
in every command. This module stores what :func:`~faceforge.anatomy.muscles.build.build_muscles_on`
returned, keyed by everything it read, and gives it back bit for bit; :func:`cached` does the same
for other rest-state builds of the rig (the skull guard and the bone collision of
:mod:`faceforge.animation.guards`, ~0.8 s of CPU on MakeHuman).

A cache file is ``<folder>/<kind>-<key>.npz`` (``muscles``, ``skullguard``, ``collision``; no
pickle): the arrays under ``a0``, ``a1``, ... and ``tree`` (a 0-d unicode array) holding the JSON
description of the object graph (:func:`encode`): dataclasses and plain objects (their
``__dict__``) of :data:`MODULES`, dicts, lists, tuples, ``None``, ``bool``, ``int``, ``float``
(JSON keeps a float's repr, so its bits), ``str`` and arrays (``np.save`` keeps dtype, shape and
memory order). An object is rebuilt without calling its ``__init__`` (its fields set as they
were: a muscle's ``__post_init__`` would recompute its constraints). Anything else (a numpy
scalar, a function, an object of another package) makes :func:`save_muscles` store nothing. A
missing, unreadable or foreign file is a miss: the caller builds again.

The key (:func:`cache_key`) hashes the caller's inputs and the source of the code that builds
them (:data:`CODE_PACKAGES`), so an edit of that code misses instead of returning a stale
build. At most :data:`KEEP` files of a kind are kept per folder (oldest removed first).
"""

from __future__ import annotations

import dataclasses
import hashlib
import importlib
import json
import os
from pathlib import Path

import numpy as np

#: the packages and modules whose source enters the key: the muscle build, the geometry it projects
#: with, the dtypes it builds in, the YAML reader of the templates, the rig that calls the build with
#: its config keys
CODE_PACKAGES = ("faceforge.anatomy", "faceforge.geometry", "faceforge.animation.guards", "faceforge.constants",
                 "faceforge.io.stagefiles", "faceforge.animation.rig")
#: the libraries whose versions enter the key (numerics, the ray caster)
LIBRARIES = ("numpy", "numba", "trimesh", "embreex", "pyyaml")
#: the modules whose objects a cache file may hold (dataclasses, or plain objects: their ``__dict__``)
MODULES = ("faceforge.anatomy.", "faceforge.geometry.", "faceforge.animation.guards.")
#: files kept per cache folder
KEEP = 8
#: bumped when the file layout changes
FORMAT = "1"

_code_digest = None


def code_digest() -> str:
    """SHA-256 of the ``.py`` sources of :data:`CODE_PACKAGES` (relative names and bytes) and the
    versions of :data:`LIBRARIES`, once per process."""
    global _code_digest
    if _code_digest is None:
        from importlib import metadata

        h = hashlib.sha256(FORMAT.encode())
        for name in CODE_PACKAGES:
            module = importlib.import_module(name)
            path = Path(module.__file__)
            files = sorted(path.parent.rglob("*.py")) if hasattr(module, "__path__") else [path]
            for p in files:
                h.update(f"{name}:{p.relative_to(path.parent).as_posix()}".encode() + b"\0" + p.read_bytes() + b"\0")
        for lib in LIBRARIES:
            try:
                h.update(f"{lib}={metadata.version(lib)}".encode())
            except metadata.PackageNotFoundError:
                h.update(f"{lib}=none".encode())
        _code_digest = h.hexdigest()
    return _code_digest


def cache_key(items) -> str:
    """Hex key of ``items`` (an iterable of ``(name, value)``; value: an array, bytes, a file or
    folder path (:class:`Path`: its bytes, a folder's files by relative name) or anything
    ``json.dumps`` writes with sorted keys) and :func:`code_digest`."""
    h = hashlib.sha256(code_digest().encode())
    for name, value in items:
        h.update(b"\0" + str(name).encode() + b"\0")
        if isinstance(value, np.ndarray):
            a = np.ascontiguousarray(value)
            h.update(f"{a.dtype.str}{a.shape}".encode())
            h.update(a.tobytes() if a.dtype != object else repr(a.tolist()).encode())
        elif isinstance(value, bytes):
            h.update(value)
        elif isinstance(value, Path):
            files = sorted(q for q in value.rglob("*") if q.is_file()) if value.is_dir() else [value]
            for q in files:
                h.update(q.relative_to(value).as_posix().encode() if value.is_dir() else b"")
                h.update(b"\0" + q.read_bytes())
        else:
            h.update(json.dumps(value, sort_keys=True, default=repr).encode())
    return h.hexdigest()[:32]


class _Unstorable(TypeError):
    """An object :func:`encode` cannot describe."""


def encode(obj, arrays: list, seen: dict | None = None):
    """A JSON-able description of ``obj``; its arrays appended to ``arrays`` (an array met twice
    is stored once and comes back as one object: ``seen`` maps ``id`` -> index)."""
    seen = {} if seen is None else seen
    if obj is None or isinstance(obj, (bool, str)) or type(obj) in (int, float):
        return obj
    if isinstance(obj, np.ndarray):
        if obj.dtype == object:
            raise _Unstorable("object array")
        if id(obj) not in seen:
            seen[id(obj)] = len(arrays)
            arrays.append(obj)
        return {"@a": seen[id(obj)]}
    if isinstance(obj, (list, tuple)):
        return {"@l" if isinstance(obj, list) else "@t": [encode(x, arrays, seen) for x in obj]}
    if type(obj) is dict:
        return {"@d": [[encode(k, arrays, seen), encode(v, arrays, seen)] for k, v in obj.items()]}
    cls = type(obj)
    if cls.__module__.startswith(MODULES) and not isinstance(obj, type) and hasattr(obj, "__dict__") \
            and not hasattr(cls, "__slots__"):
        names = [f.name for f in dataclasses.fields(obj)] if dataclasses.is_dataclass(obj) else list(vars(obj))
        if set(vars(obj)) != set(names):
            raise _Unstorable(f"{cls.__qualname__} holds attributes besides its fields")
        return {"@c": f"{cls.__module__}:{cls.__qualname__}",
                "f": {n: encode(getattr(obj, n), arrays, seen) for n in names}}
    raise _Unstorable(f"{cls.__module__}.{cls.__qualname__}")


def decode(desc, arrays):
    """Inverse of :func:`encode` (``arrays``: indexable by the stored indices)."""
    if not isinstance(desc, dict):
        return desc
    if "@a" in desc:
        return arrays[desc["@a"]]
    if "@l" in desc:
        return [decode(x, arrays) for x in desc["@l"]]
    if "@t" in desc:
        return tuple(decode(x, arrays) for x in desc["@t"])
    if "@d" in desc:
        return {decode(k, arrays): decode(v, arrays) for k, v in desc["@d"]}
    module, _, qualname = desc["@c"].partition(":")
    if not module.startswith(MODULES):
        raise ValueError(f"not a faceforge dataclass: {desc['@c']}")
    cls = importlib.import_module(module)
    for part in qualname.split("."):
        cls = getattr(cls, part)
    obj = object.__new__(cls)
    for name, value in desc["f"].items():
        object.__setattr__(obj, name, decode(value, arrays))
    return obj


def cached(folder, kind: str, items, build):
    """``build()``, or what a call with the same ``kind`` and key items (:func:`cache_key`) stored
    in ``folder`` (None: no cache, always built); a fresh build is stored."""
    if folder is None:
        return build()
    key = cache_key((("kind", kind), *items))
    obj = load_muscles(folder, key, kind)
    if obj is None:
        obj = build()
        save_muscles(folder, key, obj, kind)
    return obj


def cache_path(folder, key: str, kind: str = "muscles") -> Path:
    """Where the build of ``key`` is kept in ``folder`` (``kind``: what it is, a file name prefix)."""
    return Path(folder) / f"{kind}-{key}.npz"


def load_muscles(folder, key: str, kind: str = "muscles"):
    """What is stored under ``key`` in ``folder``, or None (no file, or one that does not read)."""
    path = cache_path(folder, key, kind)
    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as data:
            tree = json.loads(str(data["tree"][()]))
            arrays = [data[f"a{i}"] for i in range(int(tree["count"]))]
        if tree.get("key") != key or tree.get("kind", "muscles") != kind:
            return None
        return decode(tree["muscles"], arrays)
    except (OSError, ValueError, KeyError, AttributeError, TypeError, json.JSONDecodeError):
        return None


def save_muscles(folder, key: str, muscles, kind: str = "muscles") -> Path | None:
    """Store ``muscles`` (a list of them, or with ``kind`` another object of :data:`MODULES`) under
    ``key`` in ``folder`` (written to a temporary name, then renamed); None when they hold something
    :func:`encode` cannot describe or the folder is not writable. Keeps the :data:`KEEP` newest files."""
    arrays: list = []
    try:
        desc = encode(list(muscles) if kind == "muscles" else muscles, arrays)
    except _Unstorable:
        return None
    folder = Path(folder)
    path = cache_path(folder, key, kind)
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.tmp.npz")
    try:
        folder.mkdir(parents=True, exist_ok=True)
        tree = json.dumps({"key": key, "kind": kind, "count": len(arrays), "muscles": desc})
        np.savez(tmp, tree=np.array(tree), **{f"a{i}": a for i, a in enumerate(arrays)})
        os.replace(tmp, path)
        old = sorted(folder.glob(f"{kind}-*.npz"), key=lambda p: p.stat().st_mtime)[:-KEEP]
        for p in old:
            p.unlink(missing_ok=True)
    except OSError:
        tmp.unlink(missing_ok=True)
        return None
    return path
