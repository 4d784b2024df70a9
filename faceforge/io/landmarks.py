"""MPEG-4 FDP landmark files: reading, snapping to the skin, validation.

A landmark file maps MPEG-4 Facial Definition Point ids (``"3.7"``) to a vertex id
of the skin mesh and/or a 3D position. Three formats are read:

* YAML (``.yaml``/``.yml``), as the sample heads' ``*.fdp.yaml``::

      landmarks:
        "2.1": {vertex: 1575, position: [0.0, 6.32, 1.37]}
        "3.5": {vertex: null, position: [0.30, 7.34, 1.34]}

  (a top-level mapping without the ``landmarks:`` key is accepted too);
* JSON (``.json``) with the same structure;
* CSV (``.csv``) with a header ``fdp,vertex,x,y,z`` (empty vertex or xyz allowed).

:func:`load_landmarks` reads, snaps every point onto the skin surface (a given vertex
id wins when its vertex agrees with the given position) and validates: duplicated
and unknown FDP ids, required FDPs missing, vertex ids out of range, positions far
from the mesh, coincident landmarks, left and right swapped and a head facing the
wrong way. Every failure is a :class:`~faceforge.exceptions.LandmarkError` naming the
file and the FDPs.

Conventions (docs/ARCHITECTURE.md): +Y up, the face looks along +Z, the subject's
left is +X. Thresholds are fractions of the mesh's bounding-box diagonal.
"""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import yaml

from faceforge.exceptions import LandmarkError
from faceforge.mpeg4.tables import FDP_IDS, LEFT_RIGHT_PAIRS
from faceforge.io.safe_yaml import add_yaml12_floats, check_structure, construct_guarded

#: FDPs every skin must provide. The fit needs the face's frame and extent: the eye
#: corners (width, ES0 fallback, left/right check), the brows (forehead), the nose
#: tip and base (facing check, mid-face), the mouth corners and the chin. Ears,
#: hairline and jaw angles are optional, so an open face mask (MediaPipe) still fits.
REQUIRED_FDPS = ("2.1", "3.7", "3.8", "3.11", "3.12", "4.3", "4.4", "8.3", "8.4", "9.3", "9.15")

#: inner-lip FDPs that legitimately coincide on a closed mouth
_MAY_COINCIDE = {frozenset(p) for p in (("2.2", "2.3"), ("2.6", "2.8"), ("2.7", "2.9"))}

#: a given vertex and a given position disagree beyond this fraction of the diagonal
VERTEX_POSITION_TOLERANCE = 0.005
#: a position farther than this fraction of the diagonal from the surface is an error
MAX_SNAP_DISTANCE = 0.05
#: two different FDPs closer than this fraction of the diagonal coincide
COINCIDENT_DISTANCE = 1e-4


@dataclass(frozen=True)
class RawLandmarks:
    """Landmarks as read from a file, before meeting the mesh.

    ids : tuple of n FDP ids (str, e.g. ``"3.7"``), file order
    vertex : (n,) int64, vertex id or -1 where none was given
    position : (n, 3) float64, given position or NaN where none was given (mesh units)
    orientation : ``(up (3,), forward (3,))`` unit axes of the mesh as the file declares
        them (``orientation: {up: +Z, forward: -Y}``), or None
    """

    path: str
    ids: tuple
    vertex: np.ndarray
    position: np.ndarray
    orientation: tuple | None = None


@dataclass(frozen=True)
class Landmarks:
    """Validated landmarks lying on the skin surface.

    ids : tuple of n FDP ids
    positions : (n, 3) float64, points on the skin surface (mesh units)
    face_ids : (n,) int64, skin triangle holding each point
    bary : (n, 3) float64, barycentric coordinates in that triangle
    vertex : (n,) int64, the vertex used or -1 (position snapped to the surface)
    snap_distance : (n,) float64, distance moved by snapping (mesh units)
    """

    path: str
    ids: tuple
    positions: np.ndarray
    face_ids: np.ndarray
    bary: np.ndarray
    vertex: np.ndarray
    snap_distance: np.ndarray

    def as_dict(self) -> dict:
        """``{fdp: (3,) float64}``."""
        return {k: self.positions[i].copy() for i, k in enumerate(self.ids)}

    def index(self, fdp: str) -> int:
        return self.ids.index(fdp)


