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
import fnmatch
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Mapping

from faceforge.exceptions import ConfigError

# ---------------------------------------------------------------------------
# rules


class Rule:
    """Checks one leaf value; ``check`` returns the normalized value or raises ``ValueError``."""

    def check(self, value: Any, base: Path) -> Any:  # pragma: no cover - interface
        raise NotImplementedError


@dataclass(frozen=True)
class Number(Rule):
    """A finite real number (ints accepted, stored as float), optionally in [low, high]."""

    low: float | None = None
    high: float | None = None

    def describe(self) -> str:
        if self.low is None and self.high is None:
            return "a number"
        if self.high is None:
            return f"a number >= {self.low:g}"
        if self.low is None:
            return f"a number <= {self.high:g}"
        return f"a number in [{self.low:g}, {self.high:g}]"

    def check(self, value, base):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not _finite(value):
            raise ValueError(self.describe())
        if (self.low is not None and value < self.low) or (self.high is not None and value > self.high):
            raise ValueError(self.describe())
        return float(value)


def _finite(value) -> bool:
    """``math.isfinite`` that says False for an int too large for a float (instead of raising)."""
    try:
        return math.isfinite(value)
    except OverflowError:
        return False


@dataclass(frozen=True)
class Integer(Rule):
    """An integer (not a bool) >= ``low`` (no bound when ``low`` is None) and <= ``high``."""

    low: int | None = 1
    high: int | None = None

    def describe(self) -> str:
        if self.high is None:
            return "an integer" if self.low is None else f"an integer >= {self.low}"
        return f"an integer <= {self.high}" if self.low is None else f"an integer in [{self.low}, {self.high}]"

    def check(self, value, base):
        if isinstance(value, float) and _finite(value) and value.is_integer():
            value = int(value)
        if isinstance(value, bool) or not isinstance(value, int) or (self.low is not None and value < self.low) \
                or (self.high is not None and value > self.high):
            raise ValueError(self.describe())
        return value


@dataclass(frozen=True)
class Boolean(Rule):
    def check(self, value, base):
        if not isinstance(value, bool):
            raise ValueError("true or false")
        return value


@dataclass(frozen=True)
class Choice(Rule):
    """One of a fixed set of strings."""

    choices: tuple[str, ...]

    def check(self, value, base):
        if not isinstance(value, str) or value not in self.choices:
            raise ValueError("one of " + ", ".join(self.choices))
        return value


@dataclass(frozen=True)
class AxesPair(Rule):
    """``auto``, or two signed axes ``UP,FORWARD`` on different axes (e.g. ``+Z,-Y``)."""

    def check(self, value, base):
        return check_orientation(value, base)


def check_orientation(value, base=None):
    """``fit.orientation``: ``auto`` or ``UP,FORWARD`` (two signed axes, e.g. ``+Z,-Y``);
    returns it, or raises ValueError saying what is expected."""
    axes = {"+x", "-x", "+y", "-y", "+z", "-z", "x", "y", "z"}
    words = [w.strip().lower() for w in value.split(",")] if isinstance(value, str) else []
    if value == "auto" or (len(words) == 2 and set(words) <= axes and words[0][-1] != words[1][-1]):
        return value
    raise ValueError("auto, or the mesh's up and forward axes as UP,FORWARD (e.g. +Z,-Y)")


@dataclass(frozen=True)
class String(Rule):
    def check(self, value, base):
        if not isinstance(value, str):
            raise ValueError("a string")
        return value


@dataclass(frozen=True)
class PathValue(Rule):
    """A file or folder path; relative paths are made absolute against the layer's base."""

    def check(self, value, base):
        if not isinstance(value, str) or not value:
            raise ValueError("a path")
        path = Path(os.path.expanduser(value))
        return str(path if path.is_absolute() else (base / path).resolve())


@dataclass(frozen=True)
class ListOf(Rule):
    """A list, each item checked by ``item``, with at least ``min_items`` items."""

    item: Rule | None = None
    min_items: int = 0

    def check(self, value, base):
        if not isinstance(value, list):
            raise ValueError("a list")
        if len(value) < self.min_items:
            raise ValueError(f"a list of at least {self.min_items} item{'s' if self.min_items > 1 else ''}")
        if self.item is None:
            return list(value)
        try:
            return [self.item.check(v, base) for v in value]
        except ValueError as exc:
            raise ValueError(f"each item to be {exc}") from None


@dataclass(frozen=True)
class Anything(Rule):
    def check(self, value, base):
        return value


_DEFAULT_CACHE: dict[str, tuple[dict, dict[str, int], str]] = {}

