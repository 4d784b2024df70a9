"""The landmarks of a head: the user's file, completed by detection where it falls short.

:func:`find_landmarks` decides, for a mesh and its landmark file path:

* the file exists and holds every FDP the detector gives (:func:`detect.fdp_table`; the jaw
  angles 2.13/2.14 may be missing, as the detection leaves them out where the mesh has no jaw side):
  it is used as it is, nothing is detected (``source = "given"``);
* the file exists but lacks some of them (a partial file): the rest are detected, the
  file's points are kept as written (``"completed"``);
* no file at the default path (``<mesh stem>.fdp.yaml``, or none given): all are detected
  (``"detected"``); a file named explicitly but absent is an error.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from faceforge.landmarks.detect import Detection


@dataclass
class Found:
    """``source`` "given" | "completed" | "detected"; ``detection`` (None when given);
    ``given_path`` (None when detected); ``vertices (n, 3)``, ``faces (m, 3)``: the mesh."""

    source: str
    detection: Detection | None
    given_path: str | None
    vertices: np.ndarray
    faces: np.ndarray


def find_landmarks(mesh_path, landmark_path=None, symmetrise: bool = True, paint_eyes: bool = True) -> Found:
    """See the module docstring. ``landmark_path`` None: the default path next to the mesh."""
    from faceforge.io.landmarks import default_landmark_path, read_landmarks
    from faceforge.io.mesh import load_mesh
    from faceforge.io.mesh_check import check_mesh
    from faceforge.landmarks.detect import RULE_ONLY, detect_landmarks, fdp_table
    from faceforge.landmarks.output import merge

    mesh_path = Path(mesh_path)
    default = default_landmark_path(mesh_path)
    path = Path(landmark_path) if landmark_path else default
    v, f, _ = load_mesh(mesh_path)
    raw = None
    if path.exists() or path.absolute() != default.absolute():
        raw = read_landmarks(path)    # an explicit path that is absent: "not found"
        if set(fdp_table()) - set(RULE_ONLY) <= set(raw.ids):   # the jaw angles are optional
            return Found("given", None, str(path), v, f)
    # a broken mesh says what is wrong with it, not "no face"; with two heads, which one to find?
    check_mesh(v, f, str(mesh_path), one_head=True)
    det = detect_landmarks(v, f, str(mesh_path), symmetrise=symmetrise, paint_eyes=paint_eyes)
    if raw is None:
        return Found("detected", det, None, v, f)
    _check_ids(raw, len(v))
    return Found("completed", merge(det, raw, v), str(path), v, f)


def _check_ids(raw, n_vertices: int) -> None:
    from faceforge.exceptions import LandmarkError

    bad = [f"{raw.ids[i]} ({raw.vertex[i]})" for i in np.flatnonzero(raw.vertex >= n_vertices)]
    if bad:
        raise LandmarkError(f"vertex id out of range (mesh has {n_vertices} vertices) for FDP {', '.join(bad)}",
                            raw.path)
