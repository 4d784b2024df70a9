"""The ``faceforge`` command line: one click group, stage commands discovered lazily.

Built-in commands: ``status``, ``clean``, ``run``, ``config show|validate|reset``.
Stage modules in ``faceforge/pipeline/stages/`` add theirs (fit, bind, animate,
batch) with :func:`faceforge.pipeline.register_command`; see
``faceforge/pipeline/__init__.py`` for the pattern.

Importing this module imports click and the stage registry only, so
``faceforge --help`` stays instant; numpy, numba and trimesh are imported inside
the stages that use them. Every :class:`~faceforge.exceptions.FaceforgeError` is
printed as ``faceforge: error: <file>: <cause>`` with exit status 2 (traceback
with ``-v``); a result that failed its checks (:class:`~faceforge.exceptions.ChecksFailed`) exits 3.
"""

from __future__ import annotations

import os
import sys
import traceback
import warnings
from pathlib import Path

import click

from faceforge.exceptions import ChecksFailed, FaceforgeError
from faceforge.pipeline import stage as registry
from faceforge.pipeline.result_checks import keep_going_option

_BUILTIN_ORDER = ("status", "run", "clean", "config")


class App:
    """The context object of every command (``click.pass_obj``).

    Attributes
    ----------
    workspace : :class:`faceforge.pipeline.runner.Workspace` of ``--workdir``.
    config : the merged, validated :class:`faceforge.io.config.Config`.
    verbosity : ``-v`` count minus ``-q`` (-1 quiet, 0 normal, 1+ verbose).
    """

    def __init__(self, workdir: str, config_file: str | None, sets: tuple[str, ...],
                 verbosity: int, progress: bool | None):
        from faceforge.io.config import load_config, parse_sets, read_config_file
        from faceforge.pipeline.runner import Workspace

        registry.discover()  # the stage modules register their stages and commands
        self.workspace = Workspace(workdir)
        self.verbosity = verbosity
        self.progress = (sys.stderr.isatty() and verbosity >= 0) if progress is None else progress
        # validate every layer before any work
        self.config_file = config_file
        self._file_layer = read_config_file(config_file) if config_file else None
        self._sets = tuple(sets)
        self._set_layer = parse_sets(sets) if sets else None
        self.own_config = self.workspace.own_config()
        if self.own_config is False:
            self.log(f"faceforge: note: {self.workspace.config_path} is not a faceforge config "
                     "(not written by faceforge and not valid as one): ignored")
        self.config = load_config(config_file, sets, remembered=self._remembered_config())
        self._pending_params: dict | None = None   # written by commit_remembered() on success
        self._pending_overrides = False
        #: accept results that fail their checks (a command's ``--keep-going``,
        #: :mod:`faceforge.pipeline.result_checks`)
        self.keep_going = False

    def add_sets(self, *sets: str) -> None:
        """More ``KEY.PATH=VALUE`` overrides, as if given with ``--set`` (a command's own
        options that stand for config keys); validated at once."""
        from faceforge.io.config import load_config, parse_sets

        self._sets += tuple(sets)
        self._set_layer = parse_sets(self._sets)
        self.config = load_config(self.config_file, self._sets, remembered=self._remembered_config())

    def _remembered_config(self):
        """``<workdir>/config.yaml`` when it is faceforge's, else None."""
        return self.workspace.config_path if self.own_config else None

    def log(self, message: str) -> None:
        """A progress line on stderr (hidden with ``-q``)."""
        if self.verbosity >= 0:
            click.echo(message, err=True)

    def debug(self, message: str) -> None:
        if self.verbosity >= 1:
            click.echo(message, err=True)

    def remember_overrides(self) -> None:
        """Fold ``--config``/``--set`` into ``<workdir>/config.yaml`` so later commands reuse them."""
        from faceforge.io.config import merge_trees, read_config_file
        from faceforge.io.stagefiles import save_yaml

        from faceforge.pipeline.runner import CONFIG_HEADER

        layers = [layer for layer in (self._file_layer, self._set_layer) if layer is not None]
        if not layers:
            return
        path = self.workspace.config_path
        if self.workspace.own_config() is False:
            self.log(f"faceforge: note: not remembering --config/--set: {path} is not faceforge's "
                     "(give the head a folder of its own with --workdir)")
            return
        tree = read_config_file(path).tree if path.exists() else {}
        for layer in layers:
            tree = merge_trees(tree, layer.tree)
        save_yaml(path, tree, header=CONFIG_HEADER[2:] + " (from --config/--set);\n"
                                     "edit, or forget them with `faceforge config reset`")
        self.debug(f"remembered overrides in {path}")

    def params(self) -> dict:
        """The remembered inputs as this command will leave them (its stage runs' params, not
        yet written: :meth:`commit_remembered`)."""
        return dict(self._pending_params) if self._pending_params is not None else self.workspace.load_params()

    def commit_remembered(self) -> None:
        """Write what the command's stage runs are to remember (``faceforge.yaml`` and the
        overrides in ``config.yaml``), once the whole command has succeeded: a failed command
        leaves the workdir's remembered inputs as they were, so ``status`` and the next command
        see the last good run (issue 28: a failing ``fit`` of a bad mesh made ``animate`` refit it)."""
        if self._pending_params is not None:
            self.workspace.save_params(self._pending_params)
            self._pending_params = None
        if self._pending_overrides:
            self.remember_overrides()
            self._pending_overrides = False

    def run_stage(self, name: str, params: dict | None = None, force: bool = False):
        """Remember ``params`` and overrides, then bring stage ``name`` and its upstream up to date.

        ``params`` update the inputs remembered in ``<workdir>/faceforge.yaml`` (a value of
        None forgets that key; names listed in some stage's ``inputs`` are made absolute
        paths). ``--config``/``--set`` are folded into ``<workdir>/config.yaml``. Returns
        the list of :class:`~faceforge.pipeline.runner.StageStatus`.
        """
        from faceforge.pipeline import runner

        stage = registry.get_stage(name)
        inputs = {n.rstrip("?") for s in registry.stage_order([name]) for n in s.inputs}
        self.workspace.root.mkdir(parents=True, exist_ok=True)
        remembered = dict(self._pending_params) if self._pending_params is not None else self.workspace.load_params()
        for key, value in (params or {}).items():
            if value is None:
                remembered.pop(key, None)  # given as None: forget the earlier value
            else:
                remembered[key] = os.path.abspath(value) if key in inputs else value
        if params:
            self._pending_params = remembered
        self._pending_overrides = True
        statuses = runner.run(self.workspace, self.config, remembered, [stage.name], force=force,
                              log=self.log, progress=self.progress)
        from faceforge.pipeline.result_checks import enforce

        # ran now or up to date: a failed result is an error every time it is asked for
        enforce(self.workspace.stage_dir(stage.name), stage.name, self.keep_going,
                lambda line: click.echo(line, err=True))   # shown with -q too, as warnings are
        return statuses


