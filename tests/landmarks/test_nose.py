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
