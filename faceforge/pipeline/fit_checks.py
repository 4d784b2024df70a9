"""A fit that fails its own checks is an error, unless the user keeps it on purpose.

The fit report (:func:`faceforge.fit.report.build_report`) carries four named
checks. A fit whose skull ended up outside the skin used to exit 0, and bind and animate
then ran on it (issue 28); now the fit stage stops with exit 3 naming each failed check and
its figure, and ``fit.allow_failed_checks: true`` (``--set fit.allow_failed_checks=true``)
keeps such a fit, with a warning line per check.
"""

from __future__ import annotations

from typing import Callable

from faceforge.exceptions import ChecksFailed


def failed_checks(report: dict) -> list[str]:
    """One phrase per failed check of a fit ``report``, each naming the check, the measured
    figure and the limit, e.g. ``skull_inside_98pct (skull 96.2% inside the skin, needs 98%)``."""
    checks = report.get("checks", {})
    lm, skull, mus = report.get("landmarks", {}), report.get("skull", {}), report.get("muscles", {})

    def pct(x):
        return "n/a" if x is None else f"{100.0 * float(x):.1f}%"

    figures = {
        "landmarks_within_1pct": f"largest landmark residual {pct(lm.get('max_residual'))} of the diagonal, "
                                 "needs < 1%",
        "skull_inside_98pct": f"skull {pct(skull.get('inside_fraction'))} inside the skin, needs 98%",
        "muscles_inside_98pct": f"muscles {pct(mus.get('inside_fraction'))} inside the skin, needs 98%",
        "muscles_poke_below_1pct": f"muscles poke {pct(mus.get('max_outside_rel'))} of the diagonal out of "
                                   "the skin, needs <= 1%",
    }
    return [f"{name} ({figures.get(name, 'failed')})" for name, ok in checks.items() if not ok]


def enforce_checks(report: dict, allow: bool, source, log: Callable[[str], None] = lambda m: None) -> None:
    """Raise :class:`ChecksFailed` (exit 3, naming ``source``, the mesh) when the fit failed a check and
    ``allow`` is False; with ``allow`` log each failed check and go on."""
    failed = failed_checks(report)
    if not failed:
        return
    if allow:
        for phrase in failed:
            log(f"check failed, kept (fit.allow_failed_checks): {phrase}")
        return
    raise ChecksFailed("the fit failed its checks: " + "; ".join(failed)
                     + "; keep it anyway with --set fit.allow_failed_checks=true and look at fit/fit.png",
                     source)
