"""The face detector's outward bias at the eyebrows, measured on its own canonical face.

Usage::

    PYTHONPATH=. python tools/brow_bias.py

Runs the landmark detection (:func:`faceforge.landmarks.detect.detect_landmarks`: the search,
the consensus views, the lift) on the MediaPipe sample head, whose vertices are MediaPipe's
canonical face (``landmarks/data/mediapipe_canonical_478.txt``), and prints, for each brow point
(:data:`faceforge.landmarks.brows.BROW_POINTS`), how far the agreed detector point lies from the
model's own vertex, in the model's eye frame (:func:`faceforge.landmarks.brows.eye_frame`): sideways,
positive away from the midline, and up, in eye spans; then the mean of each left/right pair, the
numbers :data:`faceforge.landmarks.brows.OUTWARD_BIAS` holds for the inner and middle brows
(2026-11-29: 4.1/4.2 0.012 / 0.025, 4.3/4.4 0.043 / 0.049 outward).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

MASK = Path(__file__).resolve().parents[1] / "samples/mediapipe/face_model_with_iris.obj"


def main() -> None:
    import faceforge.landmarks.detect as detect
    from faceforge.io.mesh import load_mesh
    from faceforge.landmarks.brows import BROW_POINTS, EYE_CORNERS, canonical_model, eye_frame

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
    pairs = {}
    for k, i in BROW_POINTS.items():
        d = (seen["agreed"][i] - model[i]) / s
        out = np.sign(model[i][0] - o[0]) * d[0]
        n = int(k.split(".")[1])
        pairs.setdefault(f"4.{n - 1 + n % 2}/4.{n + n % 2}", []).append(out)
        print(f"{k} (point {i}): outward {out:+.4f}, up {d[1]:+.4f} eye spans")
    for name, vals in pairs.items():
        print(f"pair {name}: mean outward {np.mean(vals):+.4f}")


if __name__ == "__main__":
    main()
