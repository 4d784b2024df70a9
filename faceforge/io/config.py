"""YAML configuration: defaults, layered overrides and validation with line numbers.

The schema *is* ``configs/default.yaml``: every key it contains is valid, the type
of its default value is the expected type, and a small rule table adds ranges,
enumerations and paths (:data:`RULES`). Other engineers add keys to their own
sections of the default file and get validation for free.

Layers are merged in this order, later wins (each validated on its own first, so
an error names the layer it comes from):

1. the packaged default (``faceforge/data/default.yaml``, a symlink to
   ``configs/default.yaml`` in a checkout; a real copy in an installed wheel),
2. ``<workdir>/config.yaml`` (overrides remembered from earlier runs),
3. ``--config FILE``,
4. each ``--set key.path=value`` (the value parsed as YAML).

Errors read ``my.yaml:12: skin.stiffness.bending: expected a number in [0, 1],
got 'high'``; ``--set`` errors name ``--set`` instead of a file.

Relative paths (keys with a :class:`PathValue` rule) are made absolute against
the folder of the file that set them, the current directory for ``--set``, and
for the default file the folder above the one holding it (the repository root
in a checkout).
"""

from __future__ import annotations

import copy
import difflib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Mapping

from faceforge.exceptions import ConfigError

# ---------------------------------------------------------------------------
# rules: faceforge.io.config_rules (re-exported here, where callers have always found them)

from faceforge.io.config_rules import (  # noqa: E402,F401
    INT_CAP_FACTOR, INT_CAP_FLOOR, NUMBER_CAP_FACTOR, RULES, _DEFAULT_CACHE, Anything, AxesPair, Boolean, Choice,
    Integer, ListOf, Number, PathValue, Rule, String, _finite, add_rule, check_orientation, rule_for)


# ---------------------------------------------------------------------------
# reading YAML with line numbers


@dataclass
class Layer:
    """One validated override tree and where each of its keys came from."""

    tree: dict
    source: str  # file path or "--set"
    lines: dict[str, int] = field(default_factory=dict)  # dotted key -> 1-based line


def _line_map(text: str, source: str) -> dict[str, int]:
    """Dotted key -> line of its value, from ``yaml.compose``; rejects duplicate keys."""
    import yaml

    lines: dict[str, int] = {}

    def walk(node, prefix):
        if not isinstance(node, yaml.MappingNode):
            return
        seen = set()
        for key_node, value_node in node.value:
            key = str(key_node.value)
            dotted = f"{prefix}.{key}" if prefix else key
            if key in seen:
                raise ConfigError(f"{dotted}: duplicate key", source, key_node.start_mark.line + 1)
            seen.add(key)
            lines[dotted] = value_node.start_mark.line + 1
            lines["\0key:" + dotted] = key_node.start_mark.line + 1
            walk(value_node, dotted)

    walk(yaml.compose(text), "")
    return lines


def _parse_yaml(text: str, source: str) -> tuple[Any, dict[str, int]]:
    import yaml

    from faceforge.io.safe_yaml import load_user_yaml

    data = load_user_yaml(text, source, ConfigError)   # limits, YAML 1.2 floats, one-line errors
    try:
        lines = _line_map(text, source)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise ConfigError(f"not valid YAML: {problem}", source, None if mark is None else mark.line + 1) from None
    return data, lines


def _read_text(path: Path) -> str:
    try:
        return path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError("config file not found", path) from None
    except IsADirectoryError:
        raise ConfigError("is a folder, expected a YAML file", path) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"cannot read config file: {exc}", path) from None


# ---------------------------------------------------------------------------
# the default (= the schema)


def default_config_path() -> Path:
    """The packaged default configuration (``faceforge/data/default.yaml``)."""
    return Path(__file__).resolve().parent.parent / "data" / "default.yaml"


def default_base() -> Path:
    """Folder against which relative paths of the default file resolve (repo root in a checkout)."""
    return default_config_path().resolve().parent.parent


