"""A result that fails its checks is an error (exit 3), unless the user accepts it (``--keep-going``).

The animate, arkit, expressions, visemes and bake stages write physical checks into their
``report.json`` (:class:`faceforge.animation.checks.FrameReport`: a ``"checks"`` mapping with
``"ok"``, once for a take, once per pose or shape). Such a stage's folder is still committed to
the workdir (its files are valid, the cache keeps the simulation, the user may want to look), but
the command that asked for it -- whether the stage ran now or was up to date -- stops with
:class:`~faceforge.exceptions.ChecksFailed`: one line naming each failed check and where (frame,
vertex or edge count), exit status 3, and without writing its ``-o``/``--preview`` exports.
``--keep-going`` logs the same as warnings and goes on (exit 0).

Why the exports are not written: a take or a shape set that fails its checks is broken (skin
inside the bone, triangles turned over, a crumpled face), and a script that plays the exported
file does not read the log; the workdir's own files are kept so that ``--keep-going`` costs no
second simulation and ``report.json`` says what failed.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Callable, Iterator

import click

from faceforge.exceptions import ChecksFailed


def _check_blocks(report: Any, path: tuple = ()) -> Iterator[tuple[tuple, dict]]:
    """(path of keys, checks mapping) of every ``"checks": {"ok": ...}`` in a report, in order."""
    if isinstance(report, dict):
        checks = report.get("checks")
        if isinstance(checks, dict) and "ok" in checks:
            yield path, checks
        for key, value in report.items():
            if key != "checks":
                yield from _check_blocks(value, path + (str(key),))


def _frame(where: dict, name: str) -> str:
    value = where.get(name)
    if value is None:
        return ""
    return f" at frame {value[0] if isinstance(value, list) else value}"


def describe(checks: dict) -> list[str]:
    """One phrase per failed check of a :class:`FrameReport` mapping (``as_dict``), naming the check,
    the count and the frame, e.g. ``skin_inside_skull (1 skin vertex inside the skull at frame 33)``."""
    where = checks.get("where") or {}
    out = []
    if checks.get("non_finite"):
        out.append(f"non_finite ({checks['non_finite']} frames with NaN or infinite positions, the first"
                   f"{_frame(where, 'non_finite') or ' unknown'})")
    if checks.get("inverted_triangles"):
        out.append(f"inverted_triangles ({checks.get('inverted_faces', '?')} triangles turned over, at most "
                   f"{checks.get('inverted_max_per_frame', '?')} in one frame, the first{_frame(where, 'inverted')})")
    if checks.get("skin_inside_skull"):
        frames = where.get("inside_skull") or {}
        count = checks["skin_inside_skull"]
        at = (f" at frame {next(iter(frames))}" if len(frames) == 1 else
              " (" + ", ".join(f"{n} at frame {f}" for f, n in frames.items()) + ")" if frames else "")
        out.append(f"skin_inside_skull ({count} skin vert{'ex' if count == 1 else 'ices'} inside the skull{at})")
    limit = checks.get("fold_limit")
    if limit is not None and checks.get("folded_max_per_frame", 0) > limit:
        out.append(f"folded_edges ({checks['folded_max_per_frame']} skin edges folded in one frame"
                   f"{_frame(where, 'folded')}, limit {limit})")
    most = checks.get("displacement_limit")
    if most is not None and checks.get("max_displacement", 0.0) > most:
        from faceforge.animation.checks import THROWN

        out.append(f"thrown_vertex (a skin vertex moved {checks['max_displacement']:.4g} units"
                   f"{_frame(where, 'thrown')}, past the limit {most:.4g}: {THROWN:g} of the skin's diagonal)")
    carried = checks.get("carried") or {}
    if carried.get("inverted_triangles"):
        out.append(f"carried_inverted ({carried.get('inverted_faces', '?')} triangles of the user's mesh turned over "
                   f"on its simulation mesh, at most {carried.get('inverted_max_per_frame', '?')} in one frame, the "
                   f"first at frame {carried.get('inverted')})")
    if not out and checks.get("ok") is False:
        out.append("checks failed (see report.json)")
    return out


def failed_checks(report: dict) -> list[str]:
    """Every failed check of a stage's ``report``: ``"<pose>: <phrase>"`` for a pose or shape
    (``expressions.fear``, the pose's name), the bare phrase for a take."""
    out = []
    for path, checks in _check_blocks(report):
        if checks.get("ok") is False:
            label = path[-1] if path else ""
            out += [f"{label}: {phrase}" if label else phrase for phrase in describe(checks)]
    return out


def stage_failures(stage_dir: Path) -> list[str]:
    """:func:`failed_checks` of ``<stage_dir>/report.json`` (none without a readable report)."""
    try:
        report = json.loads((Path(stage_dir) / "report.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return []
    return failed_checks(report)


def enforce(stage_dir: Path, name: str, keep_going: bool, log: Callable[[str], None] = lambda m: None) -> None:
    """Raise :class:`ChecksFailed` when stage ``name``'s result in ``stage_dir`` failed a check,
    unless ``keep_going`` (then one warning line per failed check)."""
    failures = stage_failures(stage_dir)
    if not failures:
        return
    if keep_going:
        for phrase in failures:
            log(f"faceforge: warning: {name}: check failed, kept (--keep-going): {phrase}")
        return
    shown = failures if len(failures) <= 6 else failures[:6] + [f"and {len(failures) - 6} more"]
    error = ChecksFailed(f"{name} failed its checks: {'; '.join(shown)}; the result is kept in {stage_dir} "
                         "(outputs not written); accept it with --keep-going", Path(stage_dir) / "report.json")
    error.kept = True
    raise error


def _remember(ctx, param, value):
    if value and ctx.obj is not None:
        ctx.obj.keep_going = True
    return value


#: the ``--keep-going`` option of a command whose stage writes checks (sets ``App.keep_going``)
keep_going_option = click.option(
    "--keep-going", is_flag=True, expose_value=False, callback=_remember,
    help="Write the outputs even when the result fails its physical checks (a warning per failed "
         "check; exit 0). Without it a failed check exits 3 and writes no -o/--preview.")