def default_landmark_path(mesh_path: str | Path) -> Path:
    """``<mesh stem>.fdp.yaml`` next to the mesh."""
    mesh_path = Path(mesh_path)
    return mesh_path.with_name(mesh_path.stem + ".fdp.yaml")


# ----------------------------------------------------------------------------- reading


class _UniqueKeyLoader(yaml.SafeLoader):
    """SafeLoader that refuses duplicated mapping keys (PyYAML keeps the last); YAML 1.2 floats."""


def _construct_unique_mapping(loader, node, deep=False):
    seen = {}
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=deep)
        if not isinstance(key, (str, int, float, bool)) and key is not None:
            raise LandmarkError(f"a key must be an FDP id or a name, got {type(key).__name__}",
                                loader.name, key_node.start_mark.line + 1)
        if key in seen:
            raise LandmarkError(
                f"FDP {key} given twice (lines {seen[key] + 1} and {key_node.start_mark.line + 1})",
                loader.name, key_node.start_mark.line + 1)
        seen[key] = key_node.start_mark.line
    return loader.construct_mapping(node, deep=deep)


_UniqueKeyLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG,
                                 _construct_unique_mapping)
add_yaml12_floats(_UniqueKeyLoader)


#: a vertex id at or above this is refused before it meets a mesh (int64 and beyond)
MAX_VERTEX_ID = 2 ** 40


def _json_int(text: str) -> int:
    """JSON integers of at most 100 digits (Python refuses 4,300 with a ValueError)."""
    if len(text.lstrip("-")) > 100:
        raise ValueError(f"number with more than 100 digits: {text[:20]}...")
    return int(text)


def _normalise_id(key, path) -> str:
    text = str(key).strip()
    if isinstance(key, float):  # YAML reads an unquoted 2.10 as 2.1: refuse the ambiguity
        raise LandmarkError(f"FDP id {key!r} must be quoted (\"{text}\"): an unquoted 2.10 reads as 2.1", path)
    return text


def _entries_from_mapping(data, path) -> list:
    if isinstance(data, dict) and "landmarks" in data:
        data = data["landmarks"]
    if not isinstance(data, dict):
        raise LandmarkError("expected a mapping of FDP id -> {vertex, position}", path)
    entries = []
    for key, value in data.items():
        fdp = _normalise_id(key, path)
        if isinstance(value, dict):
            vertex, position = value.get("vertex"), value.get("position")
        elif isinstance(value, (list, tuple)) and len(value) == 3:
            vertex, position = None, value
        elif isinstance(value, int) and not isinstance(value, bool):
            vertex, position = value, None
        else:
            raise LandmarkError(f"FDP {fdp}: expected {{vertex: id, position: [x, y, z]}}, got {value!r}", path)
        entries.append((fdp, vertex, position))
    return entries


def _read_csv(path: Path) -> list:
    with open(path, newline="", encoding="utf-8") as fh:
        rows = [r for r in csv.reader(line for line in fh if not line.lstrip().startswith("#"))]
    rows = [r for r in rows if any(c.strip() for c in r)]
    if not rows:
        raise LandmarkError("empty landmark file", path)
    header = [c.strip().lower() for c in rows[0]]
    if header[:1] != ["fdp"] or not {"vertex", "x", "y", "z"} <= set(header):
        raise LandmarkError(f"CSV header must be fdp,vertex,x,y,z, got {','.join(header)}", path, 1)
    col = {name: header.index(name) for name in ("fdp", "vertex", "x", "y", "z")}
    entries = []
    for line, row in enumerate(rows[1:], start=2):
        row = row + [""] * (len(header) - len(row))
        cell = {name: row[i].strip() for name, i in col.items()}
        try:
            vertex = int(cell["vertex"]) if cell["vertex"] not in ("", "null", "none") else None
            xyz = [cell[c] for c in "xyz"]
            position = None if all(c == "" for c in xyz) else [float(c) for c in xyz]
        except ValueError as exc:
            raise LandmarkError(f"FDP {cell['fdp']}: {exc}", path, line) from None
        entries.append((cell["fdp"], vertex, position))
    return entries


