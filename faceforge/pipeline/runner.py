"""Run stages in a workdir: plan (which are stale and why), run atomically, status, clean.

Workdir layout::

    <workdir>/faceforge.yaml      remembered params (input paths) of the last runs
    <workdir>/config.yaml         remembered config overrides (--config/--set of stage runs)
    <workdir>/.faceforge.lock     fcntl lock serializing processes
    <workdir>/<stage>/            one folder per complete stage, stage.json inside (a folder
                                  of that name without stage.json is never overwritten)
    <workdir>/.tmp-<stage>-*      a stage being written (removed on the next run if stale)

A stage is written into ``.tmp-<stage>-<pid>-<token>/``, its ``stage.json`` last,
and only then renamed to ``<stage>/`` (the previous folder is first moved aside).
A run killed at any instant therefore leaves either the old complete folder,
no folder, or a temp folder that the next run deletes: never a folder that
looks complete but is not.
"""

from __future__ import annotations

import os
import secrets
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping

from faceforge.exceptions import StageError
from faceforge.pipeline.cache import (file_digest, folder_digests, outputs_digest, read_stage_json, record_key,
                                      settled_record, stale_reasons)
from faceforge.pipeline.lock import WorkdirLock
from faceforge.pipeline.stage import COMMANDS, STAGES, Stage, StageContext, broken_stages, stage_order

PARAMS_FILE = "faceforge.yaml"
CONFIG_FILE = "config.yaml"
_TEMP_PREFIXES = (".tmp-", ".trash-")
#: the first line faceforge writes into a workdir's config.yaml (how it knows its own file)
CONFIG_HEADER = "# config overrides remembered for this workdir"


class Workspace:
    """The files of one workdir (see the module docstring)."""

    def __init__(self, workdir: str | Path):
        self.root = Path(workdir).absolute()

    @property
    def params_path(self) -> Path:
        return self.root / PARAMS_FILE

    @property
    def config_path(self) -> Path:
        return self.root / CONFIG_FILE

    def stage_dir(self, name: str) -> Path:
        return self.root / name

    def own_config(self) -> bool | None:
        """Whether ``config.yaml`` is faceforge's: None when absent; True when it carries the
        header faceforge writes (:data:`CONFIG_HEADER`) or validates as a faceforge config;
        False for a file of someone else's that merely shares the name (a foreign
        ``config.yaml`` in the current folder must not break commands run without --workdir,
        nor be rewritten or deleted by them)."""
        from faceforge.exceptions import ConfigError
        from faceforge.io.config import read_config_file

        path = self.config_path
        if not path.is_file():
            return None if not path.exists() else False
        try:
            with open(path, "rb") as fh:
                if fh.read(len(CONFIG_HEADER)).decode("utf-8", "replace") == CONFIG_HEADER:
                    return True
            read_config_file(path)
        except (ConfigError, OSError):
            return False
        return True

    def load_params(self) -> dict:
        """Remembered params (``{}`` for a new workdir)."""
        from faceforge.io.stagefiles import load_yaml

        if not self.params_path.exists():
            return {}
        data = load_yaml(self.params_path) or {}
        params = data.get("params") if isinstance(data, dict) else None
        if not isinstance(params, dict):
            raise StageError("expected a mapping with a 'params' key", self.params_path)
        return params

    def save_params(self, params: Mapping[str, Any]) -> None:
        from faceforge.io.stagefiles import save_yaml

        save_yaml(self.params_path, {"params": dict(params)},
                  header="faceforge workdir: inputs remembered from the last runs (written by faceforge)")

    def clean_temp(self) -> list[Path]:
        """Delete leftovers of interrupted runs (call with the lock held)."""
        removed = []
        if self.root.is_dir():
            for child in self.root.iterdir():
                if child.is_dir() and child.name.startswith(_TEMP_PREFIXES):
                    shutil.rmtree(child, ignore_errors=True)
                    removed.append(child)
        return removed

    def lock(self, notify: Callable[[str], None] = lambda msg: None) -> WorkdirLock:
        return WorkdirLock(self.root, notify)


@dataclass
class StageStatus:
    """A stage's current record and key, and why it is stale (empty: up to date)."""

    stage: Stage
    record: dict | None
    key: str | None
    reasons: list[str] = field(default_factory=list)
    ran: bool = False
    #: the required inputs that are not there (bare names, e.g. ``("mesh",)``)
    missing: tuple = ()
    seconds: float = 0.0

    @property
    def up_to_date(self) -> bool:
        return not self.reasons


