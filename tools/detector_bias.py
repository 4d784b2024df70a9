"""The face detector's bias at the eyebrows and the nose's lower edge, measured on its own canonical face.

Usage::

    PYTHONPATH=. python tools/detector_bias.py

Runs the landmark detection (:func:`faceforge.landmarks.detect.detect_landmarks`: the search,
the consensus views, the lift) on the MediaPipe sample head, whose vertices are MediaPipe's
canonical face (``landmarks/data/mediapipe_canonical_478.txt``), and prints, for each brow point
(:data:`faceforge.landmarks.brows.BROW_POINTS`) and the nose's lower edge 9.4/9.5, how far the agreed detector point lies from the
model's own vertex, in the model's eye frame (:func:`faceforge.landmarks.brows.eye_frame`): sideways,
positive away from the midline, and up, in eye spans; then the mean of each left/right pair, the
numbers :data:`faceforge.landmarks.brows.OUTWARD_BIAS` holds for the inner and middle brows
(2026-11-29: 4.1/4.2 0.012 / 0.025, 4.3/4.4 0.043 / 0.049 outward) and
:data:`faceforge.landmarks.nose.NOSE_BASE_BIAS` for 9.4/9.5 (0.018 / 0.021 outward, 0.006 / 0.010 up).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

MASK = Path(__file__).resolve().parents[1] / "samples/mediapipe/face_model_with_iris.obj"


def main() -> None:
    import faceforge.landmarks.detect as detect
    from faceforge.io.mesh import load_mesh
    from faceforge.landmarks.brows import BROW_POINTS, EYE_CORNERS, canonical_model, eye_frame
    from faceforge.landmarks.detect import fdp_table

    seen = {}
    consensus = detect._consensus

    def keep(stack, diagonal):   # the agreed 478 points, before any rule or symmetrisation
        out = consensus(stack, diagonal)
        seen["agreed"] = out[0].copy()
        return out

    detect._consensus = keep
    v, f, _ = load_mesh(MASK)
    detect.detect_landmarks(v, f, str(MASK))
    model = canonical_model()
    o, s = eye_frame({k: model[i] for k, i in EYE_CORNERS.items()}, np.array([1.0, 0.0, 0.0]))
    table = fdp_table()
    points = {**BROW_POINTS, "9.4": table["9.4"], "9.5": table["9.5"]}
    bias = {}
    for k, i in points.items():
        d = (seen["agreed"][i] - model[i]) / s
        bias[k] = (np.sign(model[i][0] - o[0]) * d[0], d[1])
        print(f"{k} (point {i}): outward {bias[k][0]:+.4f}, up {bias[k][1]:+.4f} eye spans")
    for a, b in (("4.1", "4.2"), ("4.3", "4.4"), ("4.5", "4.6"), ("9.4", "9.5")):
        print(f"{a}/{b}: mean outward {(bias[a][0] + bias[b][0]) / 2:+.4f}, up {(bias[a][1] + bias[b][1]) / 2:+.4f}")


if __name__ == "__main__":
    main()