def read_landmarks(path: str | Path) -> RawLandmarks:
    """Read a YAML, JSON or CSV landmark file (format chosen by the suffix).

    Checks the file on its own: syntax, duplicated and unknown FDP ids, the types of
    vertex ids and positions. Raises :class:`LandmarkError`.
    """
    path = Path(path)
    if not path.is_file():
        raise LandmarkError("landmark file not found", path)
    suffix = path.suffix.lower()
    try:
        if suffix in (".yaml", ".yml"):
            text = path.read_text(encoding="utf-8")
            check_structure(text, str(path), LandmarkError)   # bombs, deep nesting, huge files

            def construct():
                loader = _UniqueKeyLoader(text)
                loader.name = str(path)
                try:
                    return loader.get_single_data()
                finally:
                    loader.dispose()
            data = construct_guarded(construct, str(path), LandmarkError)
            entries, orientation = _entries_from_mapping(data, path), _orientation(data, path)
        elif suffix == ".json":
            def pairs_hook(pairs):
                keys = [k for k, _ in pairs]
                dup = sorted({k for k in keys if keys.count(k) > 1})
                if dup:
                    raise LandmarkError(f"FDP {', '.join(dup)} given twice", path)
                return dict(pairs)
            with open(path, encoding="utf-8") as fh:
                text = fh.read()
            data = construct_guarded(lambda: json.loads(text, object_pairs_hook=pairs_hook,
                                                        parse_int=_json_int), str(path), LandmarkError, "JSON")
            entries, orientation = _entries_from_mapping(data, path), _orientation(data, path)
        elif suffix == ".csv":
            entries, orientation = _read_csv(path), None
        else:
            raise LandmarkError(f"unknown landmark format {suffix!r} (use .yaml, .json or .csv)", path)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        raise LandmarkError(f"invalid YAML: {getattr(exc, 'problem', exc)}", path,
                            None if mark is None else mark.line + 1) from None
    except json.JSONDecodeError as exc:
        raise LandmarkError(f"invalid JSON: {exc.msg}", path, exc.lineno) from None
    except UnicodeDecodeError:
        raise LandmarkError("not a text file", path) from None
    except OSError as exc:
        raise LandmarkError(f"cannot read landmark file: {exc.strerror or exc}", path) from None
    except RecursionError:
        raise LandmarkError("nested too deeply", path) from None
    return replace(_to_raw(entries, path), orientation=orientation)


def _orientation(data, path) -> tuple | None:
    """``(up, forward)`` unit vectors from a file's top-level ``orientation`` mapping
    (``{up: +Z, forward: -Y, subject_left: +X}``; subject_left optional, checked), or None."""
    from faceforge.geometry.orientation import axis_name, frame_rotation, parse_axis

    if not isinstance(data, dict) or data.get("orientation") is None:
        return None
    spec = data["orientation"]
    if not isinstance(spec, dict) or "up" not in spec or "forward" not in spec:
        raise LandmarkError(f"orientation: expected {{up: AXIS, forward: AXIS}}, got {spec!r}", path)
    try:
        up, forward = parse_axis(spec["up"]), parse_axis(spec["forward"])
        left = frame_rotation(up, forward)[0]
        if spec.get("subject_left") is not None and not np.array_equal(parse_axis(spec["subject_left"]), left):
            raise ValueError(f"subject_left {spec['subject_left']} contradicts up {spec['up']} and forward "
                             f"{spec['forward']} (a right-handed head has its left at {axis_name(left)})")
    except ValueError as exc:
        raise LandmarkError(f"orientation: {exc}", path) from None
    return up, forward


