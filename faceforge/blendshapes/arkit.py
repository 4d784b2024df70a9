"""The ARKit-52 blendshape names and the ARKit -> pose mapping template
(``templates/arkit_mapping.yaml``).

ARKit's ``Left``/``Right`` are the subject's own sides (``eyeBlinkLeft`` closes the subject's left
eye), the same as faceforge's ``_L``/``_R`` (+X is the subject's left).

A mapping entry says how one shape is made on a head:

``faps: {FAP: value}``
    the target: landmark motions in FAPU (each FAP's FDP along the FAP's direction, as
    ``calibrate`` measures it); the activation solve finds the pose that reaches them;
``controls: [name, ...]``
    the muscles (``head.controls`` names) and jaw DOFs (``jaw.pitch``, ``jaw.yaw``,
    ``jaw.protrusion``) the solve may use (FACS: the muscles of the shape's action units);
``lids: {FAP: IRISD}``
    eyelid FAPs 19-22, laid over the settled skin kinematically (:mod:`faceforge.animation.eyelids`);
``eye: {side: L|R, yaw: deg, pitch: deg}``
    turn that eye's eyeball piece (yaw towards +X, the subject's left; pitch up) when the mesh
    has one (:mod:`faceforge.animation.eyeballs`); without one, a shape that also has ``lids``
    is those lids alone (reported as an approximation), any other is not made;
``mirror: otherShape``
    this shape is ``otherShape`` with left and right swapped (FAPs, controls, lids);
``approximation: why``
    the shape is made but is not what ARKit's shape is (said in the report);
``not_made: why``
    the anatomy cannot make it (no eyeballs, no tongue, no air pressure): the bake leaves it
    out and says so, never fakes it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

#: the 52 ARKit blendshape names, in Apple's ``ARFaceAnchor.BlendShapeLocation`` documentation order
ARKIT_NAMES = (
    "eyeBlinkLeft", "eyeLookDownLeft", "eyeLookInLeft", "eyeLookOutLeft", "eyeLookUpLeft",
    "eyeSquintLeft", "eyeWideLeft",
    "eyeBlinkRight", "eyeLookDownRight", "eyeLookInRight", "eyeLookOutRight", "eyeLookUpRight",
    "eyeSquintRight", "eyeWideRight",
    "jawForward", "jawLeft", "jawRight", "jawOpen",
    "mouthClose", "mouthFunnel", "mouthPucker", "mouthLeft", "mouthRight",
    "mouthSmileLeft", "mouthSmileRight", "mouthFrownLeft", "mouthFrownRight",
    "mouthDimpleLeft", "mouthDimpleRight", "mouthStretchLeft", "mouthStretchRight",
    "mouthRollLower", "mouthRollUpper", "mouthShrugLower", "mouthShrugUpper",
    "mouthPressLeft", "mouthPressRight", "mouthLowerDownLeft", "mouthLowerDownRight",
    "mouthUpperUpLeft", "mouthUpperUpRight",
    "browDownLeft", "browDownRight", "browInnerUp", "browOuterUpLeft", "browOuterUpRight",
    "cheekPuff", "cheekSquintLeft", "cheekSquintRight",
    "noseSneerLeft", "noseSneerRight",
    "tongueOut",
)

#: FAP pairs (left, right) swapped by a mirror; FAP 15 (shift_jaw) changes sign
_FAP_PAIRS = ((6, 7), (8, 9), (10, 11), (12, 13), (19, 20), (21, 22), (23, 24), (25, 26), (27, 28),
              (29, 30), (31, 32), (33, 34), (35, 36), (37, 38), (39, 40), (41, 42), (53, 54), (55, 56),
              (57, 58), (59, 60), (61, 62), (65, 66), (67, 68))
_FAP_MIRROR = {a: b for a, b in _FAP_PAIRS} | {b: a for a, b in _FAP_PAIRS}
_NEGATED = (15,)
_JAW = ("jaw.pitch", "jaw.yaw", "jaw.protrusion")


def mirror_fap(fap: int, value: float) -> tuple[int, float]:
    """The FAP and value that move the other side the same way."""
    return _FAP_MIRROR.get(fap, fap), (-value if fap in _NEGATED else value)


def mirror_name(name: str) -> str:
    """``zygomaticus_major_L`` <-> ``zygomaticus_major_R``; ``eyeBlinkLeft`` <-> ``eyeBlinkRight``;
    names without a side unchanged."""
    for a, b in (("_L", "_R"), ("Left", "Right")):
        if name.endswith(a):
            return name[: -len(a)] + b
        if name.endswith(b):
            return name[: -len(b)] + a
    return name


@dataclass(frozen=True)
class ShapeSpec:
    """One shape of the mapping (module docstring); ``mirror_of`` names the shape this one
    mirrors (its faps, controls and lids already swapped here)."""

    name: str
    faps: dict = field(default_factory=dict)
    controls: tuple = ()
    lids: dict = field(default_factory=dict)
    eye: dict = field(default_factory=dict)
    approximation: str = ""
    not_made: str = ""
    mirror_of: str = ""

    @property
    def made(self) -> bool:
        return not self.not_made


def _err(source, msg):
    from faceforge.exceptions import TemplateError

    return TemplateError(f"{msg}", source)


def load_arkit_mapping(path: str | Path, names=ARKIT_NAMES) -> dict:
    """Read a mapping template -> ``{shape name: ShapeSpec}`` in ``names`` order; every name in
    ``names`` must have an entry (made, mirrored or ``not_made``), an unknown name is an error.
    Errors are :class:`faceforge.exceptions.TemplateError` naming the file and the entry."""
    from faceforge.exceptions import TemplateError
    from faceforge.io.safe_yaml import load_user_yaml

    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise TemplateError(f"cannot read the ARKit mapping: {exc}".splitlines()[0], path) from None
    data = load_user_yaml(text, str(path), TemplateError)   # a user's --mapping: limits, one-line errors
    shapes = (data or {}).get("shapes") if isinstance(data, dict) else None
    if not isinstance(shapes, dict):
        raise _err(path, "expected a 'shapes:' table")
    unknown = [n for n in shapes if n not in names]
    if unknown:
        raise _err(path, f"shapes: unknown name {unknown[0]!r} (ARKit's 52 names are case-sensitive)")
    missing = [n for n in names if n not in shapes]
    if missing:
        more = f" and {len(missing) - 3} more" if len(missing) > 3 else ""
        raise _err(path, f"shapes: no entry for {', '.join(missing[:3])}{more} (every ARKit name needs one, "
                         "`not_made: why` for a shape the head cannot make)")
    raw = {n: _entry(path, n, shapes[n]) for n in names}
    out = {}
    for n in names:
        spec = raw[n]
        if spec.mirror_of:
            src = raw.get(spec.mirror_of)
            if src is None or src.mirror_of:
                raise _err(path, f"shapes.{n}.mirror: {spec.mirror_of!r} is not a shape made directly")
            eye = ({"side": "R" if src.eye["side"] == "L" else "L", "yaw": -src.eye["yaw"],
                    "pitch": src.eye["pitch"]} if src.eye else {})
            spec = ShapeSpec(n, dict(mirror_fap(f, v) for f, v in src.faps.items()),
                             tuple(mirror_name(c) for c in src.controls),
                             dict(mirror_fap(f, v) for f, v in src.lids.items()), eye,
                             src.approximation, src.not_made, src.name)
        out[n] = spec
    return out


def _entry(path, name, raw) -> ShapeSpec:
    if not isinstance(raw, dict):
        raise _err(path, f"shapes.{name}: expected a mapping")
    allowed = {"faps", "controls", "lids", "eye", "mirror", "approximation", "not_made"}
    extra = sorted(set(raw) - allowed)
    if extra:
        raise _err(path, f"shapes.{name}: unknown key {extra[0]!r} (valid: {', '.join(sorted(allowed))})")
    if "mirror" in raw:
        return ShapeSpec(name, mirror_of=str(raw["mirror"]))

    def fap_table(key, lo=1, hi=68):
        table = raw.get(key) or {}
        if not isinstance(table, dict):
            raise _err(path, f"shapes.{name}.{key}: expected {{FAP: value}}")
        out = {}
        for k, v in table.items():
            try:
                fap, val = int(k), float(v)
            except (TypeError, ValueError):
                raise _err(path, f"shapes.{name}.{key}: {k}: {v} is not FAP: number") from None
            if not lo <= fap <= hi:
                raise _err(path, f"shapes.{name}.{key}: FAP {fap} outside {lo}-{hi}")
            out[fap] = val
        return out

    faps = fap_table("faps")
    lids = fap_table("lids", 19, 22)
    controls = tuple(str(c) for c in (raw.get("controls") or ()))
    not_made = str(raw.get("not_made") or "")
    eye = _eye(path, name, raw.get("eye"))
    if not not_made and not (faps and controls) and not lids and not eye:
        raise _err(path, f"shapes.{name}: needs faps + controls, lids, eye, mirror or not_made")
    if faps and not controls:
        raise _err(path, f"shapes.{name}: faps without controls")
    return ShapeSpec(name, faps, controls, lids, eye, str(raw.get("approximation") or ""), not_made)


def _eye(path, name, raw) -> dict:
    """``eye: {side: L|R, yaw: deg, pitch: deg}`` -> {"side", "yaw" rad, "pitch" rad} or {}."""
    import math

    if raw is None:
        return {}
    if not isinstance(raw, dict) or str(raw.get("side")) not in ("L", "R") or set(raw) - {"side", "yaw", "pitch"}:
        raise _err(path, f"shapes.{name}.eye: expected {{side: L|R, yaw: degrees, pitch: degrees}}")
    try:
        return {"side": str(raw["side"]), "yaw": math.radians(float(raw.get("yaw", 0.0))),
                "pitch": math.radians(float(raw.get("pitch", 0.0)))}
    except (TypeError, ValueError):
        raise _err(path, f"shapes.{name}.eye: yaw and pitch are degrees") from None


def default_mapping_path() -> Path:
    """``templates/arkit_mapping.yaml`` of the repository (or the installed package's copy)."""
    here = Path(__file__).resolve()
    for root in (here.parents[2], here.parents[1]):
        p = root / "templates" / "arkit_mapping.yaml"
        if p.is_file():
            return p
    return here.parents[2] / "templates" / "arkit_mapping.yaml"