def _resolve_input(name: str, config, params: Mapping) -> str | None:
    name = name.rstrip("?")
    if name in params:
        value = params[name]
    else:
        value = config.get(name, None) if "." in name else None
    return None if value in (None, "") else str(value)


def current_record(stage: Stage, config, params: Mapping,
                   upstream: Mapping[str, str | None]) -> tuple[dict, list[str]]:
    """The record of ``stage`` for the present inputs, and the names of missing required inputs.
    ``upstream``: each dep's :func:`~faceforge.pipeline.cache.outputs_digest` (None: the dep is
    stale, its output not known yet)."""
    missing, inputs = [], {}
    for name in stage.inputs:
        path = _resolve_input(name, config, params)
        if path is None:
            inputs[name.rstrip("?")] = None
            if not name.endswith("?"):
                missing.append(name)
            continue
        if not Path(path).exists():
            inputs[name.rstrip("?")] = None
            missing.append(f"{name.rstrip('?')} ({path} not found)")
            continue
        digest = stage.digests.get(name.rstrip("?"), file_digest)
        inputs[name.rstrip("?")] = {"path": path, "sha256": digest(path)}
    record = {
        "stage": stage.name,
        "version": str(stage.version),
        "config": {key: config.get(key) for key in stage.config_keys},
        "inputs": inputs,
        "upstream": {dep: upstream[dep] for dep in stage.deps},
    }
    return record, missing


def plan(workspace: Workspace, config, params: Mapping,
         targets: Iterable[str] | None = None) -> list[StageStatus]:
    """Status of the stages needed for ``targets`` (all when None), upstream first.

    With ``targets=None``, stages whose deps are not registered are listed last with
    the reason instead of failing the whole listing.
    """
    statuses: list[StageStatus] = []
    digests: dict[str, str | None] = {}
    order = stage_order(targets)
    read = {dep for stage in order for dep in stage.deps}   # a leaf's files (a long take) are not hashed
    default = _default_config()
    for stage in order:
        record, missing = current_record(stage, config, params, digests)
        # config keys newer than the stored record, at their defaults, change nothing (cache.settled_record)
        record = settled_record(record, read_stage_json(workspace.stage_dir(stage.name)), default)
        status = StageStatus(stage, record, None, [], missing=tuple(m.split(" (")[0] for m in missing))
        _judge(workspace, status, [f"needs input {', '.join(missing)}"] if missing else None)
        if stage.name in read:
            digests[stage.name] = _digest_if_current(workspace, status)
        statuses.append(status)
    if targets is None:
        statuses += [StageStatus(STAGES[n], None, None, [r]) for n, r in broken_stages().items()]
    return statuses


def _default_config():
    """The packaged default configuration (:func:`faceforge.io.config.load_default`) as a
    :class:`~faceforge.io.config.Config`."""
    from faceforge.io.config import Config, load_default

    return Config(load_default().tree)


def _judge(workspace: Workspace, status: StageStatus, reasons: list[str] | None = None) -> None:
    """Set ``status.key`` from its record and ``status.reasons`` (``reasons`` when given, else
    why the stored stage.json differs, or a missing output)."""
    status.key = record_key(status.record)
    if reasons is None:
        folder = workspace.stage_dir(status.stage.name)
        reasons = stale_reasons(status.record, read_stage_json(folder))
        if not reasons:
            absent = [o for o in status.stage.outputs if not (folder / o).exists()]
            if absent:
                reasons = [f"output missing: {', '.join(absent)}"]
    status.reasons = reasons


def _digest_if_current(workspace: Workspace, status: StageStatus) -> str | None:
    """The stage's outputs digest when it is up to date, else None (it reruns first)."""
    if status.reasons:
        return None
    return outputs_digest(read_stage_json(workspace.stage_dir(status.stage.name)) or {})


def _commit(workspace: Workspace, tmp: Path, name: str) -> None:
    """Rename the finished temp folder to ``<workdir>/<name>`` (old folder moved aside first)."""
    final = workspace.stage_dir(name)
    trash = None
    if final.exists() and not (final / "stage.json").exists():
        raise StageError(f"{final} exists but is not a faceforge stage folder (no stage.json); move it away")
    if final.exists():
        trash = workspace.root / f".trash-{name}-{os.getpid()}-{secrets.token_hex(4)}"
        os.rename(final, trash)
    os.rename(tmp, final)
    if trash is not None:
        shutil.rmtree(trash, ignore_errors=True)


