"""A face-reading check: MediaPipe's 52 ARKit-style blendshape scores of a grey render, and
which of the six basic expressions they read as.

The Face Landmarker model we already ship (:func:`faceforge.landmarks.detector.model_path`)
holds a blendshape head (``face_blendshapes.tflite``): with ``output_face_blendshapes`` it
scores the 52 ARKit names (``browInnerUp``, ``jawOpen``, ``mouthSmileLeft``, ...) in [0, 1]
from the picture alone. The model has never seen this project's meshes, so it is an
independent reader of what a render shows.

Classification (:func:`expression_scores`, :func:`recognised`): each expression is its FACS
prototype (EXPRESSION_AUS: joy 6+12, sadness 1+4+15, anger 4+5+7+23, fear 1+2+4+5+20+26,
disgust 9+15+16, surprise 1+2+5+26); each action unit is the mean of its ARKit scores
(AU_BLENDSHAPES; a pair's left and right); an expression's score is the mean over its AUs of
(the render's AU score - the neutral render's AU score); the render reads as the expression
whose score is highest of the six.
"""

from __future__ import annotations

import numpy as np

from faceforge.landmarks.detector import Detector
from faceforge.landmarks.raster import View, render

#: FACS action unit -> ARKit blendshape names (MediaPipe spells a side ``...Left``/``...Right``,
#: the subject's own side)
AU_BLENDSHAPES = {
    1: ("browInnerUp",),
    2: ("browOuterUpLeft", "browOuterUpRight"),
    4: ("browDownLeft", "browDownRight"),
    5: ("eyeWideLeft", "eyeWideRight"),
    6: ("cheekSquintLeft", "cheekSquintRight"),
    7: ("eyeSquintLeft", "eyeSquintRight"),
    9: ("noseSneerLeft", "noseSneerRight"),
    12: ("mouthSmileLeft", "mouthSmileRight"),
    15: ("mouthFrownLeft", "mouthFrownRight"),
    16: ("mouthLowerDownLeft", "mouthLowerDownRight"),
    20: ("mouthStretchLeft", "mouthStretchRight"),
    23: ("mouthPressLeft", "mouthPressRight"),
    26: ("jawOpen",),
}

#: the six basic expressions' FACS prototypes (issue 25), in MPEG-4's order
EXPRESSION_AUS = {
    "joy": (6, 12),
    "sadness": (1, 4, 15),
    "anger": (4, 5, 7, 23),
    "fear": (1, 2, 4, 5, 20, 26),
    "disgust": (9, 15, 16),
    "surprise": (1, 2, 5, 26),
}


#: the expressions in MPEG-4's order
EXPRESSIONS_ORDER = tuple(EXPRESSION_AUS)


def au_scores(blendshapes: dict) -> dict:
    """{AU: mean of its ARKit scores} from ``blendshapes {name: score}``."""
    return {au: float(np.mean([blendshapes[n] for n in names])) for au, names in AU_BLENDSHAPES.items()}


def expression_scores(blendshapes: dict, neutral: dict) -> dict:
    """{expression: mean over its AUs of (AU score - neutral AU score)}, both dicts
    ``{ARKit name: score in [0, 1]}``."""
    au, au0 = au_scores(blendshapes), au_scores(neutral)
    return {name: float(np.mean([au[a] - au0[a] for a in aus])) for name, aus in EXPRESSION_AUS.items()}


def recognised(scores: dict) -> str:
    """The expression with the highest score (:func:`expression_scores`)."""
    return max(scores, key=scores.get)


class BlendshapeScorer(Detector):
    """MediaPipe's Face Landmarker in IMAGE mode with its blendshape head: ``score(rgb)`` ->
    ``{ARKit name: score}`` (52 names, ``_neutral`` included) or None when no face is found."""

    def __init__(self, min_confidence: float = 0.3):
        super().__init__(min_confidence, blendshapes=True)

    def score(self, rgb: np.ndarray) -> dict | None:
        """Blendshape scores of the face in ``rgb (h, w, 3) uint8``, or None."""
        result = self._result(rgb)
        if not result.face_blendshapes:
            return None
        return {c.category_name: float(c.score) for c in result.face_blendshapes[0]}


