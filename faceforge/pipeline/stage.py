"""Stage declarations, the stage and command registries, and the context a stage runs in.

A stage is declared once, at the bottom of its module in ``faceforge/pipeline/stages/``::

    STAGE = register_stage(Stage(name="bind", deps=("fit",), config_keys=("bind",),
                                 outputs=("bind.npz", "report.json"), version="1", run=run))

The registries are plain dicts filled by one line per module; :func:`discover`
imports every module of ``faceforge.pipeline.stages`` once, so a new stage needs no
edit anywhere else. Stage modules must be cheap to import: heavy imports go
inside ``run``.
"""

from __future__ import annotations

import importlib
import pkgutil
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping

from faceforge.exceptions import StageError


@dataclass(frozen=True)
class Stage:
    """What a stage reads and writes; the cache key hashes exactly these.

    Attributes
    ----------
    name : folder name in the workdir and command name.
    run : ``run(ctx: StageContext) -> None``; writes ``outputs`` into ``ctx.out_dir``.
    deps : upstream stage names (their keys enter this stage's key).
    config_keys : dotted config keys read, each naming a subtree (``"skin.stiffness"``).
    inputs : names of user files whose *content* is hashed: a param name (``"mesh"``)
        or a dotted config key holding a path (``"template.skull"``; folders hash all
        their files). A trailing ``?`` marks an optional input.
    outputs : file names ``run`` must create in ``ctx.out_dir``.
    digests : ``{input name: digest(path) -> str}`` for inputs of which the stage reads only a
        part (default: the file's bytes, :func:`faceforge.pipeline.cache.file_digest`).
    version : bump when the code changes what the stage writes.
    description : one line for ``faceforge status``.
    background : ``background(log)``, called before the stage runs: starts work that later
        stages need and this one does not (fit and bind start compiling the solver's kernels
        on a fresh install, :mod:`faceforge.pbd.compile_ahead`); it must return at once.
    """

    name: str
    run: Callable[["StageContext"], None]
    deps: tuple[str, ...] = ()
    config_keys: tuple[str, ...] = ()
    inputs: tuple[str, ...] = ()
    outputs: tuple[str, ...] = ()
    digests: dict = field(default_factory=dict, hash=False)
    version: str = "1"
    description: str = ""
    background: Callable[[Callable[[str], None]], Any] | None = field(default=None, hash=False)

    def __post_init__(self):
        if not self.name.isidentifier():
            raise ValueError(f"stage name must be an identifier, got {self.name!r}")
        for attr in ("deps", "config_keys", "inputs", "outputs"):
            value = getattr(self, attr)
            if isinstance(value, str):
                raise ValueError(f"Stage.{attr} must be a tuple of strings, got the string {value!r}")
            object.__setattr__(self, attr, tuple(value))
        unknown = set(self.digests) - {name.rstrip("?") for name in self.inputs}
        if unknown:
            raise ValueError(f"Stage.digests names inputs the stage does not have: {sorted(unknown)}")
        if "stage.json" in self.outputs:
            raise ValueError("stage.json is written by the runner, not listed as an output")


#: stage name -> Stage, filled by :func:`register_stage`
STAGES: dict[str, Stage] = {}
#: command name -> click command, filled by :func:`register_command`
COMMANDS: dict[str, Any] = {}

_DISCOVERED = False


def register_stage(stage: Stage, replace: bool = False) -> Stage:
    """Add ``stage`` to :data:`STAGES`; returns it. Deps may register later (checked on use)."""
    if stage.name in STAGES and not replace and STAGES[stage.name] is not stage:
        raise ValueError(f"stage {stage.name!r} is already registered")
    STAGES[stage.name] = stage
    return stage


def register_command(command: Any) -> Any:
    """Add a click command to the ``faceforge`` group (by its ``name``); returns it."""
    COMMANDS[command.name] = command
    return command


def discover(package: str = "faceforge.pipeline.stages") -> None:
    """Import every module of ``package`` once (sorted by name), filling the registries."""
    global _DISCOVERED
    if _DISCOVERED:
        return
    _DISCOVERED = True
    pkg = importlib.import_module(package)
    for info in sorted(pkgutil.iter_modules(pkg.__path__), key=lambda m: m.name):
        if not info.name.startswith("_"):
            importlib.import_module(f"{package}.{info.name}")