def run_stage(workspace: Workspace, status: StageStatus, config, params: Mapping,
              log: Callable[[str], None] = lambda msg: None, progress: bool = False) -> None:
    """Run one stale stage into a temp folder and rename it into place (lock must be held)."""
    from faceforge import __version__
    from faceforge.io.stagefiles import save_json

    stage = status.stage
    tmp = workspace.root / f".tmp-{stage.name}-{os.getpid()}-{secrets.token_hex(4)}"
    try:
        tmp.mkdir(parents=True)
    except OSError as exc:   # a read-only workdir: said before the stage's work, not after
        raise StageError(f"cannot write in the workdir: {exc.strerror or exc}", workspace.root) from None
    ctx = StageContext(name=stage.name, config=config, params=dict(params), out_dir=tmp,
                       workdir=workspace.root, deps=stage.deps, progress_enabled=progress, logger=log)
    start = time.perf_counter()
    try:
        stage.run(ctx)
        absent = [o for o in stage.outputs if not (tmp / o).exists()]
        if absent:
            raise StageError(f"stage {stage.name} did not write {', '.join(absent)}")
        status.seconds = time.perf_counter() - start
        # no timings or dates: same inputs give the same bytes
        save_json(tmp / "stage.json", {**status.record, "key": status.key, "outputs": list(stage.outputs),
                                        "output_sha256": folder_digests(tmp), "faceforge_version": __version__})
        _commit(workspace, tmp, stage.name)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    status.ran = True


def run(workspace: Workspace, config, params: Mapping, targets: Iterable[str], force: bool = False,
        log: Callable[[str], None] = lambda msg: None, progress: bool = False) -> list[StageStatus]:
    """Bring ``targets`` and their upstream stages up to date; ``force`` reruns the targets.

    Holds the workdir lock for the whole run, deletes temp folders of interrupted
    runs, logs one line per stage ("fit: up to date", "bind: running (`bind.x`
    changed)"). Raises :class:`StageError` when a required input is missing.
    """
    targets = list(targets)
    workspace.root.mkdir(parents=True, exist_ok=True)
    with workspace.lock(notify=log):
        for leftover in workspace.clean_temp():
            log(f"removed {leftover.name} left by an interrupted run")
        statuses = plan(workspace, config, params, targets)
        digests: dict[str, str | None] = {}
        read = {dep for status in statuses for dep in status.stage.deps}
        for status in statuses:
            name = status.stage.name
            upstream = {dep: digests[dep] for dep in status.stage.deps}
            if upstream != status.record["upstream"] and not status.missing:
                # an upstream ran: this stage's key holds what it wrote now (an upstream that wrote
                # the same bytes as before leaves this stage up to date)
                status.record = {**status.record, "upstream": upstream}
                _judge(workspace, status)
            if force and name in targets and not status.reasons:
                status.reasons = ["--force"]
            if status.reasons and status.reasons[0].startswith("needs input"):
                # said as the last stage of the plan that reads the same inputs (the mesh is read
                # by the landmarks stage, then by fit: `bind` in a new workdir says to run fit);
                # no hint when that is a stage asked for (the input is the user's own argument)
                readers = [st.stage.name for st in statuses
                           if set(status.missing) <= {n.rstrip("?") for n in st.stage.inputs}]
                owner = readers[-1] if readers else name
                hint = "" if owner in targets else \
                    f"; run `faceforge {owner if owner in COMMANDS else 'run ' + owner}` first"
                raise StageError(f"stage {owner} {status.reasons[0]}{hint}", workspace.root)
            if not status.reasons:
                log(f"{name}: up to date")
                if name in read:
                    digests[name] = _digest_if_current(workspace, status)
                continue
            log(f"{name}: running ({'; '.join(status.reasons)})")
            if status.stage.background is not None:
                status.stage.background(log)
            run_stage(workspace, status, config, params, log=log, progress=progress)
            log(f"{name}: done in {status.seconds:.1f} s")
            if name in read:
                digests[name] = outputs_digest(read_stage_json(workspace.stage_dir(name)) or {})
    return statuses


def clean(workspace: Workspace, names: Iterable[str] | None = None,
          log: Callable[[str], None] = lambda msg: None) -> list[str]:
    """Delete stage folders (those holding a stage.json) and temp leftovers; keep user files."""
    removed = []
    if not workspace.root.is_dir():
        return removed
    with workspace.lock(notify=log):
        workspace.clean_temp()
        wanted = list(STAGES) if names is None else list(names)
        for name in wanted:
            folder = workspace.stage_dir(name)
            if not folder.is_dir():
                continue
            if not (folder / "stage.json").exists():
                log(f"kept {folder}: no stage.json, not a faceforge stage folder")
                continue
            shutil.rmtree(folder)
            removed.append(name)
    return removed