def load_default() -> Layer:
    """The default configuration, normalized (paths made absolute); it is also the schema."""
    path = default_config_path()
    text = _read_text(path)
    if text not in _DEFAULT_CACHE:
        data, lines = _parse_yaml(text, str(path))
        if not isinstance(data, dict):
            raise ConfigError("the default configuration must be a mapping", path)
        tree = _normalize_default(data, default_base(), "")
        _DEFAULT_CACHE.clear()
        _DEFAULT_CACHE[text] = (tree, lines, str(path))
    tree, lines, source = _DEFAULT_CACHE[text]
    return Layer(copy.deepcopy(tree), source, dict(lines))


def _normalize_default(tree: dict, base: Path, prefix: str) -> dict:
    out = {}
    for key, value in tree.items():
        dotted = f"{prefix}.{key}" if prefix else str(key)
        if isinstance(value, dict):
            out[str(key)] = _normalize_default(value, base, dotted)
        else:
            try:
                out[str(key)] = rule_for(dotted, value).check(value, base) if value is not None else None
            except ValueError as exc:
                raise ConfigError(f"{dotted}: default value {value!r} breaks its own rule ({exc})",
                                  default_config_path()) from None
    return out


def _leaf_keys(tree: Mapping, prefix: str = "", leaves_only: bool = False) -> list[str]:
    """Dotted keys of ``tree`` in order (mappings too, unless ``leaves_only``)."""
    keys = []
    for key, value in tree.items():
        dotted = f"{prefix}.{key}" if prefix else key
        if isinstance(value, Mapping):
            if not leaves_only:
                keys.append(dotted)
            keys.extend(_leaf_keys(value, dotted, leaves_only))
        else:
            keys.append(dotted)
    return keys


# ---------------------------------------------------------------------------
# validation


def _describe_got(value: Any) -> str:
    if isinstance(value, dict):
        return "a mapping"
    if isinstance(value, list):
        short = len(value) <= 8 and all(isinstance(v, (int, float, str, bool)) or v is None for v in value)
        return repr(value) if short and len(repr(value)) <= 60 else "a list"
    return repr(value)


def validate_tree(data: Any, source: str, lines: Mapping[str, int], base: Path,
                  schema: Mapping | None = None) -> Layer:
    """Check an override tree against the default; return it normalized.

    Raises :class:`ConfigError` ``source:line: key: expected ..., got ...`` for the
    first problem in file order (unknown key with a suggestion, wrong type, out of
    range).
    """
    schema = load_default().tree if schema is None else schema
    if data is None:
        return Layer({}, source, dict(lines))
    if not isinstance(data, dict):
        raise ConfigError(f"expected a mapping of settings, got {_describe_got(data)}", source, lines.get("", 1))
    all_keys = _leaf_keys(schema)
    errors: list[tuple[int, str]] = []

    def walk(node: dict, spec: Mapping, prefix: str) -> dict:
        out = {}
        for key, value in node.items():
            key = str(key)
            dotted = f"{prefix}.{key}" if prefix else key
            line = lines.get(dotted)
            if key not in spec:
                near = difflib.get_close_matches(dotted, all_keys, n=1, cutoff=0.6)
                hint = f" (did you mean {near[0]}?)" if near else ""
                errors.append((lines.get("\0key:" + dotted, line or 0), f"{dotted}: unknown key{hint}"))
                continue
            expected = spec[key]
            if isinstance(expected, dict):
                if value is None:
                    continue
                if not isinstance(value, dict):
                    errors.append((line or 0, f"{dotted}: expected a mapping, got {_describe_got(value)}"))
                    continue
                out[key] = walk(value, expected, dotted)
                continue
            try:
                out[key] = rule_for(dotted, expected).check(value, base)
            except ValueError as exc:
                errors.append((line or 0, f"{dotted}: expected {exc}, got {_describe_got(value)}"))
        return out

    tree = walk(data, schema, "")
    if errors:
        errors.sort(key=lambda e: e[0])
        line, message = errors[0]
        more = f" (and {len(errors) - 1} more)" if len(errors) > 1 else ""
        err = ConfigError(message + more, source, line or None)
        err.all_errors = [ConfigError(m, source, ln or None) for ln, m in errors]
        raise err
    return Layer(tree, source, dict(lines))


def read_config_file(path: str | Path) -> Layer:
    """Read and validate a user config file (a partial tree over the default)."""
    path = Path(path)
    data, lines = _parse_yaml(_read_text(path), str(path))
    return validate_tree(data, str(path), lines, path.resolve().parent)


