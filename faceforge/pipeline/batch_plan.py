"""Planning a batch: head jobs from meshes or a manifest, validated before any work (issue 8).

Manifest (YAML; relative paths resolve against the manifest's folder)::

    fap: tracks/joy.fap          # or  expression: joy  (+ intensity: 0.8, seconds: 2)
    output: .pc2                 # optional: export each head to <out>/<name>/<name>.pc2
    set: {solver.iterations: 8}  # optional: overrides for every head (dotted keys)
    heads:
      - mesh: heads/anna.obj
        landmarks: heads/anna.fdp.yaml   # optional [default: <mesh stem>.fdp.yaml]
        name: anna                       # optional [default: the mesh stem]; the workdir name
        set: {fit.refit: false}          # optional per-head overrides

Used by :mod:`faceforge.pipeline.batch`, which runs the jobs.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

from faceforge.exceptions import FaceforgeError, StageError

#: the stages every head goes through (the last one's upstream comes along)
DEFAULT_TARGETS = ("fit", "bind", "animate")
EXPRESSIONS = ("joy", "sadness", "surprise", "anger", "disgust", "fear")


@dataclass(frozen=True)
class HeadJob:
    """Everything one head needs; travels to a worker by pickling (paths are absolute).

    Attributes
    ----------
    name : the head's name, also its workdir's folder name.
    mesh : skin mesh path. workdir : the head's workdir.
    landmarks : FDP landmark file (None: ``<mesh stem>.fdp.yaml`` next to the mesh).
    fap : FAP track, or ``expression`` (one of :data:`EXPRESSIONS`) with ``intensity`` in
        [0, 1] and ``seconds`` (None: ``animate.expression_seconds``).
    output : export path of the animation (suffix picks the format) or None.
    overrides : dotted config key -> value, validated (the head's ``set:`` over the shared ones).
    config_file : a config YAML merged under ``overrides``. base : folder that relative
        paths in ``overrides`` resolve against.
    targets : stage names to bring up to date, in order. plugins : modules (dotted names
        or ``.py`` paths) imported before running, e.g. to register extra stages.
    keep_going : accept a stage result that fails its checks (else the head fails,
        :mod:`faceforge.pipeline.result_checks`).
    """

    name: str
    mesh: str
    workdir: str
    landmarks: str | None = None
    fap: str | None = None
    expression: str | None = None
    intensity: float = 1.0
    seconds: float | None = None
    output: str | None = None
    overrides: Mapping[str, Any] = field(default_factory=dict)
    config_file: str | None = None
    base: str = "."
    targets: tuple[str, ...] = DEFAULT_TARGETS
    plugins: tuple[str, ...] = ()
    keep_going: bool = False


# --------------------------------------------------------------------------- planning

def nest(overrides: Mapping[str, Any]) -> dict:
    """``{"a.b": 1, "a.c": 2}`` -> ``{"a": {"b": 1, "c": 2}}`` (later keys win)."""
    from faceforge.io.config import set_dotted

    tree: dict = {}
    for key, value in overrides.items():
        set_dotted(tree, key, value)
    return tree


def flatten(tree: Mapping, prefix: str = "") -> dict:
    """Inverse of :func:`nest` for the scalar leaves (lists and empty mappings kept as leaves)."""
    out = {}
    for key, value in tree.items():
        dotted = f"{prefix}.{key}" if prefix else str(key)
        if isinstance(value, Mapping) and value:
            out.update(flatten(value, dotted))
        else:
            out[dotted] = value
    return out


def validate_overrides(overrides: Mapping[str, Any], source: str, base: str | Path,
                       lines: Mapping[str, int] | None = None) -> dict:
    """Check dotted overrides against the config schema; ``ConfigError`` naming ``source:line``."""
    from faceforge.io.config import validate_tree

    nested_lines: dict[str, int] = {}
    for key, line in (lines or {}).items():
        parts = key.split(".")
        for i in range(len(parts), 0, -1):   # a bad prefix ("fitt" of "fitt.x") gets the line too
            for k in (".".join(parts[:i]), "\0key:" + ".".join(parts[:i])):
                nested_lines.setdefault(k, line)
    layer = validate_tree(nest(overrides), source, nested_lines, Path(base))
    return flatten(layer.tree)


def import_plugins(plugins: Iterable[str]) -> None:
    """Import each plugin once: a dotted module name, or a ``.py`` file path."""
    import importlib
    import importlib.util

    for plugin in plugins:
        if plugin.endswith(".py"):
            name = "faceforge_plugin_" + "".join(c if c.isalnum() else "_" for c in Path(plugin).stem)
            if name in sys.modules:
                continue
            spec = importlib.util.spec_from_file_location(name, plugin)
            if spec is None or not Path(plugin).is_file():
                raise StageError("plugin file not found", plugin)
            module = importlib.util.module_from_spec(spec)
            sys.modules[name] = module
            try:
                spec.loader.exec_module(module)
            except BaseException:
                del sys.modules[name]
                raise
        else:
            try:
                importlib.import_module(plugin)
            except ImportError as exc:
                raise StageError(f"cannot import plugin {plugin!r}: {exc}") from None


def check_unique(jobs: Sequence[HeadJob], source: str) -> None:
    """Two heads must not share a workdir; the error names both meshes."""
    seen: dict[str, HeadJob] = {}
    for job in jobs:
        if job.workdir in seen:
            raise StageError(f"heads {seen[job.workdir].mesh} and {job.mesh} would share the workdir "
                             f"{job.workdir}; give them distinct names in a manifest", source)
        seen[job.workdir] = job


def output_path(workdir: Path, name: str, suffix: str | None) -> str | None:
    """Export path ``<workdir>/<name><suffix>`` (``suffix`` "/" or "" -> an OBJ folder)."""
    if suffix is None:
        return None
    if suffix in ("", "/"):
        return str(workdir / f"{name}_frames")
    return str(workdir / f"{name}{suffix if suffix.startswith('.') else '.' + suffix}")


@dataclass(frozen=True)
class SharedOptions:
    """Options common to every head of a batch (command line over manifest)."""

    fap: str | None = None
    expression: str | None = None
    intensity: float = 1.0
    seconds: float | None = None
    output: str | None = None
    overrides: Mapping[str, Any] = field(default_factory=dict)
    config_file: str | None = None
    targets: tuple[str, ...] = DEFAULT_TARGETS
    plugins: tuple[str, ...] = ()

    def check(self, source: str) -> None:
        """One of ``fap``/``expression`` (when animating), valid expression and suffix."""
        if "animate" in self.targets and (self.fap is None) == (self.expression is None):
            raise StageError("give exactly one of a FAP track (fap) or an expression", source)
        if self.expression is not None and self.expression not in EXPRESSIONS:
            raise StageError(f"unknown expression {self.expression!r} (valid: {', '.join(EXPRESSIONS)})", source)
        if not 0.0 <= float(self.intensity) <= 1.0:
            raise StageError(f"intensity must be in [0, 1], got {self.intensity}", source)
        if self.fap is not None and not Path(self.fap).is_file():
            raise StageError("FAP file not found", self.fap)
        if self.output not in (None, "", "/"):
            from faceforge.io.export import exporter_for

            exporter_for(output_path(Path("."), "x", self.output))


def folder_name(stem: str) -> str:
    """A workdir folder name from a mesh's stem: path separators and leading dots dropped (a
    mesh ``...obj`` has the stem ``..``, which would name ``<out>``'s parent), ``head`` when
    nothing is left."""
    cleaned = stem.replace("/", "_").replace("\\", "_").lstrip(".").strip()
    return cleaned or "head"


def make_job(mesh: str | Path, out: str | Path, shared: SharedOptions, name: str | None = None,
             landmarks: str | Path | None = None, overrides: Mapping[str, Any] | None = None,
             base: str | Path = ".") -> HeadJob:
    """A :class:`HeadJob` for ``mesh`` in ``<out>/<name>/`` (paths made absolute; ``name``
    defaults to :func:`folder_name` of the mesh's stem)."""
    name = name or folder_name(Path(mesh).stem)
    workdir = Path(out).absolute() / name
    if workdir.parent != Path(out).absolute() or name in (".", ".."):
        raise StageError(f"head name {name!r} is not a folder name inside --out", str(mesh))
    return HeadJob(name=name, mesh=str(Path(mesh).absolute()), workdir=str(workdir),
                   landmarks=None if landmarks is None else str(Path(landmarks).absolute()),
                   fap=None if shared.fap is None else str(Path(shared.fap).absolute()),
                   expression=shared.expression, intensity=float(shared.intensity), seconds=shared.seconds,
                   output=output_path(workdir, name, shared.output),
                   overrides={**shared.overrides, **(overrides or {})}, config_file=shared.config_file,
                   base=str(Path(base).absolute()), targets=tuple(shared.targets), plugins=tuple(shared.plugins))


def jobs_from_meshes(meshes: Sequence[str | Path], out: str | Path, shared: SharedOptions) -> list[HeadJob]:
    """One job per mesh (landmarks next to each mesh); ``StageError`` before any work if invalid."""
    if not meshes:
        raise StageError("no head meshes given")
    shared.check("command line")
    for mesh in meshes:
        if not Path(mesh).is_file():
            raise StageError("head mesh not found", mesh)
    jobs = [make_job(m, out, shared) for m in meshes]
    check_unique(jobs, "command line")
    return jobs


def is_manifest(path: str | Path) -> bool:
    return Path(path).suffix.lower() in (".yaml", ".yml")


_MANIFEST_KEYS = ("heads", "fap", "expression", "intensity", "seconds", "output", "set")
_HEAD_KEYS = ("mesh", "landmarks", "name", "set")


def _yaml_lines(text: str, source: str) -> tuple[Any, dict]:
    """Parsed YAML and the 1-based line of every node, keyed by its path tuple (keys and items)."""
    import yaml

    from faceforge.io.safe_yaml import load_user_yaml

    data = load_user_yaml(text, source, StageError)   # limits, YAML 1.2 floats, one-line errors
    root = yaml.compose(text)                          # parses: the text passed the same parser
    lines: dict = {}

    def walk(node, path):
        lines[path] = node.start_mark.line + 1
        if isinstance(node, yaml.MappingNode):
            for k, v in node.value:
                walk(v, path + (str(k.value),))
                lines[path + (str(k.value),)] = k.start_mark.line + 1   # the key's line
        elif isinstance(node, yaml.SequenceNode):
            for i, v in enumerate(node.value):
                walk(v, path + (i,))

    if root is not None:
        walk(root, ())
    return data, lines


def _overrides(value, where: tuple, source: str, lines: dict, base: Path) -> dict:
    """A manifest ``set:`` mapping, validated; errors name the manifest line of the bad key."""
    if value is None:
        return {}
    if not isinstance(value, Mapping):
        raise StageError("set: expected a mapping of dotted config keys", source, lines.get(where))
    keyed = {str(k): lines.get(where + (str(k),)) for k in value}
    flat = {}
    for key, v in value.items():
        flat.update(flatten({str(key): v}) if isinstance(v, Mapping) and v else {str(key): v})
    line_of = {k: keyed.get(k) or keyed.get(k.split(".")[0]) or lines.get(where) for k in flat}
    return validate_overrides(flat, source, base, {k: v for k, v in line_of.items() if v})


def load_manifest(path: str | Path, out: str | Path, cli: SharedOptions,
                  cli_given: Iterable[str] = ()) -> list[HeadJob]:
    """Jobs from a manifest, all validated before any work.

    ``cli`` supplies what the command line gave; names in ``cli_given`` (``fap``,
    ``expression``, ``intensity``, ``seconds``, ``output``) win over the manifest's.
    Raises :class:`StageError`/:class:`ConfigError` ``<manifest>:<line>: <key>: <cause>``.
    """
    from dataclasses import replace

    path = Path(path)
    source, base = str(path), path.absolute().parent
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise StageError("manifest not found", path) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise StageError(f"cannot read manifest: {exc}", path) from None
    data, lines = _yaml_lines(text, source)
    if not isinstance(data, Mapping):
        raise StageError("expected a mapping with a 'heads' list", source, 1)
    for key in data:
        if str(key) not in _MANIFEST_KEYS:
            raise StageError(f"{key}: unknown key (valid: {', '.join(_MANIFEST_KEYS)})", source, lines.get((str(key),)))
    heads = data.get("heads")
    if not isinstance(heads, list) or not heads:
        raise StageError("heads: expected a non-empty list of heads", source, lines.get(("heads",), 1))

    def resolve(value, where):
        if not isinstance(value, str) or not value:
            raise StageError(f"{'.'.join(map(str, where))}: expected a path", source, lines.get(where))
        p = Path(value).expanduser()
        p = p if p.is_absolute() else base / p
        if not p.is_file():
            raise StageError(f"{'.'.join(map(str, where))}: file not found: {p}", source, lines.get(where))
        return str(p)

    given = set(cli_given)
    picked = {k: getattr(cli, k) for k in ("fap", "expression", "intensity", "seconds", "output")}
    for key in [k for k in picked if k in data and k not in given]:
        value = data[key]
        number = key in ("intensity", "seconds")
        if number and (isinstance(value, bool) or not isinstance(value, (int, float)) or value < 0):
            raise StageError(f"{key}: expected a positive number, got {value!r}", source, lines.get((key,)))
        if not number and not isinstance(value, str):
            raise StageError(f"{key}: expected a string, got {value!r}", source, lines.get((key,)))
        picked[key] = resolve(value, ("fap",)) if key == "fap" else value
    if "fap" in given or "expression" in given:   # the command line picks the animation source
        picked["fap"], picked["expression"] = cli.fap, cli.expression
    shared_set = _overrides(data.get("set"), ("set",), source, lines, base)
    shared = replace(cli, **picked, overrides={**shared_set, **cli.overrides})
    try:
        shared.check(source)
    except FaceforgeError as exc:
        raise StageError(exc.message, exc.path or source, exc.line or lines.get(("fap",)) or lines.get(("expression",))) from None
    jobs = []
    for i, head in enumerate(heads):
        where = ("heads", i)
        if not isinstance(head, Mapping) or "mesh" not in head:
            raise StageError(f"heads[{i}]: expected a mapping with a 'mesh' path", source, lines.get(where))
        for key in head:
            if str(key) not in _HEAD_KEYS:
                raise StageError(f"heads[{i}].{key}: unknown key (valid: {', '.join(_HEAD_KEYS)})",
                                 source, lines.get(where + (str(key),)))
        name = head.get("name")
        if name is not None and (not isinstance(name, str) or not name or "/" in name or name.startswith(".")):
            raise StageError(f"heads[{i}].name: expected a folder name, got {name!r}", source, lines.get(where + ("name",)))
        mesh = resolve(head["mesh"], where + ("mesh",))
        landmarks = resolve(head["landmarks"], where + ("landmarks",)) if head.get("landmarks") else None
        own = _overrides(head.get("set"), where + ("set",), source, lines, base)
        jobs.append(make_job(mesh, out, shared, name=name, landmarks=landmarks, overrides=own, base=base))
    check_unique(jobs, source)
    return jobs
