"""Eye rotation for the ``eyeLook*`` shapes: the eyeball pieces of a mesh, turned rigidly.

A mesh has an eyeball piece when a connected component other than the skin (the largest) lies
at a pupil FDP (3.5 the subject's left, 3.6 the right): its vertices nearest the pupil within
half the eye's corner distance (3.7-3.11, 3.8-3.12). The piece turns about the eyeball's centre:
:data:`EYEBALL_RADIUS` x half the corner distance (a 12 mm eye in a 30 mm fissure, as
:mod:`faceforge.animation.eyelids` takes it) behind the piece's centroid along the face's forward
axis (+Z). ``yaw`` turns the gaze towards +X (the subject's left), ``pitch`` up. The pieces
have no skin attached: nothing else moves (the lids do not follow the gaze).

All in the head's frame (+X the subject's left, +Y up, +Z forward), lengths the skin's.
"""

from __future__ import annotations

import numpy as np

#: eyeball radius as a fraction of half the eye's corner distance (as the eyelids take it)
EYEBALL_RADIUS = 0.8

#: side -> (pupil FDP, corner FDP, corner FDP)
EYE_FDPS = {"L": ("3.5", "3.7", "3.11"), "R": ("3.6", "3.12", "3.8")}


def eye_pieces(rest: np.ndarray, faces: np.ndarray, landmarks: dict) -> dict:
    """``{side: (vertex ids (k,) int, centre (3,))}`` for each eye that has a piece (see the module
    docstring); an eye without its three FDPs or without a piece at its pupil is left out.
    rest (n, 3) float; faces (m, 3) int; landmarks {FDP: (3,) position}."""
    from faceforge.geometry.triangles import vertex_components

    rest = np.asarray(rest, dtype=float)
    labels = vertex_components(len(rest), faces)
    ids, counts = np.unique(labels[labels >= 0], return_counts=True)
    if len(ids) < 2:
        return {}
    skin = ids[np.argmax(counts)]
    out = {}
    for side, (pupil, a, b) in EYE_FDPS.items():
        if not all(k in landmarks for k in (pupil, a, b)):
            continue
        p = np.asarray(landmarks[pupil], dtype=float)
        half = 0.5 * float(np.linalg.norm(np.asarray(landmarks[a], float) - np.asarray(landmarks[b], float)))
        near = (labels >= 0) & (labels != skin) & (np.linalg.norm(rest - p, axis=1) <= half)
        if not near.any():
            continue
        piece = labels[near][np.argmin(np.linalg.norm(rest[near] - p, axis=1))]
        vid = np.flatnonzero(labels == piece)
        centre = rest[vid].mean(axis=0) - np.array([0.0, 0.0, EYEBALL_RADIUS * half])
        out[side] = (vid, centre)
    return out


def gaze_rotation(yaw: float, pitch: float) -> np.ndarray:
    """(3, 3): the forward axis +Z turned ``yaw`` rad towards +X, then ``pitch`` rad up (+Y)."""
    cy, sy, cp, sp = np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch)
    turn = np.array([[cy, 0.0, sy], [0.0, 1.0, 0.0], [-sy, 0.0, cy]])       # about +Y: +Z -> +X
    lift = np.array([[1.0, 0.0, 0.0], [0.0, cp, sp], [0.0, -sp, cp]])       # about -X: +Z -> +Y
    return turn @ lift


def rotate_eye(frame: np.ndarray, ids: np.ndarray, centre: np.ndarray, yaw: float, pitch: float) -> np.ndarray:
    """A copy of ``frame (n, 3)`` with the vertices ``ids`` turned about ``centre`` (radians)."""
    out = np.array(frame, dtype=float, copy=True)
    R = gaze_rotation(yaw, pitch)
    out[ids] = (out[ids] - centre) @ R.T + centre
    return out
