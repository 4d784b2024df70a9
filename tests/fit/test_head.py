"""The fit's array functions on synthetic heads (ellipsoids), with exact expectations."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from faceforge.anatomy import tissue as fit_tissue
from faceforge.fit.align import Warp, apply_affine, map_directions, worst_first_sample
from faceforge.geometry.rigid import similarity_transform
from faceforge.fit.head import FitSettings, FitTemplate, fit_head
from faceforge.fit.surface import SkinSurface, front_mask, orient_outward, signed_skin_depth
from faceforge.anatomy.muscles.build import eq5_thickness
from faceforge.fit.muscles import cylindrical_projection
from faceforge.io.mesh_check import fill_holes

from .heads import ellipsoid_head, face_landmarks_on


def rotation(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def test_similarity_round_trip():
    rng = np.random.default_rng(1)
    src = rng.normal(size=(20, 3))
    rot, s, t = rotation([1, 2, 3], 0.7), 3.5, np.array([1.0, -2.0, 0.5])
    m = similarity_transform(src, s * src @ rot.T + t)
    np.testing.assert_allclose(m[:3, :3], s * rot, atol=1e-12)
    np.testing.assert_allclose(m[:3, 3], t, atol=1e-12)
    # a mirrored target still gives a proper rotation (det > 0): the fit never mirrors a skull
    m2 = similarity_transform(src, src * [-1, 1, 1])
    assert np.linalg.det(m2[:3, :3]) > 0


def test_directions_follow_a_similarity_exactly():
    rot = rotation([0, 1, 0], 0.3)
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = 2.0 * rot, [5, 6, 7]
    warp = Warp(m)
    d = np.array([[1.0, 0, 0], [0, 0.6, 0.8]])
    np.testing.assert_allclose(map_directions(warp, np.zeros((2, 3)), d, 0.1), d @ rot.T, atol=1e-12)


def test_worst_first_sample_keeps_spacing_and_order():
    pts = np.array([[0, 0, 0], [0.1, 0, 0], [1, 0, 0], [2, 0, 0], [2.05, 0, 0]], float)
    bad = np.array([5.0, 9.0, 1.0, 3.0, 4.0])
    pick = worst_first_sample(pts, bad, 10, np.array([[1.0, 0.0, 0.2]]), 0.5)
    np.testing.assert_array_equal(pick, [1, 4])   # 1 beats 0 (too close), 4 beats 3, 2 is near the source


def test_tissue_depth_table_and_scale():
    lm = {"3.5": np.array([3.15, 0, 0]), "3.6": np.array([-3.15, 0, 0]),
          "3.7": np.array([4.0, 0, 0]), "3.11": np.array([2.0, 0, 0]),
          "3.12": np.array([-4.0, 0, 0]), "3.8": np.array([-2.0, 0, 0])}
    assert np.isclose(fit_tissue.es0(lm), 6.3)                      # pupils
    assert np.isclose(fit_tissue.es0({k: lm[k] for k in ("3.7", "3.11", "3.12", "3.8")}), 6.0)
    scale = fit_tissue.units_per_mm(lm)                             # cm head: 0.1 cm per mm
    assert np.isclose(scale, 0.1)
    d = fit_tissue.tissue_depths(["2.10", "9.3", "4.1"], scale)
    assert np.isclose(d[0], 1.3) and np.isnan(d[1]) and np.isclose(d[2], 0.45)
    sites = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    depths = np.array([1.0, 2.0, 3.0])
    np.testing.assert_allclose(fit_tissue.depth_field(sites, sites, depths), depths)
    q = np.random.default_rng(0).normal(size=(50, 3))
    f = fit_tissue.depth_field(q, sites, depths)
    assert np.all((f >= 1.0) & (f <= 3.0))


def test_signed_depth_inside_outside_and_uncovered(ellipsoid):
    v, f = ellipsoid
    skin = SkinSurface.build(v, f)
    dirs = np.array([[0, 0, 1.0], [1.0, 0, 0], [0, 1.0, 0]])
    surf = np.array([[0, 0, 0.95], [0.8, 0, 0], [0, 1.1, 0]])
    depth, closest, normal, covered, pocket = signed_skin_depth(np.vstack([surf * 0.9, surf * 1.1]), skin)
    assert np.all(depth[:3] > 0) and np.all(depth[3:] < 0) and covered.all() and not pocket.any()
    np.testing.assert_allclose(normal, np.vstack([dirs, dirs]), atol=0.05)
    # open the front: points before the hole are no longer covered by skin
    front = np.any(v[f][:, :, 2] > 0.9, axis=1)
    open_skin = SkinSurface.build(v, f[~front], close_holes=False)
    _, _, _, covered, _ = signed_skin_depth(np.array([[0, 0, 0.5], [0, 0.6, 0.2]]), open_skin)
    assert not covered[0] and covered[1]


def test_fill_holes_closes_all_but_the_longest(ellipsoid):
    v, f = ellipsoid
    cut = np.any(v[f][:, :, 2] > 0.8, axis=1) | np.any(v[f][:, :, 1] < -1.0, axis=1)
    v2, f2, n = fill_holes(v, f[~cut], keep_open=0)
    mesh = trimesh.Trimesh(v2, f2, process=False)
    assert n == 2 and mesh.is_watertight and mesh.is_winding_consistent
    np.testing.assert_array_equal(v2[:len(v)], v)
    _, _, n1 = fill_holes(v, f[~cut], keep_open=1)
    assert n1 == 1


def test_orient_outward_flips_inward_heads(ellipsoid):
    v, f = ellipsoid
    np.testing.assert_array_equal(orient_outward(v, f), f)
    np.testing.assert_array_equal(orient_outward(v, f[:, ::-1]), f)


def test_cylindrical_projection_finds_the_muscle_above():
    box = trimesh.creation.box(extents=[0.4, 0.4, 0.1])
    box.apply_translation([0, 0, 1.05])                         # a slab from z = 1.0 to 1.1
    pts = np.array([[0, 0, 0.98], [0, 0.9, 0.98]])             # under the slab / beside it
    covered, hits, which, lift = cylindrical_projection(pts, np.zeros(3), [(box.vertices, box.faces)], 5.0)
    assert covered.tolist() == [True, False] and which[0] == 0
    np.testing.assert_allclose(hits[0], [0, 0, 1.1], atol=1e-9)
    assert np.isclose(lift[0], 0.12)
    assert eq5_thickness(0.01, 30.0) == pytest.approx(0.3)


def synthetic_case(scale=1.0):
    """Skin: an ellipsoid head (x scale); skull: a smaller, differently shaped ellipsoid in
    other units and turned 0.2 rad, with landmarks where the skin's FDP rays cross it."""
    sv, sf = ellipsoid_head(40, 60)
    sv = sv * 10 * scale
    lm = face_landmarks_on(sv, sf)
    kv, kf = ellipsoid_head(30, 40, radii=(0.75, 1.0, 0.85))
    m = trimesh.Trimesh(kv, kf, process=False)
    skl = {}
    for k, p in lm.items():
        d = p / np.linalg.norm(p)
        loc, _, _ = m.ray.intersects_location([[0, 0, 0]], [d])
        skl[k] = loc[np.argmax(loc @ d)]
    rot = rotation([0, 1, 0], 0.2)
    place = lambda p: (np.asarray(p) @ rot.T) * 3 + [1, 2, 3]
    jaw = {"pitch": (place([0, -0.5, 0]), rot @ [1.0, 0, 0])}
    template = FitTemplate((place(kv), kf), (place(kv[:0]), kf[:0]), {k: place(p) for k, p in skl.items()},
                           jaw, {"m": place(kv[:5])})
    ids = tuple(lm)
    pts = np.array([lm[k] for k in ids])
    closest, _, tri = trimesh.proximity.closest_point(trimesh.Trimesh(sv, sf, process=False), pts)
    return sv, sf, template, ids, closest


