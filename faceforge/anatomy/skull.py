"""The template skull: cranium + mandible, FDP landmarks on the bone, a 3-DOF jaw (§6.1).

A skull folder (``templates/skull/``) holds ``cranium.obj``, ``mandible.obj``,
``landmarks.yaml`` (``{fdp: {position: [x, y, z], bone: cranium|mandible}}``) and
``jaw.yaml`` (pitch axis through the condyles, yaw axis, protrusion direction, limits).
:func:`load_skull` reads and validates them into a :class:`Skull`.

The jaw has exactly three degrees of freedom, applied to the mandible as one rigid
transform (:func:`jaw_transform`): a rotation by ``pitch`` (rad, positive opens the
mouth) about the pitch axis, then a rotation by ``yaw`` (rad, positive turns the chin
towards the subject's left, +X) about the yaw axis, then a translation by
``protrusion`` (template units, positive forward) along the protrusion direction.
Landmarks on the mandible follow the jaw (:func:`posed_landmarks`); cranium landmarks
never move.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from faceforge.exceptions import TemplateError
from faceforge.io.stagefiles import yaml_safe_load

BONES = ("cranium", "mandible")


@dataclass(frozen=True)
class JawAxes:
    """The jaw frame (template units).

    pitch_point, yaw_point : (3,) float, a point on each rotation axis
    pitch_dir, yaw_dir, protrusion_dir : (3,) float, unit vectors
    limits : {"pitch": (lo, hi) rad, "yaw": (lo, hi) rad, "protrusion": (lo, hi) units}
    condyles : (2, 3) float, left and right condyle points (on the pitch axis)
    glide : (3,) float or None, the condyles' glide down the articular eminence per radian of
        opening (units per rad; :func:`condylar_glide`): a real jaw opens by turning about the
        condyles while they slide forward and down, so the chin drops rather than swings back
    """

    pitch_point: np.ndarray
    pitch_dir: np.ndarray
    yaw_point: np.ndarray
    yaw_dir: np.ndarray
    protrusion_dir: np.ndarray
    limits: dict
    condyles: np.ndarray
    glide: np.ndarray | None = None

    def clamp(self, pitch: float, yaw: float, protrusion: float) -> tuple[float, float, float]:
        """The pose with each DOF clipped to its limits."""
        lim = self.limits
        return (float(np.clip(pitch, *lim["pitch"])), float(np.clip(yaw, *lim["yaw"])),
                float(np.clip(protrusion, *lim["protrusion"])))


@dataclass
class Skull:
    """Cranium and mandible meshes, FDP landmarks on them, and the jaw frame.

    cranium, mandible : (vertices (n, 3) float64, faces (m, 3) int64)
    landmarks : {fdp id: (3,) float64} at rest
    bones : {fdp id: "cranium" | "mandible"}
    jaw : JawAxes
    folder : where it was loaded from (None when built in memory)
    """

    cranium: tuple[np.ndarray, np.ndarray]
    mandible: tuple[np.ndarray, np.ndarray]
    landmarks: dict[str, np.ndarray]
    bones: dict[str, str]
    jaw: JawAxes
    folder: Path | None = None
    units: str = "cm"
    _diagonal: float | None = field(default=None, repr=False)

    @property
    def diagonal(self) -> float:
        """Length of the bounding-box diagonal of cranium + mandible (template units)."""
        if self._diagonal is None:
            v = np.concatenate([self.cranium[0], self.mandible[0]])
            self._diagonal = float(np.linalg.norm(v.max(0) - v.min(0)))
        return self._diagonal

    def jaw_transform(self, pitch: float = 0.0, yaw: float = 0.0, protrusion: float = 0.0) -> np.ndarray:
        """(4, 4) rigid transform of the mandible; see :func:`jaw_transform`."""
        return jaw_transform(self, pitch, yaw, protrusion)

    def combined(self, pitch: float = 0.0, yaw: float = 0.0, protrusion: float = 0.0):
        """One mesh of both bones at a jaw pose.

        Returns (vertices (n, 3), faces (m, 3), face_bone (m,) int8: 0 cranium, 1 mandible).
        """
        cv, cf = self.cranium
        mv = posed_mandible(self, pitch, yaw, protrusion)
        mf = self.mandible[1]
        v = np.concatenate([cv, mv])
        f = np.concatenate([cf, mf + len(cv)])
        bone = np.concatenate([np.zeros(len(cf), np.int8), np.ones(len(mf), np.int8)])
        return v, f, bone


# ---------------------------------------------------------------------------- rigid math
def _rigid_about_axis(point, direction, angle: float):
    """Rotation by ``angle`` (rad, right-handed) about the line point + t*direction as Python
    floats: (rows of R, translation). A 3 x 3 numpy product costs several times this math."""
    dx, dy, dz = np.asarray(direction, dtype=np.float64).tolist()
    n = math.sqrt(dx * dx + dy * dy + dz * dz)
    dx, dy, dz = dx / n, dy / n, dz / n
    c, s = math.cos(angle), math.sin(angle)
    v = 1.0 - c  # Rodrigues: R = c I + s [d]x + (1 - c) d d^T
    r = ((c + v * dx * dx, v * dx * dy - s * dz, v * dx * dz + s * dy),
         (v * dy * dx + s * dz, c + v * dy * dy, v * dy * dz - s * dx),
         (v * dz * dx - s * dy, v * dz * dy + s * dx, c + v * dz * dz))
    px, py, pz = np.asarray(point, dtype=np.float64).tolist()
    return r, tuple(p - (a * px + b * py + c * pz) for p, (a, b, c) in zip((px, py, pz), r))


def _compose(a, b):
    """``a @ b`` of two (rows, translation) rigid maps in Python floats."""
    (ra, ta), (rb, tb) = a, b
    cols = tuple(zip(*rb))
    r = tuple(tuple(x * u + y * v + z * w for u, v, w in cols) for x, y, z in ra)
    t = tuple(x * tb[0] + y * tb[1] + z * tb[2] + s for (x, y, z), s in zip(ra, ta))
    return r, t


def _matrix(rigid) -> np.ndarray:
    r, t = rigid
    return np.array([[*r[0], t[0]], [*r[1], t[1]], [*r[2], t[2]], [0.0, 0.0, 0.0, 1.0]])


def rotation_about_axis(point: np.ndarray, direction: np.ndarray, angle: float) -> np.ndarray:
    """(4, 4) rotation by ``angle`` (rad, right-handed) about the line point + t*direction."""
    return _matrix(_rigid_about_axis(point, direction, float(angle)))


def jaw_transform(skull: Skull, pitch: float, yaw: float, protrusion: float) -> np.ndarray:
    """(4, 4) float64 rigid transform of the mandible for a jaw pose (three DOFs, §6.1).

    ``T = translate(protrusion * protrusion_dir + max(pitch, 0) * glide) @ R(yaw_axis, yaw)
    @ R(pitch_axis, pitch)``. pitch, yaw in radians; protrusion in template units; ``glide``
    (JawAxes.glide, absent: none) is the condyles' slide as the mouth opens. The zero pose is
    the identity.
    """
    j = skull.jaw
    r, t = _compose(_rigid_about_axis(j.yaw_point, j.yaw_dir, float(yaw)),
                    _rigid_about_axis(j.pitch_point, j.pitch_dir, float(pitch)))
    shift = float(protrusion) * np.asarray(j.protrusion_dir, dtype=np.float64)
    if j.glide is not None and pitch > 0.0:
        shift = shift + float(pitch) * np.asarray(j.glide, dtype=np.float64)
    shift = shift.tolist()
    return _matrix((r, tuple(a + b for a, b in zip(t, shift))))


def condylar_glide(protrusion_dir, pitch_dir, lever: float, ratio: float, slope_deg: float) -> np.ndarray:
    """(3,) glide of the condyles per radian of opening (:attr:`JawAxes.glide`).

    The condyles slide ``ratio * lever`` per radian (``lever``: condyle axis to chin, units;
    ``ratio`` 0.5: half the chin's arc, about what a real jaw's condyles travel, 15-20 mm for a
    50 mm opening) along the occlusal plane's forward direction ``protrusion_dir (3,)`` turned
    ``slope_deg`` downwards about ``pitch_dir (3,)`` (the articular eminence's slope).
    """
    f = np.asarray(protrusion_dir, dtype=np.float64)
    f = f / np.linalg.norm(f)
    a = np.asarray(pitch_dir, dtype=np.float64)
    a = a / np.linalg.norm(a)
    down = np.cross(a, f)                     # pitch_dir = subject's left, f forward -> down
    t = np.radians(float(slope_deg))
    return float(ratio) * float(lever) * (np.cos(t) * f + np.sin(t) * down)


def chin_path_ratio(chin, pitch_point, pitch_dir, protrusion_dir, slope_deg: float, back_per_down: float,
                    opening_deg: float = 10.0) -> float:
    """The glide fraction (``ratio`` of :func:`condylar_glide`) at which ``chin`` (3,), carried by
    the mandible, goes back ``back_per_down`` times as far as it drops at ``opening_deg`` of opening.

    Head frame: +Y up, +Z forward. The chin's displacement is affine in the glide fraction
    (``d0 + ratio * d1``: the turn about the pitch axis plus the condyles' slide), so the
    fraction is solved in closed form; clipped to [0, 2] (``animate.jaw_glide``'s range). The
    same fraction makes different paths on heads whose chin sits differently below the condyles
    (a longer chin swings back more): this gives every head the same path.
    """
    c = np.asarray(chin, dtype=np.float64)
    lever = float(np.linalg.norm(np.cross(c - pitch_point, np.asarray(pitch_dir) / np.linalg.norm(pitch_dir))))
    theta = np.radians(float(opening_deg))
    d0 = apply_transform(rotation_about_axis(np.asarray(pitch_point, float), np.asarray(pitch_dir, float), theta),
                         c[None])[0] - c
    d1 = theta * condylar_glide(protrusion_dir, pitch_dir, lever, 1.0, slope_deg)
    k = float(back_per_down)
    # back - k * down = -(d0 + r d1)_z + k (d0 + r d1)_y = 0
    den = d1[2] - k * d1[1]
    if abs(den) < 1e-12 * max(lever, 1e-12):
        return 0.0
    return float(np.clip((k * d0[1] - d0[2]) / den, 0.0, 2.0))


def apply_transform(transform: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Points (n, 3) mapped by a (4, 4) affine transform."""
    p = np.asarray(points, dtype=np.float64)
    return p @ transform[:3, :3].T + transform[:3, 3]


def posed_mandible(skull: Skull, pitch: float = 0.0, yaw: float = 0.0, protrusion: float = 0.0) -> np.ndarray:
    """(n, 3) mandible vertices at a jaw pose."""
    return apply_transform(jaw_transform(skull, pitch, yaw, protrusion), skull.mandible[0])


def posed_landmarks(skull: Skull, pitch: float = 0.0, yaw: float = 0.0,
                    protrusion: float = 0.0) -> dict[str, np.ndarray]:
    """{fdp: (3,)} at a jaw pose: mandible landmarks follow the jaw, cranium ones stay."""
    t = jaw_transform(skull, pitch, yaw, protrusion)
    return {k: (apply_transform(t, p[None])[0] if skull.bones[k] == "mandible" else p.copy())
            for k, p in skull.landmarks.items()}


# ------------------------------------------------------------------------------- loading
def _read_obj(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and triangles of an OBJ file (polygons fan-triangulated)."""
    if not path.is_file():
        raise TemplateError("missing skull mesh", path)
    verts, faces = [], []
    try:
        with path.open() as fh:
            for line in fh:
                if line.startswith("v "):
                    verts.append([float(x) for x in line.split()[1:4]])
                elif line.startswith("f "):
                    ids = [int(tok.split("/")[0]) for tok in line.split()[1:]]
                    ids = [i - 1 if i > 0 else len(verts) + i for i in ids]
                    faces.extend([ids[0], ids[k], ids[k + 1]] for k in range(1, len(ids) - 1))
    except (ValueError, IndexError) as exc:
        raise TemplateError(f"unreadable OBJ ({exc})", path) from None
    v = np.asarray(verts, dtype=np.float64).reshape(-1, 3)
    f = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    if len(v) == 0 or len(f) == 0:
        raise TemplateError("mesh has no vertices or no faces", path)
    if f.min() < 0 or f.max() >= len(v):
        raise TemplateError(f"face index out of range 0..{len(v) - 1}", path)
    if not np.isfinite(v).all():
        raise TemplateError("non-finite vertex coordinates", path)
    return v, f


def _read_yaml(path: Path) -> dict:
    if not path.is_file():
        raise TemplateError("missing file", path)
    try:
        doc = yaml_safe_load(path.read_text())
    except yaml.YAMLError as exc:
        line = getattr(getattr(exc, "problem_mark", None), "line", None)
        raise TemplateError(f"invalid YAML ({getattr(exc, 'problem', exc)})", path,
                            None if line is None else line + 1) from None
    if not isinstance(doc, dict):
        raise TemplateError("expected a mapping at the top level", path)
    return doc


def _vec3(value, path: Path, what: str, unit: bool = False) -> np.ndarray:
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        a = np.zeros(0)
    if a.shape != (3,) or not np.isfinite(a).all():
        raise TemplateError(f"{what}: expected 3 finite numbers, got {value!r}", path)
    if unit:
        n = np.linalg.norm(a)
        if n < 1e-12:
            raise TemplateError(f"{what}: zero direction", path)
        a = a / n
    return a


def read_landmarks(path: Path) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    """({fdp: position (3,)}, {fdp: bone}) from a skull ``landmarks.yaml``."""
    doc = _read_yaml(path)
    marks = doc.get("landmarks")
    if not isinstance(marks, dict) or not marks:
        raise TemplateError("expected a non-empty 'landmarks' mapping", path)
    pos, bones = {}, {}
    for key, entry in marks.items():
        k = str(key)
        if not isinstance(entry, dict) or set(entry) != {"position", "bone"}:
            raise TemplateError(f"landmark {k}: expected keys position and bone", path)
        if entry["bone"] not in BONES:
            raise TemplateError(f"landmark {k}: bone must be cranium or mandible, got {entry['bone']!r}", path)
        pos[k] = _vec3(entry["position"], path, f"landmark {k} position")
        bones[k] = entry["bone"]
    return pos, bones


def read_jaw(path: Path) -> JawAxes:
    """The :class:`JawAxes` of a skull ``jaw.yaml``."""
    doc = _read_yaml(path)
    try:
        pa, ya, pr, lim = doc["pitch_axis"], doc["yaw_axis"], doc["protrusion"], doc["limits"]
        cond = doc["condyles"]
        limits = {}
        for k in ("pitch", "yaw", "protrusion"):
            lo, hi = (float(x) for x in lim[k])
            if not lo <= 0.0 <= hi:
                raise TemplateError(f"limits.{k}: expected lo <= 0 <= hi, got [{lo}, {hi}]", path)
            limits[k] = (lo, hi)
        axes = JawAxes(
            pitch_point=_vec3(pa["point"], path, "pitch_axis.point"),
            pitch_dir=_vec3(pa["direction"], path, "pitch_axis.direction", unit=True),
            yaw_point=_vec3(ya["point"], path, "yaw_axis.point"),
            yaw_dir=_vec3(ya["direction"], path, "yaw_axis.direction", unit=True),
            protrusion_dir=_vec3(pr["direction"], path, "protrusion.direction", unit=True),
            limits=limits,
            condyles=np.stack([_vec3(cond["left"], path, "condyles.left"),
                               _vec3(cond["right"], path, "condyles.right")]),
        )
    except (KeyError, TypeError) as exc:
        raise TemplateError(f"missing or malformed key {exc}", path) from None
    except ValueError as exc:
        raise TemplateError(f"malformed limits ({exc})", path) from None
    return axes


def load_skull(folder: str | Path) -> Skull:
    """Read and validate a skull folder (see module docstring) into a :class:`Skull`.

    Raises TemplateError (naming the file) on a missing or malformed file, a landmark far
    from its bone (more than 1e-3 of the skull diagonal) or a pitch axis not through the
    condyles.
    """
    folder = Path(folder)
    cranium = _read_obj(folder / "cranium.obj")
    mandible = _read_obj(folder / "mandible.obj")
    landmarks, bones = read_landmarks(folder / "landmarks.yaml")
    jaw = read_jaw(folder / "jaw.yaml")
    jaw_path = folder / "jaw.yaml"
    doc = _read_yaml(jaw_path)
    skull = Skull(cranium, mandible, landmarks, bones, jaw, folder, str(doc.get("units", "cm")))
    tol = 1e-3 * skull.diagonal
    for c in jaw.condyles:
        off = c - jaw.pitch_point
        if np.linalg.norm(off - (off @ jaw.pitch_dir) * jaw.pitch_dir) > tol:
            raise TemplateError("a condyle does not lie on the pitch axis", jaw_path)
    _check_on_bone(skull, folder / "landmarks.yaml", tol)
    return skull


def _check_on_bone(skull: Skull, path: Path, tol: float) -> None:
    from faceforge.geometry.surface_points import closest_points

    for bone in BONES:
        keys = [k for k, b in skull.bones.items() if b == bone]
        if not keys:
            continue
        v, f = getattr(skull, bone)
        _, dist, _ = closest_points(np.array([skull.landmarks[k] for k in keys]), v, f)
        bad = np.flatnonzero(dist > tol)
        if len(bad):
            k = keys[bad[0]]
            raise TemplateError(f"landmark {k} lies {dist[bad[0]]:.4g} from the {bone} surface", path)
