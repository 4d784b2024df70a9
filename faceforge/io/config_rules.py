"""The rules that check a configuration's leaf values (:mod:`faceforge.io.config`).

The schema is ``configs/default.yaml``: a key's default value decides its type and
:func:`rule_for` gives its check; :data:`RULES` adds ranges, enumerations and paths where the
default's type is not enough (the first glob that matches a dotted key wins).
"""

from __future__ import annotations

import fnmatch
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any



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
class OffOrInteger(Rule):
    """0 (off), or an integer >= ``low``: a size below which the feature makes no sense."""

    low: int = 1

    def describe(self) -> str:
        return f"0 (off) or an integer >= {self.low}"

    def check(self, value, base):
        try:
            value = Integer(0).check(value, base)
        except ValueError:
            raise ValueError(self.describe()) from None
        if 0 < value < self.low:
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


#: ``bake.split_pairs``' choices: the ARKit Left / Right pairs that are one motion mirrored on each side
#: (not ``jawLeft`` / ``jawRight``, ``mouthLeft`` / ``mouthRight``, the gaze: opposite motions), which
#: the bake may make from their bilateral pose (:mod:`faceforge.blendshapes.split`)
SPLITTABLE_PAIRS = ("browDown", "browOuterUp", "cheekSquint", "noseSneer", "mouthSmile", "mouthFrown", "mouthDimple",
                    "mouthStretch", "mouthPress", "mouthLowerDown", "mouthUpperUp", "eyeBlink", "eyeSquint", "eyeWide")

_DEFAULT_CACHE: dict[str, tuple[dict, dict[str, int], str]] = {}

#: (glob over the dotted key, rule); the first match wins, else the default's type decides
RULES: list[tuple[str, Rule]] = [
    ("fit.orientation", AxesPair()),
    ("fit.straighten_deg", Number(0.0, 45.0)),
    ("fit.open_mouth_warn", Number(0.0, 10.0)),       # 0 = off; past 45 the snapped axes are the other ones
    ("skin.carry", Choice(("muscles", "all", "none"))),
    ("skin.carry_radius_mm", Number(0.0, 50.0)),
    ("skin.lid_hold", Number(0.0, 1.0)),              # a stiffness
    ("skin.lid_hold_sink", Number(0.0, 1.0)),         # a share of the sinking followed
    ("skin.cheek_tether", Number(0.0, 1.0)),          # a stiffness: past 1 a projection overshoots
    ("skin.commissure_fold_deg", Number(0.0, 179.0)),  # degrees; 0 turns the lips' corner contact off
    ("skin.fold_deg", Number(0.0, 179.0)),  # degrees; 0 turns the skin's fold limit off
    ("skin.proxy_fold_limit", Boolean()),
    ("skin.lip_contact_mm", Number(0.0, 20.0)),  # mm; 0 turns the lips' one-sided contact off
    ("bake.split_pairs", ListOf(Choice(SPLITTABLE_PAIRS))),  # ARKit pair stems (mouthSmile); [] = off
    ("match.rigid", Boolean()),                       # `faceforge match --rigid`: the target's head motion removed first
    ("animate.arkit_rounds", Integer(0, 20)),          # 0: the ARKit take's weights played as given
    ("curves.ridge", Number(0.0, 1.0)),               # --curves' ridge (unitless): 0 = plain bounded least squares
    ("curves.smooth", Number(0.0, 100.0)),            # --curves' smoothness over frames (unitless): 0 = off
    ("muscle.damping", Number(0.0, 0.99)),
    ("animate.orientation_guard.rounds", Integer(0)),            # 0 turns the guard off
    ("animate.orientation_guard.min_area", Number(0.0, 0.95)),
    ("animate.orientation_guard.fold_progress", Boolean()),    # past its rounds only while the fold limit's work shrinks
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
    ("muscle.sphincter.closure_vertical", Number(0.0, 1.0)),
    ("muscle.sphincter.eversion_up", Boolean()),
    ("muscle.sphincter.bulge", Number(0.0)),
    ("muscle.sphincter.lip_ties.lower", ListOf(String())),          # []: off
    ("muscle.sphincter.lip_ties.upper", ListOf(String())),          # []: off
    ("muscle.sphincter.lip_ties.radius", Number(0.0, 1.0)),         # 0: off
    ("muscle.sphincter.lip_ties.ramp", Number(0.001, 1.0)),
    ("solver.stiffness_mode", Choice(("paper", "iteration_independent", "xpbd"))),
    ("solver.gravity", Number()),
    ("fit.rbf_kernel", Choice(("multiquadric", "inverse_multiquadric", "thin_plate_spline", "gaussian"))),
    ("bind.max_ray_distance", Number(0.0, 1.0)),
    ("bind.modiolus_radius", Number(0.0, 0.5)),
    ("bind.commissure_radius", Number(0.0, 0.5)),
    ("bind.vermilion_reach", Number(0.0, 5.0)),
    ("bind.vermilion_depth_mm", Number(0.0, 100.0)),               # 0: off (the red of the lips by its rays)
    ("bind.forehead_bone_mm", Number(0.0, 100.0)),                # 0: off (the forehead by its rays)
    ("bind.nose_on_bone", Boolean()),
    ("bind.ala_mm", Number(0.0, 30.0)),                           # 0: off (the ala by its rays)
    ("bind.ala_muscles", ListOf(String())),
    ("bind.normal_rounds", Integer(0, 50)),                       # 0: the vertex normals as they are
    ("fit.normal_rounds", Integer(0, 50)),
    ("fit.level_muscles", ListOf(String())),
    ("fit.simulation_vertices", OffOrInteger(300)),                # 0: never a proxy (under a few hundred the
                                                                   # decimated copy loses the landmarks' places)
    ("fit.simulation_borders", Boolean()),
    ("fit.simulation_lip_sides", Boolean()),
    ("fit.simulation_contour_lock", Boolean()),
    ("fit.simulation_lock_rings", Integer(0, 10)),
    ("fit.simulation_corner_lock", Number(0.0, 1.0)),
    ("fit.noisy_normal_rounds", Integer(0, 50)),                  # 0: a fit that fails its checks is not refitted
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
    ("animate.eyelid_relative", Boolean()),               # the lids' limit and guard held to the simulated frame
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