def test_synthetic_fit_meets_the_acceptance_checks():
    sv, sf, template, ids, pts = synthetic_case()
    skin = SkinSurface.build(sv, sf)
    res = fit_head(template, skin, ids, pts, FitSettings())
    assert np.linalg.norm(res.reached - res.targets, axis=1).max() < 1e-8 * skin.diagonal
    depth, _, _, covered, _ = signed_skin_depth(res.cranium, skin)
    front = front_mask(res.cranium, dict(zip(ids, pts)), 0.75)
    assert front.sum() > 200 and np.all(depth[covered & front] > 0)
    # the jaw's pitch axis was turned with the template: the map turns it back to +X
    assert res.jaw_axes["pitch"][1] @ [1.0, 0, 0] > 0.99
    # targets lie beneath the skin by the table's depth for this head size
    scale = fit_tissue.units_per_mm(dict(zip(ids, pts)))
    for f, t in zip(res.fdps, res.tissue_targets):
        d, _, _, _, _ = signed_skin_depth(t[None], skin)
        assert d[0] == pytest.approx(fit_tissue.tissue_depths([f], scale)[0], rel=0.2)


def test_synthetic_fit_is_scale_equivariant():
    a = synthetic_case(1.0)
    b = synthetic_case(10.0)
    ra = fit_head(a[2], SkinSurface.build(a[0], a[1]), *a[3:])
    rb = fit_head(b[2], SkinSurface.build(b[0], b[1]), *b[3:])
    diag = np.linalg.norm(np.ptp(ra.cranium, axis=0))
    assert np.max(np.linalg.norm(rb.cranium / 10.0 - ra.cranium, axis=1)) < 1e-6 * diag


