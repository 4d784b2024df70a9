"""The template hexahedral mesh (Fig. 4) and its RBF morph (§5.1.2)."""

import numpy as np
import pytest
import trimesh

from faceforge.anatomy.muscles.hexmesh import hex_topology, morph_hex, signed_volume, template_positions


@pytest.mark.parametrize("h,w,closed", [(2, 2, False), (5, 3, False), (7, 4, False), (3, 2, True), (16, 3, True)])
def test_template_closed_oriented_watertight(h, w, closed):
    topo = hex_topology(h, w, closed)
    p = template_positions(topo, height=0.5)
    m = trimesh.Trimesh(p, topo.faces, process=False)
    assert m.is_watertight and m.is_winding_consistent
    assert m.volume > 0 and signed_volume(p, topo.faces) == pytest.approx(m.volume)
    # Euler characteristic: sphere (box) or torus (annulus)
    chi = len(p) - len(m.edges_unique) + len(topo.faces)
    assert chi == (0 if closed else 2)


@pytest.mark.parametrize("h,w,closed", [(5, 3, False), (6, 4, False), (8, 3, True)])
def test_contour_is_the_bottom_border_in_order(h, w, closed):
    topo = hex_topology(h, w, closed)
    g = topo.contour_grid()
    assert len(topo.contour) == (2 * h if closed else 2 * (h + w) - 4)
    assert len(np.unique(topo.contour)) == len(topo.contour)
    assert np.all(topo.contour < h * w)  # bottom sheet
    if not closed:  # a closed walk of grid neighbours
        step = np.abs(np.diff(np.vstack([g, g[:1]]), axis=0)).sum(axis=1)
        assert np.all(step == 1)
    else:  # inner ring then outer ring
        assert np.all(g[:h, 1] == 0) and np.all(g[h:, 1] == w - 1)


def curved_contour(topo, scale=1.0):
    """Contour samples on the cylinder y^2 + z^2 = 4 with outward normals."""
    g = topo.contour_grid().astype(float)
    if topo.closed:
        ang = 2 * np.pi * g[:, 0] / topo.h
        r = 0.3 + 0.2 * g[:, 1] / (topo.w - 1)
        x, u = r * np.cos(ang), r * np.sin(ang)
    else:
        x, u = g[:, 1] / (topo.w - 1) * 0.6, g[:, 0] / (topo.h - 1) * 1.0
    th = u / 2.0
    s = np.stack([x, 2 * np.sin(th), 2 * np.cos(th)], 1) * scale
    n = np.stack([np.zeros_like(th), np.sin(th), np.cos(th)], 1)
    return s, n


@pytest.mark.parametrize("closed", [False, True])
def test_morph_meets_samples_and_has_thickness(closed):
    topo = hex_topology(8 if closed else 6, 3, closed)
    s, n = curved_contour(topo)
    t = 0.05
    p, faces = morph_hex(topo, s, n, t)
    np.testing.assert_allclose(p[topo.contour], s, atol=1e-12)
    m = trimesh.Trimesh(p, faces, process=False)
    assert m.is_watertight and m.is_winding_consistent and m.volume > 0
    hw = topo.h * topo.w
    gap = p[hw:] - p[:hw]
    np.testing.assert_allclose(np.linalg.norm(gap, axis=1), t, rtol=1e-9)
    # the top is on the outer side (the side the sample normals point to)
    assert np.all(np.einsum("ij,ij->i", gap[topo.contour], n) > 0.9 * t)


def test_morph_is_equivariant_under_rigid_motion():
    """§5.1.2: size/orientation of the template do not matter; moving the contour rigidly moves
    the muscle rigidly."""
    topo = hex_topology(6, 4)
    s, n = curved_contour(topo)
    a = 0.7
    R = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    tr = np.array([1.0, -2.0, 0.5])
    p, f = morph_hex(topo, s, n, 0.05)
    q, g = morph_hex(topo, s @ R.T + tr, n @ R.T, 0.05)
    np.testing.assert_allclose(q, p @ R.T + tr, atol=1e-9)
    np.testing.assert_array_equal(f, g)


def test_morph_fixes_mirrored_orientation():
    topo = hex_topology(5, 3)
    s, n = curved_contour(topo)
    s[:, 0] *= -1  # mirror
    p, faces = morph_hex(topo, s, n, 0.05)
    assert signed_volume(p, faces) > 0


def test_bad_arguments():
    with pytest.raises(ValueError):
        hex_topology(1, 3)
    topo = hex_topology(4, 3)
    s, n = curved_contour(topo)
    with pytest.raises(ValueError, match="thickness"):
        morph_hex(topo, s, n, 0.0)
    with pytest.raises(ValueError, match="contour samples"):
        morph_hex(topo, s[:-1], n[:-1], 0.1)