def _to_raw(entries: list, path) -> RawLandmarks:
    if not entries:
        raise LandmarkError("no landmarks in file", path)
    ids = [e[0] for e in entries]
    dup = sorted({k for k in ids if ids.count(k) > 1}, key=ids.index)
    if dup:
        raise LandmarkError(f"FDP {', '.join(dup)} given twice", path)
    unknown = [k for k in ids if k not in FDP_IDS]
    if unknown:
        raise LandmarkError(f"unknown FDP id {', '.join(unknown)} (MPEG-4 ids run 2.1 ... 11.6)", path)
    vertex = np.full(len(ids), -1, dtype=np.int64)
    position = np.full((len(ids), 3), np.nan)
    for i, (fdp, v, p) in enumerate(entries):
        if v is None and p is None:
            raise LandmarkError(f"FDP {fdp}: neither vertex nor position given", path)
        if v is not None:
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
                raise LandmarkError(f"FDP {fdp}: vertex must be an integer id, got {v!r}", path)
            if v < 0:
                raise LandmarkError(f"FDP {fdp}: vertex id {v} is negative", path)
            if v >= MAX_VERTEX_ID:
                raise LandmarkError(f"FDP {fdp}: vertex id {str(v)[:20]}{'...' if len(str(v)) > 20 else ''} "
                                    "is larger than any mesh", path)
            vertex[i] = v
        if p is not None:
            try:
                arr = np.asarray(p, dtype=np.float64)
            except (TypeError, ValueError):
                arr = np.empty(0)
            if arr.shape != (3,) or not np.all(np.isfinite(arr)):
                raise LandmarkError(f"FDP {fdp}: position must be 3 finite numbers, got {p!r}", path)
            position[i] = arr
    return RawLandmarks(str(path), tuple(ids), vertex, position)


# ----------------------------------------------------------------------------- meeting the mesh