#: (glob over the dotted key, rule); the first match wins, else the default's type decides
RULES: list[tuple[str, Rule]] = [
    ("fit.orientation", AxesPair()),
    ("skin.carry", Choice(("muscles", "all", "none"))),
    ("skin.carry_radius_mm", Number(0.0, 50.0)),
    ("skin.lid_hold", Number(0.0, 1.0)),              # a stiffness
    ("skin.cheek_tether", Number(0.0, 1.0)),          # a stiffness: past 1 a projection overshoots
    ("skin.commissure_fold_deg", Number(0.0, 179.0)),  # degrees; 0 turns the lips' corner contact off
    ("skin.fold_deg", Number(0.0, 179.0)),  # degrees; 0 turns the skin's fold limit off
    ("curves.ridge", Number(0.0, 1.0)),               # --curves' ridge (unitless): 0 = plain bounded least squares
    ("curves.smooth", Number(0.0, 100.0)),            # --curves' smoothness over frames (unitless): 0 = off
    ("muscle.damping", Number(0.0, 0.99)),
    ("animate.orientation_guard.rounds", Integer(0)),            # 0 turns the guard off
    ("animate.orientation_guard.min_area", Number(0.0, 0.95)),
    ("animate.skull_guard.collision_reach", Number(0.0, 0.5)),     # 0 turns bone collision off
    ("animate.skull_guard.collision_keep", Number(0.0, 0.95)),
    ("animate.jaw_glide", Number(0.0, 2.0)),                       # 0: the jaw only turns
    ("animate.jaw_glide_slope", Number(-30.0, 80.0)),
    ("animate.chin_path", Number(0.0, 1.5)),                       # 0: jaw_glide as given
    ("*.stiffness.*", Number(0.0, 1.0)),
    ("solver.damping", Number(0.0, 1.0)),
    ("muscle.sphincter.carry_inner", Number(0.0, 1.0)),
    ("muscle.sphincter.protrusion", Number(0.0)),
    ("muscle.sphincter.inner_on_bone", Boolean()),
    ("muscle.sphincter.closure_centre", Number(0.0, 1.0)),
    ("solver.stiffness_mode", Choice(("paper", "iteration_independent", "xpbd"))),
    ("solver.gravity", Number()),
    ("fit.rbf_kernel", Choice(("multiquadric", "inverse_multiquadric", "thin_plate_spline", "gaussian"))),
    ("bind.max_ray_distance", Number(0.0, 1.0)),
    ("bind.modiolus_radius", Number(0.0, 0.5)),
    ("bind.commissure_radius", Number(0.0, 0.5)),
    ("bind.vermilion_reach", Number(0.0, 5.0)),
    ("bind.forehead_bone_mm", Number(0.0, 100.0)),                # 0: off (the forehead by its rays)
    ("template.*", PathValue()),
    ("animate.fap_mapping", PathValue()),
    ("animate.calibrate.magnitudes", PathValue()),
    ("animate.quality", Choice(("realtime", "offline"))),
    # no fraction, no probe: the calibration wrote an empty mapping and said nothing
    ("animate.calibrate.fractions", ListOf(Number(0.01, 1.0), min_items=1)),
    ("animate.calibrate.fractions.*", Number(0.01, 1.0)),
    ("animate.calibrate.tolerance", Number(0.0, 0.5)),
    ("animate.statics.tolerance", Number(0.0, 0.01)),
    ("animate.statics.stall", Integer(0, 2000)),                  # 0: hold a stalled pose to max_frames
    ("animate.calibrate.statics_tolerance", Number(0.0, 0.01)),
    ("animate.calibrate.cycle", Integer(0, 2000)),                # 0: no period-2 stop (statics.SettleSettings.cycle)
    ("animate.calibrate.warm_jaw_poses", Boolean()),
    ("animate.neck_fade", Number(0.0, 10.0)),
    ("animate.eyelid_reach", Number(0.1, 10.0)),
    ("animate.eyelid_depth", Number(0.1, 10.0)),
    ("animate.eyelid_fold_deg", Number(0.0, 179.0)),       # degrees; 0 turns the lids' fold limit off
    ("animate.eyelid_jaw_hold", Number(0.0, 1.0)),         # share of a moving jaw's drift the upper lids take back
    # sane upper bounds: a value past them is a typo, and 1e9 iterations hang, 1e9 s of
    # expression tried to allocate 186 GiB (issue 28)
    ("solver.iterations", Integer(1, 1000)),
    ("solver.substeps", Integer(1, 100)),
    ("solver.partitions", Integer(1, 64)),
    ("animate.fps", Number(1.0, 1000.0)),
    ("animate.expression_seconds", Number(0.04, 3600.0)),
    ("animate.expression_ramp", Number(0.0, 3600.0)),
    ("animate.preview_frames", Integer(1, 100)),
]

#: an integer key without a rule accepts at most this many times its default (or INT_CAP_FLOOR)
INT_CAP_FACTOR = 100
INT_CAP_FLOOR = 1000
#: a number key without a rule accepts magnitudes up to this many times its default (at least 1)
NUMBER_CAP_FACTOR = 1e6


def add_rule(pattern: str, rule: Rule) -> None:
    """Give keys matching ``pattern`` a rule, ahead of the built-in ones (for tests and
    plug-ins; faceforge's own rules are all in :data:`RULES`, so importing a module never
    changes validation), e.g. ``add_rule("animate.fps", Number(1, 240))``.
    """
    RULES.insert(0, (pattern, rule))
    _DEFAULT_CACHE.clear()


def rule_for(key: str, default: Any) -> Rule:
    """The rule of a leaf ``key`` whose default value is ``default``.

    Without a matching :data:`RULES` entry: bool -> true/false; int -> an integer >= 1
    (>= 0 if the default is 0, unbounded if negative) and at most :data:`INT_CAP_FACTOR`
    times the default (at least :data:`INT_CAP_FLOOR`); float -> a finite number of magnitude
    at most :data:`NUMBER_CAP_FACTOR` times the default's (at least 1);
    str -> a string; list -> a list; null -> anything.
    """
    for pattern, rule in RULES:
        if fnmatch.fnmatchcase(key, pattern):
            return rule
    if isinstance(default, bool):
        return Boolean()
    if isinstance(default, int):
        return Integer(1 if default >= 1 else 0 if default == 0 else None,
                       max(INT_CAP_FLOOR, INT_CAP_FACTOR * abs(default)))
    if isinstance(default, float):
        cap = NUMBER_CAP_FACTOR * max(1.0, abs(default))
        return Number(-cap, cap)
    if isinstance(default, str):
        return String()
    if isinstance(default, list):
        return ListOf(rule_for(key + ".*", default[0]) if default else None)
    return Anything()


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
