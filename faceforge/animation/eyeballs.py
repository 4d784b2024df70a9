"""The eyeball pieces of a mesh, turned rigidly: by the eyeball FAPs 23-26 of a track, and for the
``eyeLook*`` shapes of the bake.

A mesh has an eye when connected components other than the skin (the largest in area) lie at a pupil
FDP (3.5 the subject's left, 3.6 the right): every such piece with a vertex within half the eye's
corner distance (3.7-3.11, 3.8-3.12) of the pupil and its centroid within 1.5 times that of the
pupil and not in front of it (lashes are), so that a sclera, a cornea and an iris modelled apart
turn together. They turn about the eyeball's centre: the centre of the sphere through the vertices
of the largest of them (least squares) when it is eyeball-sized (radius within :data:`SPHERE_FIT` of
:data:`~faceforge.animation.eyelids.EYEBALL_RADIUS` x half the corner distance: a 12 mm eye in a 30
mm fissure, as the lids take it), else, for a flat piece such as MediaPipe's iris discs, that radius
behind their centroid along the face's forward axis (+Z). ``yaw`` turns the gaze towards +X (the
subject's left), ``pitch`` up. The pieces have no skin attached: nothing else moves (the lids do not
follow the gaze). Between frames the bind's rigid parts (:mod:`faceforge.skin.parts`) keep them on
the cranium; the turn is laid over each finished frame, as the lids are.

MPEG-4's eyeball FAPs are angles in AU (1e-5 rad): ``yaw_l_eyeball`` (23) and ``yaw_r_eyeball``
(24) positive to the left (the subject's, +X), ``pitch_l_eyeball`` (25) and ``pitch_r_eyeball``
(26) positive down (:func:`gaze_from_faps`).

All in the head's frame (+X the subject's left, +Y up, +Z forward), lengths the skin's.
"""

from __future__ import annotations

import numpy as np

from faceforge.animation.eyelids import EYEBALL_RADIUS

#: the eyeball FAPs (yaw L, pitch L, yaw R, pitch R) in :func:`apply_gaze`'s column order
GAZE_FAPS = (23, 25, 24, 26)

#: one AU, the FAP unit of angles (rad)
AU = 1e-5

#: side -> (pupil FDP, corner FDP, corner FDP)
EYE_FDPS = {"L": ("3.5", "3.7", "3.11"), "R": ("3.6", "3.12", "3.8")}


def eye_pieces(rest: np.ndarray, faces: np.ndarray, landmarks: dict) -> dict:
    """``{side: (vertex ids (k,) int, centre (3,))}`` for each eye that has pieces (see the module
    docstring); an eye without its three FDPs or without a piece at its pupil is left out.
    rest (n, 3) float; faces (m, 3) int; landmarks {FDP: (3,) position}."""
    from faceforge.geometry.triangles import face_areas, vertex_components

    rest = np.asarray(rest, dtype=float)
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    labels = vertex_components(len(rest), faces)
    ids = np.unique(labels[labels >= 0])
    if len(ids) < 2:
        return {}
    # the skin: the piece of largest area (an eyeball may have more vertices than a low-poly head)
    area = np.bincount(labels[faces[:, 0]], weights=face_areas(rest, faces), minlength=int(ids.max()) + 1)
    skin = int(np.argmax(area))
    out = {}
    for side, (pupil, a, b) in EYE_FDPS.items():
        if not all(k in landmarks for k in (pupil, a, b)):
            continue
        p = np.asarray(landmarks[pupil], dtype=float)
        half = 0.5 * float(np.linalg.norm(np.asarray(landmarks[a], float) - np.asarray(landmarks[b], float)))
        near = (labels >= 0) & (labels != skin) & (np.linalg.norm(rest - p, axis=1) <= half)
        pieces = [k for k in np.unique(labels[near]) if _at_pupil(rest[labels == k].mean(axis=0) - p, half)]
        if not pieces:
            continue
        vid = np.flatnonzero(np.isin(labels, pieces))
        ball = np.flatnonzero(labels == pieces[int(np.argmax(area[pieces]))])   # the sclera, if any
        out[side] = (vid, eyeball_centre(rest[ball], rest[vid], EYEBALL_RADIUS * half))
    return out


def _at_pupil(offset: np.ndarray, half: float) -> bool:
    """A piece whose centroid lies ``offset (3,)`` from the pupil is part of the eye: within 1.5
    ``half`` (an eyeball's centre is 0.8 of it behind the cornea) and not in front of the pupil
    (by more than a tenth of ``half``: lashes stand in front of the lids)."""
    return bool(np.linalg.norm(offset) <= 1.5 * half and offset[2] <= 0.1 * half)


#: a sphere fitted to an eye's pieces is taken for the eyeball when its radius is within this
#: factor of the expected one (either way)
SPHERE_FIT = 1.6


def eyeball_centre(points: np.ndarray, pieces: np.ndarray, radius: float) -> np.ndarray:
    """(3,) the centre an eye's pieces turn about: the least-squares sphere's centre of ``points
    (k, 3)`` (its largest piece) when they are many (12) and deep (RMS depth along their thinnest
    axis a quarter of ``radius``) and its radius is within :data:`SPHERE_FIT` of ``radius``, else
    ``radius`` behind the centroid of all its ``pieces (j, 3)`` along +Z (a flat iris or cornea in
    front of an eyeball the mesh lacks)."""
    points = np.asarray(points, dtype=float)
    fallback = np.asarray(pieces, dtype=float).mean(axis=0) - np.array([0.0, 0.0, radius])
    if len(points) < 12:
        return fallback
    thin = np.linalg.svd(points - points.mean(axis=0), compute_uv=False)[-1] / np.sqrt(len(points))
    if thin < 0.25 * radius:        # a disc or a shallow cap: no sphere to fit (its RMS depth)
        return fallback
    # |x - c|^2 = r^2  <=>  2 x.c + (r^2 - |c|^2) = |x|^2: linear in (c, d)
    a = np.column_stack([2.0 * points, np.ones(len(points))])
    sol, _, rank, _ = np.linalg.lstsq(a, (points ** 2).sum(axis=1), rcond=None)
    if rank < 4:
        return fallback
    centre = sol[:3]
    r = float(np.sqrt(max(sol[3] + centre @ centre, 0.0)))
    if not radius / SPHERE_FIT <= r <= radius * SPHERE_FIT:
        return fallback
    return centre


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


def gaze_from_faps(faps: np.ndarray) -> np.ndarray:
    """``(F, 4)`` radians (yaw L, pitch L, yaw R, pitch R; pitch up) of the eyeball FAPs of
    ``faps (F, 68)`` (MPEG-4 values, pitch positive down)."""
    faps = np.atleast_2d(np.asarray(faps, dtype=float))
    return faps[:, [f - 1 for f in GAZE_FAPS]] * (AU * np.array([1.0, -1.0, 1.0, -1.0]))


def apply_gaze(frames: np.ndarray, gaze: np.ndarray, eyes: dict) -> np.ndarray:
    """Frames (F, n, 3) with each eye piece turned by ``gaze (F, 4)`` (yaw L, pitch L, yaw R,
    pitch R; radians) about its centre (:func:`eye_pieces`); a copy."""
    out = np.array(frames, dtype=float, copy=True)
    for side, cols in (("L", (0, 1)), ("R", (2, 3))):
        if side not in eyes:
            continue
        ids, centre = eyes[side]
        for f in np.flatnonzero(np.any(gaze[:, cols] != 0.0, axis=1)):
            out[f] = rotate_eye(out[f], ids, centre, gaze[f, cols[0]], gaze[f, cols[1]])
    return out