class FaceforgeGroup(click.Group):
    """Lists built-in commands plus those registered by stage modules; formats errors."""

    def list_commands(self, ctx):
        registry.discover()
        extra = sorted(name for name in registry.COMMANDS if name not in self.commands)
        return [n for n in _BUILTIN_ORDER if n in self.commands] + extra

    def get_command(self, ctx, name):
        if name in self.commands:
            return self.commands[name]
        registry.discover()
        return registry.COMMANDS.get(name)

    def invoke(self, ctx):
        try:
            result = super().invoke(ctx)
            if isinstance(ctx.obj, App):
                ctx.obj.commit_remembered()
            return result
        except FaceforgeError as exc:
            if isinstance(exc, ChecksFailed) and exc.kept and isinstance(ctx.obj, App):
                ctx.obj.commit_remembered()   # the stage folders hold this run's inputs' result
            verbose = ctx.params.get("verbose", 0) > 0
            if verbose:
                traceback.print_exc()
            click.echo(f"faceforge: error: {one_line(str(exc))}", err=True)
            ctx.exit(exc.exit_code)
        except OSError as exc:   # the user's file system said no (an unwritable --preview, a full disk)
            if ctx.params.get("verbose", 0) > 0:
                traceback.print_exc()
            where = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
            click.echo(f"faceforge: error: {where}{one_line(exc.strerror or str(exc))}", err=True)
            ctx.exit(2)

    def main(self, args=None, prog_name=None, complete_var=None, standalone_mode=True, **extra):
        """click's main, but a usage error is one line ``faceforge: error: ...`` with exit 2
        (click prints three: usage, a hint and the error)."""
        if not standalone_mode:
            return super().main(args, prog_name, complete_var, standalone_mode, **extra)
        try:
            with warnings.catch_warnings():
                warnings.showwarning = _show_warning
                rv = super().main(args, prog_name, complete_var, standalone_mode=False, **extra)
        except click.ClickException as exc:
            if type(exc).__name__ == "NoArgsIsHelpError":   # bare `faceforge`: the help, as click gives it
                exc.show()
                sys.exit(exc.exit_code)
            click.echo(f"faceforge: error: {one_line(exc.format_message())}", err=True)
            sys.exit(2 if isinstance(exc, click.UsageError) else exc.exit_code)
        except click.exceptions.Abort:
            click.echo("faceforge: aborted", err=True)
            sys.exit(1)
        sys.exit(rv if isinstance(rv, int) else 0)


