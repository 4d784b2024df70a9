"""The alare rule (faceforge.landmarks.nose) on the sample meshes, without the detector."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from faceforge.landmarks.nose import alae

ROOT = Path(__file__).resolve().parents[2]
FRAME = (np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0]))   # the samples face +Z


def _head(rel, scale=1.0):
    from faceforge.geometry.triangles import vertex_normals
    from faceforge.io.landmarks import read_landmarks
    from faceforge.io.mesh import load_mesh

    mesh = ROOT / rel
    v, f, _ = load_mesh(mesh)
    v = v * scale
    raw = read_landmarks(mesh.with_name(mesh.stem + ".fdp.yaml"))
    hand = {k: (v[raw.vertex[i]] if raw.vertex[i] >= 0 else scale * raw.position[i]) for i, k in enumerate(raw.ids)}
    return v, f, vertex_normals(v, f), hand, float(np.linalg.norm(np.ptp(v, axis=0)))


@pytest.mark.parametrize("rel, scale, within", [("samples/makehuman/mh_head_default.obj", 1.0, 1e-9),
                                                ("samples/ict/ict_face_headneck_neutral.obj", 10.0, 0.0045)])
def test_alae_beside_the_wing_go_to_its_lateral_edge(rel, scale, within):
    # the detector's alae lie beside the wing, in the groove on the cheek (0.6-1.1 % of the diagonal
    # behind the hand points); started from the hand points moved 0.8 % outwards and back, the rule
    # finds the wing's edge: MakeHuman's hand vertex, ICT within 0.45 % (its hand point 0.39 % away)
    v, f, n, hand, diag = _head(rel, scale)
    start = {k: hand[k] + np.array([side * 0.008 * diag, 0.0, -0.008 * diag]) for k, side in (("9.1", 1), ("9.2", -1))}
    out = alae(v, f, n, start, FRAME, diag)
    assert set(out) == {"9.1", "9.2"}
    for k in out:
        assert np.linalg.norm(v[out[k]] - hand[k]) <= within * diag, (k, np.linalg.norm(v[out[k]] - hand[k]) / diag)
        assert np.linalg.norm(start[k] - hand[k]) > 0.01 * diag
        assert abs(n[out[k]][0]) >= 0.85          # its skin faces sideways


def test_a_mesh_too_coarse_to_draw_the_wing_is_left_to_the_detector():
    v, f, n, hand, diag = _head("samples/mediapipe/face_model_with_iris.obj")    # 478 vertices
    assert alae(v, f, n, {k: hand[k] for k in ("9.1", "9.2")}, FRAME, diag) == {}
    assert alae(v, f, n, {"9.1": hand["9.1"]}, FRAME, diag) == {}


def test_nose_base_less_the_detector_bias_goes_back_to_the_canonical_vertices():
    # MediaPipe's canonical face (the mask) with its nose-base points 9.4/9.5 moved as the detector
    # moves them on a grey render of it (outwards and up by NOSE_BASE_BIAS) comes back onto the
    # model's vertices; a missing eye corner places nothing
    from faceforge.geometry.rays import RayCaster
    from faceforge.landmarks.detect import fdp_table
    from faceforge.landmarks.nose import NOSE_BASE_BIAS, nose_base

    v, f, _, hand, diag = _head("samples/mediapipe/face_model_with_iris.obj")
    table = fdp_table()
    pos = {k: v[table[k]] for k in ("3.7", "3.12", "9.4", "9.5")}
    span = abs(pos["3.7"][0] - pos["3.12"][0])
    moved = dict(pos, **{k: pos[k] + np.array([np.sign(pos[k][0]) * NOSE_BASE_BIAS[k][0] * span,
                                               NOSE_BASE_BIAS[k][1] * span, 0.0]) for k in ("9.4", "9.5")})
    out = nose_base(RayCaster(v, f), moved, FRAME, diag)
    assert set(out) == {"9.4", "9.5"}
    for k in out:
        assert np.linalg.norm(out[k] - pos[k]) < 1e-3 * diag, k
        assert np.linalg.norm(moved[k] - pos[k]) > 0.005 * diag
    assert nose_base(RayCaster(v, f), {k: p for k, p in moved.items() if k != "3.7"}, FRAME, diag) == {}
