"""geometry.mirror_mesh: a closed mesh made its own mirror image about x = 0 (issue 25)."""

from __future__ import annotations

import numpy as np
import trimesh

from faceforge.geometry.mirror_mesh import mirror_half, vertex_partners


def _lopsided_sphere():
    """A closed sphere whose triangulation is not its own mirror image (turned, shifted in x)."""
    m = trimesh.creation.icosphere(subdivisions=3)
    rot = trimesh.transformations.rotation_matrix(0.3, [0.2, 1.0, 0.4])[:3, :3]
    v = np.asarray(m.vertices) @ rot.T + [0.01, 0.0, 0.0]
    return v, np.asarray(m.faces)


def test_a_lopsided_mesh_gets_partners_and_stays_closed():
    v, f = _lopsided_sphere()
    assert vertex_partners(v) is None
    hv, hf = mirror_half(v, f)
    partner = vertex_partners(hv)
    assert partner is not None
    assert np.array_equal(partner[partner], np.arange(len(hv)))
    faces = {tuple(sorted(x)) for x in hf.tolist()}
    assert all(tuple(sorted(x)) in faces for x in partner[hf].tolist())   # mirror-image triangulation
    mesh = trimesh.Trimesh(hv, hf, process=False)
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
    # the +x half is kept as it was: its vertices lie on the old surface
    old = trimesh.Trimesh(v, f, process=False)
    right = hv[hv[:, 0] > 0.05]
    assert trimesh.proximity.closest_point(old, right)[1].max() < 1e-9
    assert abs(mesh.volume - old.volume) / old.volume < 0.05


def test_no_slivers_at_the_cut():
    v, f = _lopsided_sphere()
    hv, hf = mirror_half(v, f)
    edges = np.linalg.norm(hv[hf] - hv[np.roll(hf, 1, axis=1)], axis=2)
    old = np.linalg.norm(v[f] - v[np.roll(f, 1, axis=1)], axis=2)
    assert edges.min() > 0.1 * old.mean()


def test_a_mirror_image_rounded_to_float32_has_exact_partners_and_a_sculpted_one_not():
    from faceforge.geometry.mirror import Mirror

    rng = np.random.default_rng(3)
    half = rng.random((200, 3)) * [10.0, 20.0, 15.0] + [0.5, 0.0, 0.0]   # x > 0: a head's left half
    v = np.vstack([half, half * [-1.0, 1.0, 1.0]]).astype(np.float32).astype(np.float64) + [0.3, 0, 0]
    v = v.astype(np.float32).astype(np.float64)      # shifted, rounded as an OBJ export would be
    mirror = Mirror([0.3, 0.0, 0.0], [1.0, 0.0, 0.0])
    partner = mirror.exact_partners(v)
    assert partner is not None and np.array_equal(partner, np.r_[np.arange(200, 400), np.arange(200)])
    sculpted = v.copy()
    sculpted[5, 1] += 1e-4 * 20.0                    # one vertex 1e-4 of the extent off its twin
    assert mirror.exact_partners(sculpted) is None