def one_line(text: str, limit: int = 2000) -> str:
    """``text`` on one line, at most ``limit`` characters (an error quoting a huge value stays short)."""
    flat = " ".join(str(text).split())
    return flat if len(flat) <= limit else flat[:limit - 3] + "..."


def _show_warning(message, category, filename, lineno, file=None, line=None):
    """Warnings (e.g. a repaired FAP file) as one line ``faceforge: warning: ...`` on stderr."""
    click.echo(f"faceforge: warning: {one_line(str(message))}", err=True)


@click.group(cls=FaceforgeGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.option("--workdir", "-w", type=click.Path(file_okay=False), default=".", show_default=True,
              help="Folder holding the current head's stages (one per head).")
@click.option("--config", "config_file", type=click.Path(dir_okay=False), default=None,
              help="YAML file merged over the defaults (remembered by stage commands).")
@click.option("--set", "sets", multiple=True, metavar="KEY.PATH=VALUE",
              help="Override one config value (YAML scalar); repeatable.")
@click.option("-v", "--verbose", count=True, help="More output; tracebacks on errors.")
@click.option("-q", "--quiet", is_flag=True, help="Only errors.")
@click.option("--progress/--no-progress", default=None,
              help="Progress bars on stderr [default: only on a terminal, not with -q].")
@click.version_option(package_name="faceforge", prog_name="faceforge")
@click.pass_context
def cli(ctx, workdir, config_file, sets, verbose, quiet, progress):
    """faceforge: fit a skull and muscles into a head mesh, bind the skin and
    animate it with MPEG-4 FAPs (Fratarcangeli 2012, position-based dynamics).

    \b
    faceforge --workdir work fit head.obj --landmarks head.fdp.yaml
    faceforge --workdir work bind
    faceforge --workdir work animate --fap joy.fap -o work/joy.pc2
    """
    ctx.obj = App(workdir, config_file, tuple(sets), verbose - (1 if quiet else 0), progress)


@cli.command()
@click.pass_obj
def status(app: App):
    """List the stages and why each is or is not up to date."""
    from faceforge.pipeline.runner import plan

    statuses = plan(app.workspace, app.config, app.workspace.load_params())
    if not statuses:
        click.echo("no stages registered yet")
        return
    width = max(len(s.stage.name) for s in statuses)
    for s in statuses:
        if s.up_to_date:
            from faceforge.pipeline.result_checks import stage_failures

            failures = stage_failures(app.workspace.stage_dir(s.stage.name))
            state = "up to date" + (f"; failed its checks: {'; '.join(failures)}" if failures else "")
        else:
            state = ("stale: " if s.key else "cannot run: ") + "; ".join(s.reasons)
        click.echo(f"{s.stage.name:<{width}}  {state}")
        if app.verbosity >= 1 and s.key:
            click.echo(f"{'':<{width}}  key {s.key[:16]}  {s.stage.description}")


@cli.command("run")
@click.argument("stage_name", metavar="STAGE")
@click.option("--param", "params", multiple=True, metavar="NAME=VALUE",
              help="Set a remembered input (a path for names listed in the stage's inputs).")
@click.option("--force", is_flag=True, help="Rerun STAGE even if it is up to date.")
@keep_going_option
@click.pass_obj
def run_command(app: App, stage_name, params, force):
    """Bring STAGE and everything upstream of it up to date."""
    values = {}
    for item in params:
        name, sep, value = item.partition("=")
        if not sep or not name:
            raise click.BadParameter(f"expected NAME=VALUE, got {item!r}", param_hint="--param")
        values[name] = value
    app.run_stage(stage_name, values, force=force)


@cli.command()
@click.argument("stages", nargs=-1)
@click.option("--forget", is_flag=True, help="Also forget remembered inputs and config overrides.")
@click.pass_obj
def clean(app: App, stages, forget):
    """Delete stage folders (all, or STAGES); user files are kept."""
    from faceforge.pipeline.runner import clean as clean_stages

    for name in stages:
        registry.get_stage(name)
    removed = clean_stages(app.workspace, list(stages) or None, log=app.log)
    app.log(f"removed {', '.join(removed)}" if removed else "nothing to remove")
    if forget:
        for path in (app.workspace.params_path, app.workspace.config_path):
            if path == app.workspace.config_path and app.workspace.own_config() is False:
                app.log(f"kept {path}: not faceforge's")
                continue
            if path.exists():
                path.unlink()
                app.log(f"forgot {path.name}")


@cli.group("config")
def config_group():
    """Show, validate or reset the configuration."""


@config_group.command("show")
@click.option("--origins/--no-origins", default=True, help="Mark values not from the defaults.")
@click.pass_obj
def config_show(app: App, origins):
    """Print the merged, validated configuration as YAML."""
    click.echo(app.config.to_yaml(annotate=origins), nl=False)


@config_group.command("validate")
@click.argument("file", type=click.Path(dir_okay=False))
@click.pass_obj
def config_validate(app: App, file):
    """Check FILE against the schema (configs/default.yaml); print every problem."""
    from faceforge.exceptions import ConfigError
    from faceforge.io.config import read_config_file

    try:
        read_config_file(file)
    except ConfigError as exc:
        for err in getattr(exc, "all_errors", [exc])[:-1]:
            click.echo(f"faceforge: error: {err}", err=True)
        raise getattr(exc, "all_errors", [exc])[-1] from None
    app.log(f"{file}: ok")


@config_group.command("reset")
@click.pass_obj
def config_reset(app: App):
    """Forget the overrides remembered in <workdir>/config.yaml."""
    path: Path = app.workspace.config_path
    if app.workspace.own_config() is False:
        app.log(f"kept {path}: not faceforge's")
    elif path.exists():
        path.unlink()
        app.log(f"removed {path}")
    else:
        app.log("no remembered overrides")


def main(argv: list[str] | None = None) -> None:
    """Console-script entry point (``faceforge``); FACEFORGE_<OPTION> env vars set defaults."""
    cli.main(args=argv, prog_name="faceforge", auto_envvar_prefix="FACEFORGE")


if __name__ == "__main__":  # pragma: no cover
    main()
