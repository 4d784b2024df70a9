"""Which way the face looks: the orientation search and the consensus views.

:func:`find_face` renders the mesh from the six axis directions, turns each picture
through four quarter turns (exactly the four ``up`` choices of that direction), runs the
face detector on them (up to 24: an upright face seen from the front ends the search) and
keeps the face with the best score. Every camera is built
from the mesh's bounding box and the axes, so a head turned by a signed permutation of the
axes (Blender's Z-up frame, a head facing +X) sees the very same pictures.

:func:`face_frame` turns the best view's points into the face's own frame (left, up,
forward, from the back-projected eye, mouth and chin points), and :func:`consensus_views`
places a frontal camera in that frame plus a few turned a little, framed on the face.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from faceforge.landmarks.lift import lift
from faceforge.landmarks.raster import Render, View, render

#: the face search's picture size (pixels)
SEARCH_SIZE = 320
#: the consensus pictures' size (pixels) and the face's share of it
VIEW_SIZE = 512
FACE_SHARE = 0.5
#: consensus views: (yaw, pitch) in degrees about the face's up and left axes (nine views: median
#: error on MakeHuman / ICT / MediaPipe 0.54 / 0.46 / 1.21 %, p90 1.65 / 1.04 / 2.46 %; the first
#: five alone 0.52 / 0.46 / 1.27 %, p90 1.83 / 1.10 / 2.51 %; the frontal one alone 0.51 / 0.50 /
#: 1.35 %, p90 1.83 / 1.07 / 2.56 %: the detector's error on grey renders is mostly a bias)
VIEW_ANGLES = ((0.0, 0.0), (-12.0, 0.0), (12.0, 0.0), (0.0, -8.0), (0.0, 8.0),
               (-20.0, 0.0), (20.0, 0.0), (0.0, -15.0), (0.0, 15.0))
#: a face scoring below this is no face; one scoring above SURE_SCORE ends the search
MIN_SCORE = 0.35
SURE_SCORE = 0.9
#: face likeness (:func:`face_likeness`) at which a detection's score falls to zero, and the
#: span over which it rises to full (measured, trimmed RMS: MakeHuman 0.07 facing the camera,
#: 0.09 turned 25 degrees and rolled 15, 0.11 looking 40 degrees down; a sphere's hallucinated
#: face 0.185)
LIKENESS_NONE = 0.16
LIKENESS_SPAN = 0.06
#: the share of the points (best fitting) the likeness is measured on: points MediaPipe
#: places behind the nose of a turned head lift onto the wrong surface
LIKENESS_KEEP = 0.75
#: hole-search radius of the search views' lifting, fraction of the picture
SEARCH_LIFT = 0.06

#: MediaPipe point indices used for the face frame: (left, right) mirror pairs, chin, brows
_PAIRS = ((263, 33), (362, 133), (291, 61), (334, 105), (358, 129))
_CHIN = 152


@dataclass
class Sighting:
    """A face seen in one render: ``points (478, 2)`` pixels, ``score``, the render."""

    render: Render
    points: np.ndarray
    score: float
    label: str


def _axis_name(vec) -> str:
    i = int(np.argmax(np.abs(vec)))
    return ("+" if vec[i] > 0 else "-") + "XYZ"[i]


#: the search's camera directions, in order, each with its picture's up (all four quarter turns of
#: each picture are tried, so the up only sets which turn is upright): first the two frames heads
#: come in most (OBJ/glTF: +Y up facing +Z, seen looking along -Z; Blender: +Z up facing -Y, seen
#: looking along +Y), where an upright face ends the search after one picture (24 detections
#: for an OBJ head before, 4 now); the same pictures in any order, so turned heads still see
#: the same ones
SEARCH_DIRECTIONS = (((0, 0, -1), (0, 1, 0)), ((0, 1, 0), (0, 0, 1)), ((0, 0, 1), (0, 1, 0)),
                     ((0, -1, 0), (0, 0, 1)), ((1, 0, 0), (0, 1, 0)), ((-1, 0, 0), (0, 1, 0)))


def search_views(vertices: np.ndarray):
    """The six axis-direction cameras over the whole mesh: [(direction, up)] (unit (3,)),
    in :data:`SEARCH_DIRECTIONS` order."""
    return [(np.array(d, dtype=np.float64), np.array(u, dtype=np.float64)) for d, u in SEARCH_DIRECTIONS]


def face_likeness(points3d: np.ndarray) -> float:
    """RMS distance (fraction of the model's RMS radius) between lifted points ``(478, 3)``
    (NaN where lost) and MediaPipe's canonical face after the best similarity transform
    (Umeyama), over the best-fitting :data:`LIKENESS_KEEP` of them: small for a face in
    relief, large for a face-like pattern painted on a sphere or a box, whose lifted points
    do not have a face's shape."""
    from pathlib import Path

    model = np.loadtxt(Path(__file__).with_name("data") / "mediapipe_canonical_478.txt")
    ok = np.isfinite(points3d).all(axis=1)
    if ok.sum() < 100:
        return np.inf
    a, b = points3d[ok], model[ok]
    a0, b0 = a - a.mean(axis=0), b - b.mean(axis=0)
    u, s, vt = np.linalg.svd(a0.T @ b0)
    d = np.sign(np.linalg.det(u @ vt))
    s[-1] *= d
    u[:, -1] *= d
    rot = u @ vt                                   # a0 @ rot ~ scale * b0
    scale = s.sum() / (a0 ** 2).sum()
    resid = np.sort(((scale * a0 @ rot - b0) ** 2).sum(axis=1))[: int(LIKENESS_KEEP * len(a0))]
    return float(np.sqrt(resid.mean() / (b0 ** 2).sum(axis=1).mean()))


def find_face(vertices, faces, normals, detector, centre, radius) -> tuple[Sighting | None, int]:
    """The best face over the 24 axis frames, or None; and the number of views tried.

    ``centre (3,)``, ``radius``: the mesh's bounding-box centre and half diagonal. A face's
    score is the detector's plausibility (upright, frontal) times how much the points lifted
    onto the mesh have a face's shape (:func:`face_likeness`).
    """
    best, tried = None, 0
    for direction, up in search_views(vertices):
        view = View(direction, up, centre, SEARCH_SIZE / (2.0 * radius), SEARCH_SIZE)
        r = render(vertices, faces, normals, view, raise_light=0.0)   # a quarter turn = another up
        for quarter in range(4):
            tried += 1
            rgb = np.rot90(r.rgb(), k=quarter).copy()
            face = detector.detect(rgb)
            if face is None:
                continue
            pts = _unrotate(face.points, quarter, SEARCH_SIZE)
            lifted, _ = lift(r, vertices, faces, pts, 2.0 * radius, SEARCH_LIFT * SEARCH_SIZE)
            score = face.score * float(np.clip((LIKENESS_NONE - face_likeness(lifted)) / LIKENESS_SPAN, 0.0, 1.0))
            if best is None or score > best.score:
                best = Sighting(r, pts, score, f"looking along {_axis_name(direction)}, turn {90 * quarter}")
        if best is not None and best.score >= SURE_SCORE:
            break   # only an upright face seen from the front scores this high
    if best is None or best.score < MIN_SCORE:
        return None, tried
    return best, tried


def _unrotate(points: np.ndarray, quarter: int, size: int) -> np.ndarray:
    """Pixel points found on ``np.rot90(image, quarter)`` -> the unrotated image's pixels."""
    p = points.copy()
    for _ in range(quarter % 4):
        # rot90 (counter-clockwise) maps (col, row) -> (row, size - col); undo it
        p = np.column_stack([size - p[:, 1], p[:, 0]])
    return p


def face_frame(points3d: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(left, up, forward) unit (3,) of the face from its back-projected points ``(478, 3)``
    (NaN where unseen): left from the mirror pairs, up from the chin to the eyes and brows. A chin
    point off the mesh (a face mask cut just under the chin: MakeHuman's young female cut to a
    mask's extent gave a NaN frame, nine black views and "no face found") is taken from
    MediaPipe's canonical face fitted to the other points (:func:`canonical_point`)."""
    diffs = [points3d[a] - points3d[b] for a, b in _PAIRS]
    left = np.nanmean(np.array(diffs), axis=0)
    left /= np.linalg.norm(left)
    high = np.nanmean(points3d[[263, 33, 334, 105]], axis=0)
    up = high - (points3d[_CHIN] if np.isfinite(points3d[_CHIN]).all() else canonical_point(points3d, _CHIN))
    up -= left * (up @ left)
    up /= np.linalg.norm(up)
    forward = np.cross(left, up)
    return left, up, forward


def canonical_point(points3d: np.ndarray, index: int) -> np.ndarray:
    """(3,) where MediaPipe's canonical face puts point ``index`` once fitted (similarity,
    Umeyama) to the lifted points ``(478, 3)`` that are on the mesh (NaN rows left out)."""
    from faceforge.landmarks.brows import canonical_model

    model = canonical_model()
    ok = np.isfinite(points3d).all(axis=1)
    a, b = points3d[ok], model[ok]
    a0, b0 = a - a.mean(axis=0), b - b.mean(axis=0)
    u, s, vt = np.linalg.svd(b0.T @ a0)
    d = np.ones(3)
    d[-1] = np.sign(np.linalg.det(u @ vt))
    rot = (u * d) @ vt                            # b0 @ rot ~ a0 / scale
    scale = (s * d).sum() / (b0 ** 2).sum()
    return scale * (model[index] - b.mean(axis=0)) @ rot + a.mean(axis=0)


def _turn(vec, axis, deg):
    """``vec`` turned about unit ``axis`` by ``deg`` degrees (Rodrigues)."""
    t = np.radians(deg)
    return vec * np.cos(t) + np.cross(axis, vec) * np.sin(t) + axis * (axis @ vec) * (1 - np.cos(t))


def view_labels() -> list[str]:
    """Names of the consensus views, in :data:`VIEW_ANGLES` order ("front", "yaw -12", ...)."""
    return ["front" if (y, p) == (0.0, 0.0) else " ".join(f"{n} {a:+g}" for n, a in (("yaw", y), ("pitch", p)) if a)
            for y, p in VIEW_ANGLES]


def consensus_views(left, up, forward, centre, width) -> list[View]:
    """Cameras around the face: frontal, then turned by :data:`VIEW_ANGLES`. ``centre (3,)``
    the face's middle, ``width`` its extent (mesh units)."""
    scale = FACE_SHARE * VIEW_SIZE / width
    views = []
    for yaw, pitch in VIEW_ANGLES:
        d = _turn(-forward, up, yaw)
        u = _turn(up, left, pitch)
        d = _turn(d, left, pitch)
        views.append(View(d, u, centre, scale, VIEW_SIZE))
    return views


def sight(vertices, faces, normals, detector, view: View, label: str) -> Sighting | None:
    """Render ``view`` and detect the face in it (upright: no quarter turns)."""
    r = render(vertices, faces, normals, view)
    face = detector.detect(r.rgb())
    if face is None:
        return None
    return Sighting(r, face.points, 1.0, label)