def face_view(region_vertices: np.ndarray, yaw_deg: float = 0.0, size: int = 512,
              share: float = 0.72) -> View:
    """An orthographic camera on a face in the project frame (+Y up, the face looking along +Z):
    centred on ``region_vertices (k, 3)`` (the face's box), its height ``share`` of a ``size``
    pixel picture, turned ``yaw_deg`` degrees about +Y (positive: the subject's left cheek
    turns towards the camera)."""
    v = np.asarray(region_vertices, dtype=np.float64)
    lo, hi = v.min(axis=0), v.max(axis=0)
    centre = 0.5 * (lo + hi)
    t = np.radians(yaw_deg)
    direction = np.array([-np.sin(t), 0.0, -np.cos(t)])
    extent = max(hi[1] - lo[1], hi[0] - lo[0])
    return View(direction, np.array([0.0, 1.0, 0.0]), centre, share * size / extent, size)


def eyeballs(centres: np.ndarray, radii: np.ndarray, forward: np.ndarray, subdivisions: int = 3):
    """Eyeballs to draw with a head (:func:`grey_render`): a sphere per eye, ``centres (e, 3)``,
    ``radii (e,)`` and looking along ``forward (e, 3)`` (unit), in the head's frame and units.
    Returns ``(vertices (k, 3), faces (f, 3), facing (k,))``: the spheres' mesh and each vertex's
    cosine to its eye's forward axis (1 at the pupil's centre)."""
    import trimesh

    ball = trimesh.creation.icosphere(subdivisions=subdivisions)
    unit, tri = np.asarray(ball.vertices, dtype=np.float64), np.asarray(ball.faces, dtype=np.int64)
    centres, forward = np.atleast_2d(centres).astype(np.float64), np.atleast_2d(forward).astype(np.float64)
    radii = np.atleast_1d(radii).astype(np.float64)
    vertices = np.concatenate([c + r * unit for c, r in zip(centres, radii)])
    faces = np.concatenate([tri + k * len(unit) for k in range(len(centres))])
    facing = np.concatenate([unit @ w for w in forward])
    return vertices, faces, facing


#: an eyeball's pupil and iris, half-angles about its forward axis (degrees; an 11-12 mm iris and a
#: 4 mm pupil on a 24 mm eye), and their grey levels with the sclera's
PUPIL_DEG, IRIS_DEG = 10.0, 30.0
PUPIL_GREY, IRIS_GREY, SCLERA_GREY = 15, 70, 235


def grey_render(vertices: np.ndarray, faces: np.ndarray, view: View, eyes=None) -> np.ndarray:
    """(size, size, 3) uint8: the mesh smooth-shaded grey on black (:func:`faceforge.landmarks.
    raster.render`, vertex normals, light above the camera). ``eyes``: :func:`eyeballs`' meshes,
    drawn with the mesh (hidden where the skin is in front: behind the lids) and painted flat,
    sclera light, iris grey, pupil black; None (the default): the eye holes stay empty."""
    from faceforge.geometry.triangles import vertex_normals

    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    if eyes is None:
        return render(vertices, faces, vertex_normals(vertices, faces), view).rgb()
    ev, ef, facing = eyes
    n, m = len(vertices), len(faces)
    allv = np.concatenate([vertices, np.asarray(ev, dtype=np.float64)])
    allf = np.concatenate([faces, np.asarray(ef, dtype=np.int64) + n])
    out = render(allv, allf, vertex_normals(allv, allf), view)
    image = out.image.copy()
    eye = out.face_id >= m
    if eye.any():
        cos = np.einsum("kj,kj->k", out.bary[eye], np.asarray(facing)[allf[out.face_id[eye]] - n])
        image[eye] = np.where(cos > np.cos(np.radians(PUPIL_DEG)), PUPIL_GREY,
                              np.where(cos > np.cos(np.radians(IRIS_DEG)), IRIS_GREY, SCLERA_GREY))
    return np.ascontiguousarray(np.repeat(image[:, :, None], 3, axis=2))
