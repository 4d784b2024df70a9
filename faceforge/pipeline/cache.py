"""Cache keys of stages and the reasons a stage is stale (DVC-like).

A stage's record holds exactly what its key hashes::

    {"stage": "bind", "version": "1",
     "config": {"bind": {...}},                                # values of its config keys
     "inputs": {"mesh": {"path": "/abs/head.obj", "sha256": "..."}},
     "upstream": {"fit": "<digest of fit's files>"}}

The key is the SHA-256 of the record's canonical JSON with input *paths* left out,
so moving an unchanged file does not rerun anything. ``<workdir>/<name>/stage.json``
stores the record, the key, the outputs and ``output_sha256`` (every file the stage wrote ->
its SHA-256, computed once when it writes them); :func:`stale_reasons` compares it with
the current record and says why in words ("`skin.stiffness.bending` changed").

An upstream enters a key by the *content* of what it wrote (:func:`outputs_digest`), not by its
own key: ``calibrate --force`` after a code change that writes a different mapping makes
``animate`` stale even without a stage-version bump, and an upstream rerun that writes the same
bytes leaves its downstream up to date.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any, Mapping

from faceforge.exceptions import StageError

_CHUNK = 1 << 20


def file_digest(path: str | Path) -> str:
    """SHA-256 hex digest of a file's bytes, or of a folder (sorted relative names + contents)."""
    path = Path(path)
    digest = hashlib.sha256()
    if path.is_dir():
        for child in sorted(p for p in path.rglob("*") if p.is_file()):
            digest.update(child.relative_to(path).as_posix().encode("utf-8") + b"\0")
            digest.update(file_digest(child).encode("ascii"))
        return digest.hexdigest()
    try:
        with open(path, "rb") as fh:
            for chunk in iter(lambda: fh.read(_CHUNK), b""):
                digest.update(chunk)
    except FileNotFoundError:
        raise StageError("input file not found", path) from None
    except OSError as exc:
        raise StageError(f"cannot read input: {exc.strerror}", path) from None
    return digest.hexdigest()


def folder_digests(folder: Path) -> dict[str, str]:
    """``{relative file name: SHA-256}`` of every file under ``folder`` but ``stage.json``."""
    folder = Path(folder)
    return {p.relative_to(folder).as_posix(): file_digest(p)
            for p in sorted(folder.rglob("*")) if p.is_file() and p.relative_to(folder).as_posix() != "stage.json"}


def outputs_digest(stored: Mapping) -> str:
    """The digest by which a complete stage (its ``stage.json``, ``stored``) enters its downstream
    keys: SHA-256 of its files' digests (``stored["output_sha256"]``, recorded when it wrote them).
    A stage written by an older faceforge (no digests) enters by its key, as it did then, so an
    upgrade does not rerun every workdir's downstream stages; its next run records digests."""
    digests = stored.get("output_sha256")
    if not isinstance(digests, dict):
        return str(stored.get("key"))
    return hashlib.sha256(canonical_json(digests).encode("utf-8")).hexdigest()


def canonical_json(value: Any) -> str:
    """Deterministic JSON (sorted keys, no spaces) used for hashing."""
    return json.dumps(value, sort_keys=True, separators=(",", ":"), allow_nan=False)


def record_key(record: Mapping) -> str:
    """The cache key of a record: SHA-256 of its canonical JSON without input paths."""
    hashed = dict(record)
    hashed["inputs"] = {name: (None if v is None else v["sha256"]) for name, v in record["inputs"].items()}
    return hashlib.sha256(canonical_json(hashed).encode("utf-8")).hexdigest()


def _leaf_diff(old: Any, new: Any, prefix: str) -> list[str]:
    """Dotted keys whose values differ between two config subtrees."""
    if isinstance(old, Mapping) and isinstance(new, Mapping):
        out = []
        for key in list(old) + [k for k in new if k not in old]:
            if key not in old or key not in new:
                out.append(f"{prefix}.{key}")
            else:
                out.extend(_leaf_diff(old[key], new[key], f"{prefix}.{key}"))
        return out
    return [] if old == new else [prefix]


#: a key the packaged defaults do not have
_ABSENT = object()


def _without_new_defaults(value: Any, old: Any, default: Any) -> Any:
    """``value`` (a config subtree) less the leaves ``old`` (the stored subtree) lacks and that
    equal ``default`` (the packaged default subtree) there."""
    if not (isinstance(value, Mapping) and isinstance(old, Mapping)):
        return value
    out = {}
    for k, v in value.items():
        d = default.get(k, _ABSENT) if isinstance(default, Mapping) else _ABSENT
        if k not in old:
            if d is _ABSENT or d != v:
                out[k] = v
        else:
            out[k] = _without_new_defaults(v, old[k], None if d is _ABSENT else d)
    return out


def settled_record(current: Mapping, previous: Mapping | None, default) -> dict:
    """``current`` (a stage's record) less the config its stored ``previous`` record predates
    and that is at its packaged ``default`` (the default :class:`~faceforge.io.config.Config`,
    read with ``get(dotted key, missing)``): a config key a newer faceforge added (off, as new
    behaviours come) does not make an existing workdir's stages stale, while a key set to
    anything else, or a changed default of a key the record has, does (a changed output
    comes with a stage-version bump, which the record holds). ``current`` itself when there
    is no ``previous``."""
    if previous is None:
        return dict(current)
    # the record's top-level keys are dotted paths into the default config, read with its get()
    tops = {key: d for key in current["config"] if (d := default.get(key, _ABSENT)) is not _ABSENT}
    return {**current, "config": _without_new_defaults(current["config"], previous.get("config", {}), tops)}


def stale_reasons(current: Mapping, previous: Mapping | None) -> list[str]:
    """Why a stage whose record is ``current`` differs from its stored ``previous`` record.

    Returns an empty list when the keys agree; otherwise short sentences naming the
    changed config keys, inputs and upstream stages.
    """
    if previous is None:
        return ["never run"]
    if record_key(current) == previous.get("key"):
        return []
    reasons = []
    if previous.get("version") != current["version"]:
        reasons.append(f"code version {previous.get('version')} -> {current['version']}")
    old_config = previous.get("config", {})
    for key, value in current["config"].items():
        if key not in old_config:
            reasons.append(f"`{key}` newly read")
        else:
            reasons.extend(f"`{k}` changed" for k in _leaf_diff(old_config[key], value, key))
    old_inputs = previous.get("inputs", {})
    for name, entry in current["inputs"].items():
        old = old_inputs.get(name)
        old_sha = None if old is None else old.get("sha256")
        new_sha = None if entry is None else entry["sha256"]
        if old_sha != new_sha:
            label = Path(entry["path"]).name if entry else name
            reasons.append(f"input {label} changed" if old and entry else f"input {name} {'added' if entry else 'removed'}")
    old_up = previous.get("upstream", {})
    for dep, key in current["upstream"].items():
        if old_up.get(dep) != key:
            reasons.append(f"upstream {dep} changed")
    return reasons or ["stage.json does not match (written by another faceforge version?)"]


def read_stage_json(stage_dir: Path) -> dict | None:
    """The stored record of a complete stage folder, or None when absent or unreadable."""
    path = stage_dir / "stage.json"
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) and "key" in data else None
