"""rules.first_hit (the jaw angles' ray cast, numpy alone) against the mesh-wide RayCaster."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from faceforge.landmarks.rules import first_hit

MASK = Path(__file__).resolve().parents[2] / "samples/mediapipe/face_model_with_iris.obj"


def test_first_hit_matches_the_ray_caster_on_the_mask():
    from faceforge.geometry.rays import RayCaster
    from faceforge.io.mesh import load_mesh

    v, f, _ = load_mesh(MASK)
    caster = RayCaster(v, f)
    rng = np.random.default_rng(3)
    lo, hi = v.min(0), v.max(0)
    hits = 0
    for _ in range(60):
        origin = lo + rng.random(3) * (hi - lo) + np.array([0.0, 0.0, 2.0]) * (hi - lo)
        d = rng.normal(size=3) * 0.3 + np.array([0.0, 0.0, -1.0])
        d /= np.linalg.norm(d)
        fid, ref, _ = caster.first_hit(origin[None], d[None], 10 * np.linalg.norm(hi - lo))
        got = first_hit(v[f], origin, d)
        if np.asarray(fid)[0] < 0:
            assert got is None
        else:
            hits += 1
            assert got is not None and np.allclose(got, np.asarray(ref)[0], atol=1e-9 * np.ptp(v))
    assert hits > 10          # the test sees hits, not only misses


def test_first_hit_ignores_triangles_behind_the_origin():
    tri = np.array([[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
                    [[0.0, 0.0, 2.0], [1.0, 0.0, 2.0], [0.0, 1.0, 2.0]]])
    hit = first_hit(tri, np.array([0.2, 0.2, 1.0]), np.array([0.0, 0.0, -1.0]))
    assert np.allclose(hit, [0.2, 0.2, 0.0])
    assert first_hit(tri, np.array([0.2, 0.2, -1.0]), np.array([0.0, 0.0, -1.0])) is None
