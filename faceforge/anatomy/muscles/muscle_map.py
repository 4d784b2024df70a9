"""The muscle map YAML (§6.2, Fig. 6) -> validated :class:`MuscleSpec` list.

Format: docs/ARCHITECTURE.md ("The muscle-map YAML"). A point is ``[x, y, z]`` in
template (skull) space or ``{fdp: "2.10", offset: [dx, dy, dz]}`` relative to a skull
landmark. The loader resolves every point to 3D and projects it onto the skull at rest
(closest point on cranium + mandible), so contours always start on bone; when the muscle
is built, its action lines are projected again onto the bodies of ``lies_on``.

A right muscle may be written as ``{name: X_R, mirror_of: X_L}``: the left muscle's
resolved points mirrored in x (then projected), ``lies_on`` names with ``_L`` <-> ``_R``
swapped, every other field copied. ``lies_on`` may be overridden in the mirror entry.

Action lines of a spec (paper §5.1.2, :meth:`MuscleSpec.action_lines`):

* linear: ``A3`` = origin (latitudinal, fixed site), ``A1`` = insertion (latitudinal,
  moving site), ``A0`` = origin[0] -> fibre_a -> insertion[0] and ``A2`` = origin[-1] ->
  fibre_b -> insertion[-1] (longitudinal, the fibres, running origin -> insertion).
* sphincter: ``A1`` = inner loop, ``A3`` = outer loop (closed: first point not repeated),
  ``A0`` = ``A2`` = inner[0] -> outer[0].
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from faceforge.exceptions import TemplateError
from faceforge.io.stagefiles import yaml_safe_load

TYPES = ("linear", "sphincter")
COMMON_KEYS = {"name", "type", "layer", "lies_on", "active", "h", "w", "thickness"}
LINEAR_KEYS = COMMON_KEYS | {"origin", "insertion", "fibre_a", "fibre_b", "max_contraction"}
SPHINCTER_KEYS = COMMON_KEYS | {"inner", "outer"}
MIRROR_KEYS = {"name", "mirror_of", "lies_on"}
TOP_KEYS = {"units", "muscles"}
SKULL = "skull"
#: bone names ``lies_on`` accepts: the whole skull, or one of its two bodies
BONES = (SKULL, "cranium", "mandible")


#: the order of a spec's point fields in :meth:`MuscleSpec.points`
POINTS_ORDER = ("origin", "fibre_a", "fibre_b", "insertion", "inner", "outer")


@dataclass(frozen=True)
class MuscleSpec:
    """One muscle of the map, resolved to template space and projected onto the skull.

    Attributes
    ----------
    name : str
    type : "linear" | "sphincter"
    layer : int, 0 lies on the skull; layer n lies only on the skull or layers < n
    lies_on : tuple of str, "skull" (cranium + mandible), "cranium" or "mandible" alone,
        and/or names of deeper muscles
    active : bool, False for passive support tissue (contraction ignored)
    h, w : int >= 2, samples along the longitudinal / latitudinal action lines
    thickness : float, fraction of the skull's bounding-box diagonal
    origin, insertion : (k, 3) float64, k >= 2 (linear; empty (0, 3) for a sphincter)
    fibre_a, fibre_b : (k, 3) float64, intermediate fibre points, k >= 0 (linear)
    inner, outer : (k, 3) float64, k >= 3, closed loops (sphincter; empty for linear)
    mirror_of : name of the muscle this one mirrors, or None
    max_contraction : float or None, linear: the fibre shortening at c = 1 (``kappa`` of
        :mod:`faceforge.anatomy.muscles.linear`, in (0, 0.9)); None: the default
    """

    name: str
    type: str
    layer: int
    lies_on: tuple
    active: bool
    h: int
    w: int
    thickness: float
    origin: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    insertion: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    fibre_a: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    fibre_b: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    inner: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    outer: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    mirror_of: str | None = None
    max_contraction: float | None = None

    def action_lines(self) -> dict[str, np.ndarray]:
        """The four action lines A0..A3 as polylines {name: (k, 3)} (see module docstring)."""
        if self.type == "linear":
            return {"A0": np.vstack([self.origin[:1], self.fibre_a, self.insertion[:1]]),
                    "A1": self.insertion.copy(),
                    "A2": np.vstack([self.origin[-1:], self.fibre_b, self.insertion[-1:]]),
                    "A3": self.origin.copy()}
        cross = np.vstack([self.inner[:1], self.outer[:1]])
        return {"A0": cross, "A1": self.inner.copy(), "A2": cross.copy(), "A3": self.outer.copy()}

    def points(self) -> np.ndarray:
        """Every contour point, (k, 3)."""
        return np.vstack([getattr(self, k) for k in POINTS_ORDER])

    def with_points(self, points) -> "MuscleSpec":
        """This spec with its contour points taken from ``points (k, 3)`` in :meth:`points`
        order (the inverse of :meth:`points`; e.g. a fitted map's points)."""
        from dataclasses import replace

        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        ends = np.cumsum([0] + [len(getattr(self, k)) for k in POINTS_ORDER])
        if ends[-1] != len(p):
            raise ValueError(f"muscle {self.name}: {len(p)} points for a spec of {ends[-1]}")
        return replace(self, **{k: p[ends[i]:ends[i + 1]] for i, k in enumerate(POINTS_ORDER)})

    def absolute_thickness(self, diagonal: float) -> float:
        """Thickness in template units for a skull of bounding-box ``diagonal``."""
        return self.thickness * diagonal


def mirrored_name(name: str) -> str:
    """``X_L`` <-> ``X_R``; other names unchanged (midline muscles)."""
    if name.endswith("_L"):
        return name[:-2] + "_R"
    if name.endswith("_R"):
        return name[:-2] + "_L"
    return name


# -------------------------------------------------------------------------- projection
class SkullProjector:
    """Closest points on the rest skull (cranium + mandible); built once per skull."""

    def __init__(self, skull):
        from faceforge.geometry.surface_points import SurfaceProjector

        v, f, bone = skull.combined()
        self.projector = SurfaceProjector(v, f)
        self.face_bone = bone

    def __call__(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(projected (k, 3), bone (k,) int8: 0 cranium, 1 mandible) of points (k, 3)."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        if len(p) == 0:
            return p.copy(), np.zeros(0, np.int8)
        closest, _, tri = self.projector.closest(p)
        return closest, self.face_bone[tri]


# ------------------------------------------------------------------------------- loading
class _Ctx:
    """Error helper: the file and the muscle's line."""

    def __init__(self, path: Path):
        self.path = path

    def fail(self, msg: str, line: int | None = None, muscle: str | None = None):
        where = f"muscle {muscle}: " if muscle else ""
        raise TemplateError(where + msg, self.path, line)


def _lines_of_muscles(text: str) -> list[int | None]:
    """1-based start line of each item of ``muscles`` (None when not composable)."""
    try:
        root = yaml.compose(text)
        for key, value in root.value:
            if key.value == "muscles" and isinstance(value, yaml.SequenceNode):
                return [item.start_mark.line + 1 for item in value.value]
    except (yaml.YAMLError, AttributeError, TypeError):
        pass
    return []


def _resolve_point(item, skull, ctx: _Ctx, name: str, line) -> np.ndarray:
    if isinstance(item, dict):
        if set(item) - {"fdp", "offset"} or "fdp" not in item:
            ctx.fail(f"a landmark point needs keys fdp and offset, got {sorted(item)}", line, name)
        fdp = str(item["fdp"])
        if fdp not in skull.landmarks:
            ctx.fail(f"unknown FDP {fdp!r} (the skull has {len(skull.landmarks)} landmarks)", line, name)
        offset = _vec3(item.get("offset", [0.0, 0.0, 0.0]), ctx, name, line, "offset")
        return skull.landmarks[fdp] + offset
    return _vec3(item, ctx, name, line, "point")


def _vec3(value, ctx, name, line, what) -> np.ndarray:
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        a = np.zeros(0)
    if a.shape != (3,) or not np.isfinite(a).all():
        ctx.fail(f"{what}: expected [x, y, z] numbers, got {value!r}", line, name)
    return a


def _points(entry: dict, key: str, skull, ctx, name, line, minimum: int) -> np.ndarray:
    raw = entry.get(key, [])
    if not isinstance(raw, list):
        ctx.fail(f"{key}: expected a list of points", line, name)
    if len(raw) < minimum:
        ctx.fail(f"{key}: expected at least {minimum} points, got {len(raw)}", line, name)
    return np.array([_resolve_point(p, skull, ctx, name, line) for p in raw], dtype=np.float64).reshape(-1, 3)


def _int(entry, key, ctx, name, line, low) -> int:
    v = entry.get(key)
    if isinstance(v, bool) or not isinstance(v, int):
        ctx.fail(f"{key}: expected an integer, got {v!r}", line, name)
    if v < low:
        ctx.fail(f"{key} = {v}: must be >= {low}", line, name)
    return v


def _parse_muscle(entry, skull, ctx, line):
    """A non-mirror entry -> dict of fields (points resolved, not yet projected)."""
    name = entry.get("name")
    if not isinstance(name, str) or not name:
        ctx.fail("every muscle needs a name", line)
    kind = entry.get("type")
    if kind not in TYPES:
        ctx.fail(f"type must be one of {', '.join(TYPES)}, got {kind!r}", line, name)
    allowed = LINEAR_KEYS if kind == "linear" else SPHINCTER_KEYS
    unknown = sorted(set(entry) - allowed)
    if unknown:
        ctx.fail(f"unknown key(s) {', '.join(unknown)}; valid: {', '.join(sorted(allowed))}", line, name)
    for key in ("layer", "lies_on", "h", "w", "thickness"):
        if key not in entry:
            ctx.fail(f"missing key {key}", line, name)
    layer = _int(entry, "layer", ctx, name, line, 0)
    h = _int(entry, "h", ctx, name, line, 2)
    w = _int(entry, "w", ctx, name, line, 2)
    thickness = entry["thickness"]
    if isinstance(thickness, bool) or not isinstance(thickness, (int, float)) or not 0.0 < thickness < 0.2:
        ctx.fail(f"thickness: expected a fraction of the skull diagonal in (0, 0.2), got {thickness!r}", line, name)
    active = entry.get("active", True)
    if not isinstance(active, bool):
        ctx.fail(f"active: expected true or false, got {active!r}", line, name)
    lies_on = entry["lies_on"]
    if not isinstance(lies_on, list) or not lies_on or not all(isinstance(s, str) for s in lies_on):
        ctx.fail("lies_on: expected a non-empty list of names", line, name)
    fields = dict(name=name, type=kind, layer=layer, lies_on=tuple(lies_on), active=active, h=h, w=w,
                  thickness=float(thickness))
    if kind == "linear":
        fields["origin"] = _points(entry, "origin", skull, ctx, name, line, 2)
        fields["insertion"] = _points(entry, "insertion", skull, ctx, name, line, 2)
        fields["fibre_a"] = _points(entry, "fibre_a", skull, ctx, name, line, 0)
        fields["fibre_b"] = _points(entry, "fibre_b", skull, ctx, name, line, 0)
        kappa = entry.get("max_contraction")
        if kappa is not None:
            if isinstance(kappa, bool) or not isinstance(kappa, (int, float)) or not 0.0 < kappa < 0.9:
                ctx.fail(f"max_contraction: expected a fibre shortening in (0, 0.9), got {kappa!r}", line, name)
            fields["max_contraction"] = float(kappa)
    else:
        fields["inner"] = _points(entry, "inner", skull, ctx, name, line, 3)
        fields["outer"] = _points(entry, "outer", skull, ctx, name, line, 3)
    return fields


POINT_FIELDS = ("origin", "insertion", "fibre_a", "fibre_b", "inner", "outer")


def _mirror_fields(src: dict, entry: dict, ctx, line) -> dict:
    name = entry.get("name")
    if not isinstance(name, str) or not name:
        ctx.fail("every muscle needs a name", line)
    unknown = sorted(set(entry) - MIRROR_KEYS)
    if unknown:
        ctx.fail(f"unknown key(s) {', '.join(unknown)} in a mirror entry; valid: "
                 f"{', '.join(sorted(MIRROR_KEYS))}", line, name)
    out = dict(src)
    out["name"] = name
    out["mirror_of"] = src["name"]
    lies_on = entry.get("lies_on")
    if lies_on is None:
        out["lies_on"] = tuple(s if s == SKULL else mirrored_name(s) for s in src["lies_on"])
    elif not isinstance(lies_on, list) or not lies_on or not all(isinstance(s, str) for s in lies_on):
        ctx.fail("lies_on: expected a non-empty list of names", line, name)
    else:
        out["lies_on"] = tuple(lies_on)
    for key in POINT_FIELDS:
        if key in src:
            out[key] = src[key] * np.array([-1.0, 1.0, 1.0])
    return out


def load_muscle_map(path: str | Path, skull) -> list[MuscleSpec]:
    """Read, validate, resolve and project a muscle-map YAML; specs in file order.

    Raises TemplateError naming the file (and line) and the muscle for: unreadable YAML,
    unknown keys, a bad type, layer, h or w (< 2), thickness, a missing or unknown FDP, too
    few points, duplicate names, an unknown ``mirror_of`` or ``lies_on`` name, and a muscle
    lying on a muscle of the same or a shallower (higher) layer.
    """
    path = Path(path)
    ctx = _Ctx(path)
    if not path.is_file():
        ctx.fail("muscle map not found")
    text = path.read_text()
    try:
        doc = yaml_safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        ctx.fail(f"invalid YAML ({getattr(exc, 'problem', exc)})", None if mark is None else mark.line + 1)
    if not isinstance(doc, dict):
        ctx.fail("expected a mapping with keys units and muscles")
    unknown = sorted(set(doc) - TOP_KEYS)
    if unknown:
        ctx.fail(f"unknown top-level key(s) {', '.join(unknown)}; valid: {', '.join(sorted(TOP_KEYS))}")
    if doc.get("units", "template") != "template":
        ctx.fail(f"units must be 'template', got {doc.get('units')!r}")
    entries = doc.get("muscles")
    if not isinstance(entries, list) or not entries:
        ctx.fail("muscles: expected a non-empty list")
    lines = _lines_of_muscles(text)
    lines += [None] * (len(entries) - len(lines))

    resolved: dict[str, dict] = {}
    order: list[tuple[str, int | None]] = []
    for entry, line in zip(entries, lines):
        if not isinstance(entry, dict):
            ctx.fail("each muscle must be a mapping", line)
        if "mirror_of" in entry:
            src_name = entry["mirror_of"]
            if src_name not in resolved or resolved[src_name].get("mirror_of"):
                ctx.fail(f"mirror_of {src_name!r}: not a muscle defined above (mirrors of mirrors "
                         "are not allowed)", line, entry.get("name"))
            fields = _mirror_fields(resolved[src_name], entry, ctx, line)
        else:
            fields = _parse_muscle(entry, skull, ctx, line)
            fields["mirror_of"] = None
        if fields["name"] in resolved:
            ctx.fail("duplicate muscle name", line, fields["name"])
        resolved[fields["name"]] = fields
        order.append((fields["name"], line))

    for name, line in order:
        f = resolved[name]
        if len(set(f["lies_on"])) != len(f["lies_on"]):
            ctx.fail("lies_on lists a name twice", line, name)
        for under in f["lies_on"]:
            if under in BONES:
                continue
            if under == name:
                ctx.fail("a muscle cannot lie on itself", line, name)
            if under not in resolved:
                ctx.fail(f"lies_on {under!r}: no such muscle (valid: skull, cranium, mandible or a muscle name)", line, name)
            if resolved[under]["layer"] >= f["layer"]:
                ctx.fail(f"lies on {under} (layer {resolved[under]['layer']}), which is not deeper than "
                         f"its own layer {f['layer']}", line, name)

    project = SkullProjector(skull)
    specs = []
    for name, _ in order:
        f = dict(resolved[name])
        for key in POINT_FIELDS:
            if key in f:
                f[key] = project(f[key])[0]
        specs.append(MuscleSpec(**f))
    return specs


def layers(specs: list[MuscleSpec]) -> dict[int, list[str]]:
    """{layer: [muscle names]} in ascending layer order."""
    out: dict[int, list[str]] = {}
    for s in sorted(specs, key=lambda s: s.layer):
        out.setdefault(s.layer, []).append(s.name)
    return out