def snap_landmarks(raw: RawLandmarks, vertices: np.ndarray, faces: np.ndarray) -> Landmarks:
    """Put every landmark on the surface of ``(vertices (n,3) float, faces (m,3) int)``.

    A given vertex id wins when its vertex lies within ``VERTEX_POSITION_TOLERANCE`` of the
    diagonal of the given position (or no position is given); a position alone is moved to
    the closest surface point. Raises :class:`LandmarkError` for vertex ids out of range, a
    vertex that disagrees with its position, and points farther than ``MAX_SNAP_DISTANCE``
    of the diagonal from the surface.
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    path, ids = raw.path, raw.ids
    diag = float(np.linalg.norm(vertices.max(0) - vertices.min(0)))
    bad = [f"{ids[i]} ({raw.vertex[i]})" for i in np.flatnonzero(raw.vertex >= len(vertices))]
    if bad:
        raise LandmarkError(f"vertex id out of range (mesh has {len(vertices)} vertices) for FDP {', '.join(bad)}", path)
    has_v = raw.vertex >= 0
    has_p = ~np.isnan(raw.position[:, 0])
    both = has_v & has_p
    gap = np.linalg.norm(vertices[raw.vertex[both]] - raw.position[both], axis=1)
    off = gap > VERTEX_POSITION_TOLERANCE * diag
    if np.any(off):
        names = [f"{ids[i]} (vertex {raw.vertex[i]} is {g:.3g} units from the given position)"
                 for i, g in zip(np.flatnonzero(both)[off], gap[off])]
        raise LandmarkError("vertex and position disagree for FDP " + "; ".join(names), path)
    target = np.where(has_v[:, None], vertices[np.maximum(raw.vertex, 0)], raw.position)
    from faceforge.geometry.surface_points import closest_points
    from faceforge.geometry.triangles import barycentric

    closest, distance, face_ids = closest_points(target, vertices, faces)
    far = distance > MAX_SNAP_DISTANCE * diag
    if np.any(far):
        names = [f"{ids[i]} ({distance[i] / diag:.1%})" for i in np.flatnonzero(far)]
        raise LandmarkError(f"FDP {', '.join(names)} lie far from the mesh (fraction of the diagonal; "
                            f"limit {MAX_SNAP_DISTANCE:.0%}): wrong mesh or wrong units?", path)
    positions = np.where(has_v[:, None], target, closest)
    bary = barycentric(positions, vertices, faces, face_ids)
    return Landmarks(path, ids, positions, face_ids, bary, raw.vertex.copy(),
                     np.where(has_v, 0.0, distance))


def check_landmarks(lm: Landmarks, vertices: np.ndarray, required=REQUIRED_FDPS) -> None:
    """Validate landmarks against each other and the mesh frame; raise :class:`LandmarkError`.

    Checks, in order: required FDPs present; no two different FDPs at one point (inner-lip
    pairs of a closed mouth excepted); subject-left FDPs at larger x than their right mirror
    (subject's left = +X); the nose tip 9.3 in front (+Z) of the eyes and ears.
    """
    path, ids = lm.path, lm.ids
    missing = [f for f in required if f not in ids]
    if missing:
        raise LandmarkError(f"required FDP {', '.join(missing)} missing (required: {', '.join(required)})", path)
    diag = float(np.linalg.norm(np.ptp(vertices, axis=0)))
    p = lm.positions
    dist = np.linalg.norm(p[:, None] - p[None], axis=2)
    ii, jj = np.nonzero(np.triu(dist < COINCIDENT_DISTANCE * diag, k=1))
    pairs = [(ids[i], ids[j]) for i, j in zip(ii, jj) if frozenset((ids[i], ids[j])) not in _MAY_COINCIDE]
    if pairs:
        raise LandmarkError("FDP at the same point: " + ", ".join(f"{a}={b}" for a, b in pairs), path)
    pos = lm.as_dict()
    present = [(l, r) for l, r in LEFT_RIGHT_PAIRS if l in pos and r in pos]
    swapped = [(l, r) for l, r in present if pos[l][0] < pos[r][0] - COINCIDENT_DISTANCE * diag]
    if swapped and len(swapped) * 2 >= len(present):
        raise LandmarkError("left and right swapped: subject-left FDP "
                            + ", ".join(f"{l} (x={pos[l][0]:.4g}) vs {r} (x={pos[r][0]:.4g})" for l, r in swapped)
                            + " should have the larger x (subject's left = +X); mirror the landmarks or the mesh", path)
    if swapped:
        raise LandmarkError("left/right labels inconsistent for FDP "
                            + ", ".join(f"{l}/{r}" for l, r in swapped)
                            + " (the left one should have the larger x)", path)
    back = [f for f in ("3.7", "3.12", "3.11", "3.8", "10.9", "10.10") if f in pos]
    if "9.3" not in pos or not back or not all(f in pos for f in ("3.7", "3.12", "2.1")):
        return   # (a caller that requires fewer FDPs than REQUIRED_FDPS: the frame checks need these)
    behind = np.mean([pos[f][2] for f in back])
    if pos["9.3"][2] <= behind:
        raise LandmarkError(f"head faces the wrong way: nose tip 9.3 (z={pos['9.3'][2]:.4g}) is not in front of "
                            f"the eyes/ears (mean z={behind:.4g}); the face must look along +Z with +Y up", path)
    up = pos["3.7"][1] + pos["3.12"][1] - 2 * pos["2.1"][1]
    if up <= 0:
        raise LandmarkError("head upside down: the eyes (3.7, 3.12) are not above the chin 2.1 along +Y", path)


def remap_vertices(raw: RawLandmarks, user_to_internal: np.ndarray) -> RawLandmarks:
    """Landmarks whose vertex ids refer to the user's mesh, re-expressed on the internal
    (merged) mesh via ``user_to_internal (n,) int64``. Raises for ids out of range."""
    bad = [f"{raw.ids[i]} ({raw.vertex[i]})" for i in np.flatnonzero(raw.vertex >= len(user_to_internal))]
    if bad:
        raise LandmarkError(f"vertex id out of range (mesh has {len(user_to_internal)} vertices) "
                            f"for FDP {', '.join(bad)}", raw.path)
    vertex = np.where(raw.vertex >= 0, np.asarray(user_to_internal)[np.maximum(raw.vertex, 0)], -1)
    return replace(raw, vertex=vertex.astype(np.int64), position=raw.position.copy())


def load_landmarks(path: str | Path, vertices: np.ndarray, faces: np.ndarray,
                   required=REQUIRED_FDPS, user_to_internal: np.ndarray | None = None,
                   rotation: np.ndarray | None = None, raw: RawLandmarks | None = None) -> Landmarks:
    """Read, snap and validate a landmark file for the mesh ``(vertices, faces)``.

    With ``user_to_internal`` (from :func:`faceforge.io.mesh_check.check_mesh`) the file's
    vertex ids refer to the user's mesh and ``(vertices, faces)`` is the internal one.
    With ``rotation (3, 3)`` (:func:`faceforge.geometry.orientation.frame_rotation`) the
    file's positions are in the user's frame and ``vertices`` already in faceforge's: the
    positions are turned by it before they meet the mesh. ``raw``: the file already read.
    """
    raw = read_landmarks(path) if raw is None else raw
    if rotation is not None:
        raw = replace(raw, position=raw.position @ np.asarray(rotation, dtype=np.float64).T)
    if user_to_internal is not None:
        raw = remap_vertices(raw, user_to_internal)
    lm = snap_landmarks(raw, vertices, faces)
    check_landmarks(lm, vertices, required)
    return lm


#: FDPs low on the face (chin, chin boss) and high on it (eye corners, pupils, inner brows),
#: for :func:`landmark_frame`
LOW_FDPS = ("2.1", "2.10")
HIGH_FDPS = ("3.5", "3.6", "3.7", "3.8", "3.11", "3.12", "4.1", "4.2")


def landmark_frame(raw: RawLandmarks, vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Up and forward of the head (unit (3,), the mesh's own coordinates) from its landmarks:
    the mirror pairs give the left, chin -> eyes the up (:func:`faceforge.geometry.orientation.
    estimate_frame`). ``vertices``: the mesh the file's vertex ids refer to. Raises LandmarkError."""
    v = np.asarray(vertices, dtype=np.float64)
    ok = (raw.vertex >= 0) & (raw.vertex < len(v))
    pos = np.where(ok[:, None], v[np.where(ok, raw.vertex, 0)], raw.position)
    at = {f: pos[i] for i, f in enumerate(raw.ids) if np.isfinite(pos[i]).all()}
    return points_frame(at, raw.path)


def points_frame(at: dict, path=None) -> tuple[np.ndarray, np.ndarray]:
    """Up and forward (unit (3,)) spanned by FDP points ``{fdp: (3,)}`` (the same points and rule
    as :func:`landmark_frame`; e.g. the template skull's landmarks). Raises LandmarkError naming
    ``path``."""
    from faceforge.geometry.orientation import estimate_frame

    pairs = [(a, b) for a, b in LEFT_RIGHT_PAIRS if a in at and b in at]
    low, high = [at[f] for f in LOW_FDPS if f in at], [at[f] for f in HIGH_FDPS if f in at]
    if not pairs or not low or not high:
        raise LandmarkError("cannot tell the head's orientation from its landmarks (need a left/right pair, "
                            f"one of {', '.join(LOW_FDPS)} and one of {', '.join(HIGH_FDPS)})", path)
    try:
        return estimate_frame([at[a] for a, _ in pairs], [at[b] for _, b in pairs], low, high)
    except ValueError as exc:
        raise LandmarkError(f"cannot tell the head's orientation from its landmarks: {exc}", path) from None