def get_stage(name: str) -> Stage:
    """The registered stage ``name``; the error lists the valid names."""
    discover()
    if name not in STAGES:
        valid = ", ".join(STAGES) or "none registered"
        raise StageError(f"unknown stage {name!r} (stages: {valid})")
    return STAGES[name]


def broken_stages() -> dict[str, str]:
    """Registered stages that cannot run because a dep (direct or not) is not registered."""
    discover()
    broken: dict[str, str] = {}

    def check(name: str, path: tuple[str, ...]) -> str | None:
        if name in path:
            return f"dependency cycle {' -> '.join(path + (name,))}"
        if name not in STAGES:
            return f"depends on unknown stage {name!r}"
        for dep in STAGES[name].deps:
            reason = check(dep, path + (name,))
            if reason:
                return reason
        return None

    for name in STAGES:
        reason = check(name, ())
        if reason:
            broken[name] = reason
    return broken


def stage_order(targets: Iterable[str] | None = None) -> list[Stage]:
    """Stages needed for ``targets`` upstream first, registry order kept.

    With ``targets=None``: every registered stage except the :func:`broken_stages`.
    """
    discover()
    if targets is None:
        broken = broken_stages()
        names = [name for name in STAGES if name not in broken]
    else:
        names = list(targets)
    order: list[Stage] = []
    seen: set[str] = set()

    def visit(name: str, path: tuple[str, ...]):
        if name in path:
            raise StageError(f"stage dependency cycle: {' -> '.join(path + (name,))}")
        if name in seen:
            return
        if path and name not in STAGES:
            raise StageError(f"stage {path[-1]!r} depends on unknown stage {name!r}")
        stage = get_stage(name)
        for dep in stage.deps:
            visit(dep, path + (name,))
        seen.add(name)
        order.append(stage)

    for name in names:
        visit(name, ())
    return order


def downstream(name: str) -> list[str]:
    """Registered stages that depend on ``name``, directly or not."""
    out = []
    for stage in stage_order():
        if any(dep == name or dep in out for dep in stage.deps):
            out.append(stage.name)
    return out


@dataclass
class StageContext:
    """What ``Stage.run`` receives.

    Attributes
    ----------
    name : the stage's name.
    config : the validated :class:`faceforge.io.config.Config` (dotted ``get``).
    params : user inputs remembered in the workdir (``{"mesh": "/abs/head.obj", ...}``).
    out_dir : temporary folder; renamed to ``<workdir>/<name>/`` when ``run`` returns.
    workdir : the working folder.
    """

    name: str
    config: Any
    params: Mapping[str, Any]
    out_dir: Path
    workdir: Path
    deps: tuple[str, ...] = ()
    progress_enabled: bool = False
    logger: Callable[[str], None] = field(default=lambda msg: None)

    def input(self, stage_name: str) -> Path:
        """Folder of an upstream stage (must be one of this stage's deps)."""
        if stage_name not in self.deps:
            raise StageError(f"stage {self.name!r} reads {stage_name!r} but does not list it in deps")
        return self.workdir / stage_name

    def param(self, name: str) -> Any:
        """A remembered user input; :class:`StageError` if it was never given."""
        if self.params.get(name) is None:
            raise StageError(f"{self.name}: no {name} given", self.workdir)
        return self.params[name]

    def log(self, message: str) -> None:
        """One progress line on stderr, prefixed with the stage name (silent with ``-q``)."""
        if not self.progress_enabled:
            self.logger(f"{self.name}: {message}")
            return
        from tqdm import tqdm

        with tqdm.external_write_mode(file=sys.stderr):  # keep open bars intact
            self.logger(f"{self.name}: {message}")

    def progress(self, iterable: Iterable | None = None, total: int | None = None, desc: str | None = None):
        """Wrap ``iterable`` in a tqdm bar on stderr (silent with -q / without a TTY unless asked)."""
        from tqdm import tqdm

        return tqdm(iterable, total=total, desc=f"{self.name}: {desc}" if desc else self.name,
                    file=sys.stderr, disable=not self.progress_enabled, leave=False, dynamic_ncols=True)