def test_settings_from_config_reject_other_kernels():
    from faceforge.exceptions import ConfigError

    assert FitSettings.from_config({"rbf_kernel": "multiquadric", "refit": False}).refit is False
    with pytest.raises(ConfigError, match="rbf_kernel"):
        FitSettings.from_config({"rbf_kernel": "gaussian"})
    assert apply_affine(np.eye(4), np.ones((2, 3))).shape == (2, 3)


def test_enhancement_flow_keeps_placed_landmarks_and_does_not_fold():
    """§7 enhancement as a flow: points where the field is zero stay exactly, a new pair's
    bone point moves most of the way to its target, and a dense grid carried along keeps
    every cell's orientation (the map is one-to-one) even where the exact RBF through the
    same pairs turns cells over (a target pulled past a held landmark 1 unit away: the
    flow brings the bone point up to the landmark, never across)."""
    from faceforge.fit.align import Flow, enhancement_field, integrate_flow
    from faceforge.geometry.rbf import hardy_epsilon, hardy_rbf

    rng = np.random.default_rng(3)
    held = rng.uniform(-4, 4, (12, 3))
    held[0] = 0.0
    start = np.array([[1.0, 0.0, 0.0]])
    target = np.array([[-1.5, 0.0, 0.0]])          # pulled past the held landmark at the origin
    eps = hardy_epsilon(held)
    u = enhancement_field(held, start, target - start, eps)
    np.testing.assert_allclose(u(held), 0.0, atol=1e-9)
    flow = Flow(u, 8)
    np.testing.assert_allclose(flow(held), held, atol=1e-8)
    # it cannot cross the held landmark: the bone point comes up to it and stops short
    assert 0.0 < flow(start)[0, 0] < 0.5
    # a pair not pulled across anything goes most of the way
    away = np.array([[1.6, 0.4, 0.0]])
    moved = Flow(enhancement_field(held, start, away - start, eps), 8)(start)
    assert np.linalg.norm(moved - away) < 0.5 * np.linalg.norm(away - start)
    assert np.array_equal(integrate_flow(u, held[:3], 8), flow(held[:3]))
    # orientation of a grid's cells: determinant of the finite-difference Jacobian
    g = np.stack(np.meshgrid(*[np.linspace(-2, 2, 21)] * 3, indexing="ij"), -1).reshape(-1, 3)
    h = 1e-4

    def min_det(f):
        jac = np.stack([(f(g + h * e) - f(g - h * e)) / (2 * h) for e in np.eye(3)], -1)
        return np.linalg.det(jac).min()

    assert min_det(flow) > 0.0
    exact = hardy_rbf(np.vstack([held, start]), np.vstack([held, target]), epsilon=eps)
    assert min_det(exact) < 0.0       # the exact RBF folds here: the case the flow is for


def test_exact_rbf_enhancement_is_still_available():
    """``enhancement_flow_steps: 0``: the paper's exact RBF through all pairs (one map)."""
    sv, sf, template, ids, pts = synthetic_case()
    skin = SkinSurface.build(sv, sf)
    a = fit_head(template, skin, ids, pts, FitSettings(enhancement_flow_steps=0))
    b = fit_head(template, skin, ids, pts, FitSettings())
    for res in (a, b):
        assert np.linalg.norm(res.reached - res.targets, axis=1).max() < 1e-8 * skin.diagonal
