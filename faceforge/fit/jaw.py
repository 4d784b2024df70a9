"""The fitted jaw axes (§6.1): where the mandible turns and which way the condyles glide.

The template's axes (``jaw.yaml``: pitch, yaw, protrusion, each a point and a direction) are
carried onto the head after the bones are fitted (:func:`fit_jaw_axes`):

- **points** by the fit's similarity (the least-squares scale, turn and shift of all the
  landmarks), not by the full map: the condyles lie far behind the face's landmarks, where the
  RBFs extrapolate (MakeHuman: the map put the pitch axis 0.2 cm above the pupils, the
  similarity 1.3 cm below them, in front of the ear);
- **pitch and yaw directions** by the rotation that best carries the template mandible onto the
  fitted one (least squares over all its vertices): the jaw is one rigid body;
- **the protrusion direction** by the rotation that best carries the template *cranium* onto the
  fitted one. The condyles glide forward along the articular eminence of the temporal bone (and
  the opening's glide, :func:`faceforge.anatomy.skull.condylar_glide`, is taken along this
  direction), a part of the cranium. The fitted mandible is no rigid copy of the template's:
  on a face mask with no ears or jaw angles (MediaPipe) its angles are held where the similarity
  puts them while the chin is pulled down to a long chin, so its best rotation is an opening
  (18 degrees from the head's own turn on MediaPipe, 11 on MakeHuman, 4 on ICT), which tipped the
  glide downwards and let the chin swing back (open_jaw 713 MNS on MediaPipe: 0.38 of the way
  down).
"""

from __future__ import annotations

import numpy as np

from faceforge.fit.align import apply_affine
from faceforge.geometry.rigid import similarity_transform

#: which template bone's best rotation turns each axis' direction
AXIS_BONE = {"pitch": "mandible", "yaw": "mandible", "protrusion": "cranium"}


def best_rotation(template_vertices, fitted_vertices, fallback: np.ndarray) -> np.ndarray:
    """(3, 3) rotation of the least-squares similarity template (n, 3) -> fitted (n, 3); the
    rotation part of ``fallback`` (4, 4) when there are fewer than three vertices."""
    if len(template_vertices) >= 3:
        m = similarity_transform(np.asarray(template_vertices, dtype=np.float64),
                                 np.asarray(fitted_vertices, dtype=np.float64))
    else:
        m = np.asarray(fallback, dtype=np.float64)
    return m[:3, :3] / np.cbrt(abs(np.linalg.det(m[:3, :3])))


def fit_jaw_axes(jaw_axes: dict, similarity: np.ndarray, cranium: tuple, mandible: tuple) -> dict:
    """{name: (point (3,), unit direction (3,))} on the head for the template's ``jaw_axes``
    (same form, template units). ``similarity`` (4, 4) is the fit's template -> head similarity;
    ``cranium`` and ``mandible`` are (template vertices (n, 3), fitted vertices (n, 3)) pairs."""
    rot = {"cranium": best_rotation(*cranium, similarity), "mandible": best_rotation(*mandible, similarity)}
    out = {}
    for name, (point, direction) in jaw_axes.items():
        d = rot[AXIS_BONE.get(name, "mandible")] @ np.asarray(direction, dtype=np.float64)
        out[name] = (apply_affine(similarity, np.asarray(point, dtype=np.float64)[None])[0], d / np.linalg.norm(d))
    return out
