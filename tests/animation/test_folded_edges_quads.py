"""folded_edges keeps the bending quads of the last few face arrays (a bake checks ~60 shapes of
one mesh): the same answer as from the topology built afresh, the topology built once per mesh."""

from __future__ import annotations

import numpy as np

from faceforge.animation import checks


def _grid(n=6):
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    v = np.stack([i.ravel(), j.ravel(), np.zeros(n * n)], axis=1).astype(float)
    a = (i[:-1, :-1] * n + j[:-1, :-1]).ravel()
    f = np.concatenate([np.stack([a, a + n, a + 1], 1), np.stack([a + 1, a + n, a + n + 1], 1)])
    return v, f


def _folded_twin(rest, frames, faces):
    """folded_edges from the topology built afresh (the code before the quads were kept)."""
    from faceforge.pbd.constraints.bending import dihedral_angle
    from faceforge.skin.layer import skin_topology

    quads = skin_topology(faces).bending_quads
    flat = np.abs(dihedral_angle(rest, quads)) < np.radians(checks.FLAT_DEG)
    return np.stack([flat & (np.abs(dihedral_angle(p, quads)) > np.radians(checks.FOLD_DEG)) for p in frames])


def test_folded_edges_builds_the_topology_once_per_mesh(monkeypatch):
    import faceforge.skin.layer as layer

    v, f = _grid()
    frames = np.repeat(v[None], 3, axis=0)
    for k, line in ((1, 3.0), (2, 2.0)):   # the grid folded back over itself along x = line
        far = v[:, 0] > line
        frames[k, far, 0] = line - 0.9 * (v[far, 0] - line)
        frames[k, far, 2] = 0.3 * (v[far, 0] - line)
    want = _folded_twin(v, frames, f)
    other = f[:, ::-1].copy()        # another face array (same vertices, turned): built again
    want_other = _folded_twin(v, frames, other)
    assert want.any()
    calls = []
    real = layer.skin_topology
    monkeypatch.setattr(layer, "skin_topology", lambda faces: calls.append(1) or real(faces))
    checks._QUADS.clear()
    for _ in range(3):
        assert np.array_equal(checks.folded_edges(v, frames, f), want)
    assert len(calls) == 1
    assert np.array_equal(checks.folded_edges(v, frames, other), want_other)
    assert len(calls) == 2
