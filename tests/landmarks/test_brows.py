"""The eyebrow rule (faceforge.landmarks.brows) on MediaPipe's canonical face, without the detector."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from faceforge.landmarks.brows import (BROW_POINTS, EYE_CORNERS, OUTWARD_BIAS, brows, canonical_height,
                                      canonical_lateral)

MASK = Path(__file__).resolve().parents[2] / "samples/mediapipe/face_model_with_iris.obj"
FRAME = (np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0]))


def _mask(scale=1.0):
    from faceforge.geometry.rays import RayCaster
    from faceforge.io.mesh import load_mesh

    v, f, _ = load_mesh(MASK)     # vertex ids are MediaPipe's point indices
    v = v * scale
    return v, RayCaster(v, f), float(np.linalg.norm(np.ptp(v, axis=0)))


def test_canonical_heights_are_above_the_eyes_and_mirror_pairs_agree():
    h = canonical_height()
    assert set(h) == set(BROW_POINTS)
    assert h["4.1"] == h["4.2"] and h["4.3"] == h["4.4"] and h["4.5"] == h["4.6"]
    assert 0.1 < h["4.5"] < h["4.1"] < h["4.3"] < 0.5    # the brow arches over the eye, its tail lowest


def test_lowered_brows_go_back_to_the_canonical_brow_points():
    # the canonical face's own brows pulled down by 15 % of the eye span (what the detector does
    # on a grey render) and out from the midline by the detector's outward bias come back onto the
    # model's brow vertices
    v, caster, diag = _mask()
    pos = {k: v[i] for k, i in {**EYE_CORNERS, **BROW_POINTS}.items()}
    span = abs(pos["3.7"][0] - pos["3.12"][0])
    low = {k: (p + [np.sign(p[0]) * OUTWARD_BIAS.get(k, 0.0) * span, -0.15 * span, 0.0] if k in BROW_POINTS else p)
           for k, p in pos.items()}
    out = brows(caster, low, FRAME, diag, moved=tuple(BROW_POINTS))
    assert set(out) == set(BROW_POINTS)
    for k, i in BROW_POINTS.items():
        assert np.linalg.norm(out[k] - v[i]) < 1e-3 * diag, k
        assert np.linalg.norm(low[k] - v[i]) > 0.03 * diag       # the start was far


def test_scale_and_missing_corners():
    v, caster, diag = _mask()
    v2, caster2, diag2 = _mask(100.0)
    pos = {k: v[i] - np.array([0.0, 0.5, 0.0]) * (k in BROW_POINTS) for k, i in {**EYE_CORNERS, **BROW_POINTS}.items()}
    pos2 = {k: 100.0 * p for k, p in pos.items()}
    a, b = brows(caster, pos, FRAME, diag), brows(caster2, pos2, FRAME, diag2)
    assert set(a) == set(BROW_POINTS)     # the outer brows are moved sideways only
    assert all(np.allclose(100.0 * a[k], b[k], atol=1e-6 * diag2) for k in a)
    assert brows(caster, {k: p for k, p in pos.items() if k != "3.8"}, FRAME, diag) == {}
    only = brows(caster, pos, FRAME, diag, moved=("4.1", "4.2"), sideways=())
    assert set(only) == {"4.1", "4.2"}


def test_outer_brows_moved_inwards_go_back_sideways_and_keep_their_height():
    # the canonical face's outer brows pulled 10 % of the eye span towards the midline (the detector
    # stops short of the temple on a grey render) come back to the model's brow vertices; a raised
    # one keeps its height (only the side-to-side position is the canonical face's)
    v, caster, diag = _mask()
    pos = {k: v[i] for k, i in {**EYE_CORNERS, **BROW_POINTS}.items()}
    span = abs(pos["3.7"][0] - pos["3.12"][0])
    lat = canonical_lateral()
    assert lat["4.5"] == -lat["4.6"] and lat["4.5"] > lat["4.3"] > lat["4.1"] > 0
    inward = {k: (p - np.sign(p[0]) * np.array([0.1 * span, 0.0, 0.0]) if k in ("4.5", "4.6") else p) for k, p in pos.items()}
    out = brows(caster, inward, FRAME, diag, moved=())
    assert set(out) == {"4.5", "4.6"}
    for k in ("4.5", "4.6"):
        assert np.linalg.norm(out[k] - v[BROW_POINTS[k]]) < 2e-3 * diag, k
        assert np.linalg.norm(inward[k] - v[BROW_POINTS[k]]) > 0.02 * diag
    raised = dict(inward, **{"4.5": inward["4.5"] + np.array([0.0, 0.05 * span, 0.0])})
    up = brows(caster, raised, FRAME, diag, moved=())
    assert abs(up["4.5"][1] - raised["4.5"][1]) < 1e-9 * diag