def parse_sets(items: Iterable[str], base: Path | None = None) -> Layer:
    """Turn ``["a.b=1", ...]`` into one validated layer; the source is ``--set``."""
    from faceforge.io.safe_yaml import load_user_yaml

    tree: dict = {}
    for item in items:
        key, sep, raw = item.partition("=")
        key = key.strip()
        if not sep or not key or any(not part for part in key.split(".")):
            raise ConfigError(f"expected key.path=value, got {item!r}", "--set")
        try:
            value = load_user_yaml(raw, "--set", ConfigError) if raw.strip() else ""
        except ConfigError as exc:
            raise ConfigError(f"{key}: value {raw[:80]!r} is not a valid YAML value ({exc.message})",
                              "--set") from None
        set_dotted(tree, key, value)
    return validate_tree(tree, "--set", {}, base or Path.cwd())


def set_dotted(tree: dict, key: str, value) -> None:
    """Set ``tree["a"]["b"] = value`` for ``key = "a.b"``, creating (or replacing non-dict)
    intermediate mappings."""
    node = tree
    parts = str(key).split(".")
    for part in parts[:-1]:
        child = node.get(part)
        if not isinstance(child, dict):
            child = node[part] = {}
        node = child
    node[parts[-1]] = value


# ---------------------------------------------------------------------------
# the merged configuration


def merge_trees(base: Mapping, override: Mapping) -> dict:
    """Deep merge: mappings merge key by key, anything else is replaced."""
    out = copy.deepcopy(dict(base))
    for key, value in override.items():
        if isinstance(value, Mapping) and isinstance(out.get(key), Mapping):
            out[key] = merge_trees(out[key], value)
        else:
            out[key] = copy.deepcopy(value)
    return out


_MISSING = object()


class Config:
    """The merged, validated configuration with dotted access.

    ``origins`` maps each leaf key set by an override to ``"file:line"`` or ``"--set"``.
    """

    def __init__(self, data: Mapping, origins: Mapping[str, str] | None = None):
        self._data = copy.deepcopy(dict(data))
        self.origins = dict(origins or {})

    def get(self, key: str, default: Any = _MISSING) -> Any:
        """Value (a copy, for subtrees) at a dotted ``key``; ``KeyError`` naming it if absent."""
        node: Any = self._data
        for part in key.split("."):
            if not isinstance(node, Mapping) or part not in node:
                if default is not _MISSING:
                    return default
                raise KeyError(f"unknown config key {key!r}")
            node = node[part]
        return copy.deepcopy(node)

    __getitem__ = get

    def as_dict(self) -> dict:
        return copy.deepcopy(self._data)

    def to_yaml(self, annotate: bool = True) -> str:
        """The whole configuration as YAML; overridden leaves carry a ``# from ...`` comment."""
        import yaml

        text = yaml.safe_dump(self._data, sort_keys=False, default_flow_style=False)
        if not annotate or not self.origins:
            return text
        out, stack = [], []
        for line in text.splitlines():
            stripped = line.lstrip(" ")
            indent = (len(line) - len(stripped)) // 2
            key = stripped.split(":", 1)[0]
            stack = stack[:indent] + [key]
            dotted = ".".join(stack)
            origin = self.origins.get(dotted)
            out.append(f"{line}  # from {origin}" if origin and ":" in stripped else line)
        return "\n".join(out) + "\n"


def build_config(layers: Iterable[Layer]) -> Config:
    """Merge validated layers over the default."""
    default = load_default()
    data = default.tree
    origins: dict[str, str] = {}
    for layer in layers:
        data = merge_trees(data, layer.tree)
        for key in _leaf_keys(layer.tree, leaves_only=True):
            line = layer.lines.get(key)
            origins[key] = f"{layer.source}:{line}" if line else layer.source
    return Config(data, origins)


def load_config(config_file: str | Path | None = None, sets: Iterable[str] = (),
                remembered: str | Path | None = None) -> Config:
    """Default ⊕ remembered workdir overrides ⊕ ``config_file`` ⊕ ``sets``, all validated."""
    layers = []
    if remembered is not None and Path(remembered).exists():
        layers.append(read_config_file(remembered))
    if config_file is not None:
        layers.append(read_config_file(config_file))
    sets = list(sets)
    if sets:
        layers.append(parse_sets(sets))
    return build_config(layers)
