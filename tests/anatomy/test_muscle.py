"""Linear (§5.2.1) and sphincter (§5.2.2) muscles: network, rest state, contraction."""

import numpy as np
import pytest
import trimesh

from faceforge.anatomy.muscles.hexmesh import hex_topology, signed_volume
from faceforge.anatomy.muscles.muscle import STIFFNESS_KEYS, bending_quads, distance_network
from faceforge.anatomy.muscles.sphincter import fit_ellipse, sphincter_displacement
from faceforge.pbd import ModelBuilder, Solver, SolverSettings

from tests.anatomy.conftest import LINEAR_STIFFNESS, SPHINCTER_STIFFNESS, icosphere, linear_on, on_sphere, sphincter_on


@pytest.fixture(scope="module")
def sphere():
    return icosphere(3)


@pytest.fixture(scope="module")
def linear(sphere):
    v, f = sphere
    return linear_on("zyg", v, f, [(-0.2, 0.4), (0.0, 0.45), (0.2, 0.4)], [(-0.15, -0.2), (0.15, -0.2)],
                     h=6, w=3, thickness=0.05)


@pytest.fixture(scope="module")
def sphincter(sphere):
    v, f = sphere
    return sphincter_on("oris", v, f, (0.0, -0.3), (0.15, 0.07), (0.32, 0.17))


def simulate(muscle, v, f, c, frames=150, ramp=25):
    b = ModelBuilder()
    first, slots = muscle.add_to_builder(b)
    model = b.finalize()
    state, control = model.state(), model.control()
    solver = Solver(model, SolverSettings())
    for k in range(frames):
        control.position_targets[slots] = muscle.sample_targets(c * min(1.0, (k + 1) / ramp), v, f)
        solver.step(state, state, control, 1 / 25)
    return state.positions[first:first + muscle.n_particles]


# -- network ---------------------------------------------------------------------------

def test_distance_network_counts_and_uniqueness():
    h, w = 6, 4
    net = distance_network(hex_topology(h, w))
    assert len(net["latitudinal_up"]) == h * (w - 1)
    assert len(net["longitudinal_low"]) == (h - 1) * w
    assert len(net["shear_up"]) == 2 * (h - 1) * (w - 1)
    assert len(net["connection"]) == h * w
    allpairs = np.sort(np.concatenate(list(net.values())), axis=1)
    assert len(np.unique(allpairs, axis=0)) == len(allpairs)
    closed = distance_network(hex_topology(h, w, closed=True))
    assert len(closed["longitudinal_up"]) == h * w  # wraps around


def test_bending_quads_cover_every_edge_once(linear):
    q = bending_quads(linear.faces)
    m = trimesh.Trimesh(linear.rest_positions, linear.faces, process=False)
    assert len(q) == len(m.edges_unique)
    assert len(np.unique(np.sort(q[:, :2], axis=1), axis=0)) == len(q)
    with pytest.raises(ValueError, match="more than two"):
        bending_quads(np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]]))


def test_zero_stiffness_kinds_are_not_created(linear):
    assert set(linear.constraints) == {"latitudinal_up", "longitudinal_up", "connection", "bend"}
    b = ModelBuilder()
    linear.add_to_builder(b)
    model = b.finalize()
    assert model.constraint_count == linear.constraint_count()
    with pytest.raises(ValueError, match="unknown muscle stiffness"):
        type(linear)(**{**linear.__dict__, "stiffness": {"lattitude": 1.0}})
    assert set(STIFFNESS_KEYS) >= set(LINEAR_STIFFNESS)


def test_rest_mesh_closed_and_on_its_samples(linear, sphincter, sphere):
    v, f = sphere
    for m in (linear, sphincter):
        mesh = trimesh.Trimesh(m.rest_positions, m.faces, process=False)
        assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
        np.testing.assert_allclose(m.sample_targets(0.0, v, f), m.rest_positions[m.bound], atol=1e-12)
        assert not m.inverted_faces(m.rest_positions, v, f).any()
        # the bottom lies on the sphere, the top one thickness above it
        hw = m.topology.h * m.topology.w
        r = np.linalg.norm(m.rest_positions, axis=1)
        assert np.all(np.abs(r[:hw] - 1) < 0.01)
        assert np.all(np.abs(r[hw:] - 1 - m.thickness) < 0.01)


def test_muscle_build_commutes_with_scaling(sphere):
    """Units are the input's: the same muscle on a 100x larger skull is 100x larger.

    (The muscle is placed off the x = 0 symmetry plane on purpose: its interior bottom
    vertices are projected onto the faceted sphere from slightly inside it, and a point
    exactly under a mesh edge is equidistant from two faces, so round-off picks either.)
    """
    from faceforge.anatomy.muscles.action_line import ActionLine
    from faceforge.anatomy.muscles.muscle import build_linear_muscle

    v, f = sphere
    origin, insertion = [(-0.17, 0.4), (0.23, 0.4)], [(-0.17, 0.0), (0.23, 0.0)]
    a = linear_on("m", v, f, origin, insertion, thickness=0.05)
    o, i = 100 * on_sphere(*origin), 100 * on_sphere(*insertion)
    V = v * 100
    lines = [ActionLine.from_points(p, V, f) for p in (o, i, [o[0], i[0]], [o[-1], i[-1]])]
    b = build_linear_muscle("m", *lines, V, f, 6, 3, 5.0, LINEAR_STIFFNESS)
    np.testing.assert_allclose(b.rest_positions, 100 * a.rest_positions, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(b.sample_targets(0.7, V, f), 100 * a.sample_targets(0.7, v, f), atol=1e-9)


# -- dynamics ----------------------------------------------------------------------------

@pytest.mark.parametrize("which", ["linear", "sphincter"])
def test_rest_is_a_fixed_point(which, linear, sphincter, sphere):
    m = linear if which == "linear" else sphincter
    p = simulate(m, *sphere, c=0.0, frames=200)
    np.testing.assert_allclose(p, m.rest_positions, atol=1e-12)


def test_contraction_shortens_fibres_and_keeps_volume(linear, sphere):
    """c shortens the fibre by c * max_contraction (Eq. 4); volume within 5 %.

    Tolerances: the sample targets meet the request within 2 % (chords of a curved line);
    the simulated bottom fibres A0/A2 within 0.1 of the rest length (measured: they shorten
    0.02 too little at c = 0.3, 0.09 at c = 1), because the soft position constraints
    (k = 0.2) balance the longitudinal (0.1), bending and volume ones.
    """
    v, f = sphere
    rest_len = linear.fibre_lengths(linear.rest_positions)
    rest_vol = signed_volume(linear.rest_positions, linear.faces)
    hw = linear.topology.h * linear.topology.w
    rest_thick = np.linalg.norm(linear.rest_positions[hw:] - linear.rest_positions[:hw], axis=1).mean()
    for c in (0.3, 0.6, 1.0):
        want = 1 - c * linear.max_contraction
        tg = linear.sample_targets(c, v, f)
        g = linear.bound_grid
        grid = np.zeros((linear.topology.h, linear.topology.w, 3))
        grid[g[:, 0], g[:, 1]] = tg
        for j in (0, -1):
            target_len = np.linalg.norm(np.diff(grid[:, j], axis=0), axis=1).sum()
            assert target_len / rest_len[j] == pytest.approx(want, abs=0.02)
        p = simulate(linear, v, f, c)
        ratio = linear.fibre_lengths(p) / rest_len
        assert abs(ratio[0] - want) < 0.1 and abs(ratio[-1] - want) < 0.1
        assert signed_volume(p, linear.faces) / rest_vol == pytest.approx(1.0, abs=0.05)
        thick = np.linalg.norm(p[hw:] - p[:hw], axis=1).mean()
        assert thick > rest_thick  # a shortened muscle bulges
        assert not linear.inverted_faces(p, v, f).any()


def test_interior_bottom_particles_are_bound_and_their_fibres_shorten_like_the_sides(linear, sphere):
    """The interior bottom particles are bound after the contour; their targets keep their
    rest place between the side fibres' samples of their row, so between the interior rows
    every column of the target grid shortens by c * max_contraction like the two side
    fibres (within the 2 % of the chords, as the sides in
    test_contraction_shortens_fibres_and_keeps_volume). (The first and last segments of an
    interior column end on the origin and insertion lines, which are curved: their middle
    samples lie off the chord between the corners, so those two segments do not scale.)"""
    v, f = sphere
    h, w = linear.topology.h, linear.topology.w
    assert len(linear.bound) == 2 * (h + w) - 4 + (h - 2) * (w - 2)
    np.testing.assert_array_equal(linear.bound[: len(linear.topology.contour)], linear.topology.contour)
    g = linear.bound_grid
    assert np.array_equal(linear.bound, linear.topology.bottom(g[:, 0], g[:, 1]))
    rest = linear.rest_positions[: h * w].reshape(h, w, 3)
    rest_len = np.linalg.norm(np.diff(rest[1:-1], axis=0), axis=2).sum(axis=0)
    for c in (0.3, 1.0):
        grid = np.zeros((h, w, 3))
        grid[g[:, 0], g[:, 1]] = linear.sample_targets(c, v, f)
        ratio = np.linalg.norm(np.diff(grid[1:-1], axis=0), axis=2).sum(axis=0) / rest_len
        assert ratio == pytest.approx(np.full(w, 1 - c * linear.max_contraction), abs=0.02)


def test_targets_turn_with_a_rigid_motion_of_the_layer(linear, sphere):
    """Every target, the interior ones (rest offsets kept in their row's frame) included,
    moves with a rigid motion of the layer the muscle lies on."""
    v, f = sphere
    a = 0.7
    R = np.array([[np.cos(a), 0.0, np.sin(a)], [0.0, 1.0, 0.0], [-np.sin(a), 0.0, np.cos(a)]])
    T = np.array([0.3, -1.2, 2.0])
    for c in (0.0, 0.6):
        np.testing.assert_allclose(linear.sample_targets(c, v @ R.T + T, f),
                                   linear.sample_targets(c, v, f) @ R.T + T, atol=1e-12)


def test_contraction_moves_insertion_toward_origin_only(linear, sphere):
    v, f = sphere
    g = linear.bound_grid
    rest = linear.sample_targets(0.0, v, f)
    tg = linear.sample_targets(0.6, v, f)
    origin = g[:, 0] == 0
    np.testing.assert_allclose(tg[origin], rest[origin], atol=1e-12)  # origin fixed
    insertion = g[:, 0] == linear.topology.h - 1
    o = rest[origin].mean(axis=0)
    assert np.all(np.linalg.norm(tg[insertion] - o, axis=1) < np.linalg.norm(rest[insertion] - o, axis=1))


def test_passive_muscle_ignores_contraction(sphere):
    v, f = sphere
    m = linear_on("fat", v, f, [(-0.2, 0.4), (0.2, 0.4)], [(-0.2, 0.0), (0.2, 0.0)], active=False)
    np.testing.assert_array_equal(m.sample_targets(1.0, v, f), m.sample_targets(0.0, v, f))


def test_sphincter_contracts_toward_its_centre(sphincter, sphere):
    v, f = sphere
    inner = sphincter.bound[: sphincter.topology.h]
    o = sphincter.sample_targets(0.0, v, f).mean(axis=0)
    rest_r = np.linalg.norm(sphincter.rest_positions[inner] - o, axis=1)
    vol0 = signed_volume(sphincter.rest_positions, sphincter.faces)
    last = rest_r.mean()
    for c in (0.3, 0.6, 1.0):
        tg = sphincter.sample_targets(c, v, f)
        # targets: every inner sample moved toward the centre, by at most c * max_contraction
        tr = np.linalg.norm(tg[: sphincter.topology.h] - o, axis=1)
        assert np.all(tr < rest_r)
        assert np.all(tr >= (1 - c * sphincter.max_contraction) * rest_r - 1e-9)
        p = simulate(sphincter, v, f, c)
        r = np.linalg.norm(p[inner] - o, axis=1).mean()
        assert r < last
        last = r
        assert signed_volume(p, sphincter.faces) / vol0 == pytest.approx(1.0, abs=0.05)
        assert not sphincter.inverted_faces(p, v, f).any()


def test_fit_ellipse_recovers_axes():
    a, b = 2.0, 0.7
    ang = np.linspace(0, 2 * np.pi, 30, endpoint=False)
    e1 = np.array([1.0, 1.0, 0.0]) / np.sqrt(2)
    e2 = np.array([-1.0, 1.0, 0.5]) / np.linalg.norm([-1.0, 1.0, 0.5])
    e2 -= (e2 @ e1) * e1
    e2 /= np.linalg.norm(e2)
    o = np.array([0.3, -1.0, 2.0])
    pts = o + a * np.cos(ang)[:, None] * e1 + b * np.sin(ang)[:, None] * e2
    c, da, db, fa, fb = fit_ellipse(pts)
    np.testing.assert_allclose(c, o, atol=1e-12)
    assert fa == pytest.approx(a) and fb == pytest.approx(b)
    assert abs(da @ e1) == pytest.approx(1.0) and abs(db @ e2) == pytest.approx(1.0)


def test_sphincter_moves_its_loops_in_the_ellipse_plane():
    """Loops wrapped around a face (a bowl: the lips in front, the corners further back) have
    their mean behind the lips; the contraction moves them toward it within the ellipse's
    plane, not into the head: no component along the plane's normal."""
    ang = np.linspace(0, 2 * np.pi, 20, endpoint=False)
    outer = np.stack([2 * np.cos(ang), np.sin(ang), -0.5 * (2 * np.cos(ang)) ** 2], 1)
    inner = 0.5 * outer
    d = sphincter_displacement(inner, outer, 0.4)
    _, _, vt = np.linalg.svd(np.concatenate([inner, outer]) - np.concatenate([inner, outer]).mean(0))
    np.testing.assert_allclose(d @ vt[2], 0.0, atol=1e-12)
    assert np.abs(d).max() > 0.1


def test_sphincter_displacement_formula():
    """On the fitted ellipse r = 1, so delta = c (o - s1); c = 0 gives no motion."""
    ang = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    ring = np.stack([2 * np.cos(ang), np.sin(ang), np.zeros(16)], 1)
    d0 = sphincter_displacement(0.5 * ring, ring, 0.0)
    np.testing.assert_array_equal(d0, 0.0)
    # inner and outer on one ellipse shape: fit to both, the outer samples sit at r > 1
    d = sphincter_displacement(ring, ring, 0.4)
    np.testing.assert_allclose(d, 0.4 * (0 - ring), atol=1e-9)


def test_sphincter_protrusion_moves_the_loops_along_the_normal():
    """The protrusion drive moves every pair along the ellipse plane's normal, on the side of
    ``forward``, by ``lift b`` times the fall-off (1 on the ellipse), turns the lips out
    (``EVERSION`` times the lift and the sample's height along the minor axis: the upper lip up,
    the lower one down, the corners not at all), and adds to the in-plane contraction
    unchanged; without a lift the contraction has no normal component."""
    from faceforge.anatomy.muscles.sphincter import EVERSION

    ang = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    ring = np.stack([2 * np.cos(ang), np.sin(ang), np.zeros(16)], 1)     # b = 1, in z = 0
    up = np.array([0.0, 0.0, 1.0])
    lift = sphincter_displacement(ring, ring, 0.0, 0.3, up)
    assert EVERSION > 0.0
    out = np.stack([np.zeros(16), 0.3 * EVERSION * ring[:, 1], np.full(16, 0.3)], 1)
    np.testing.assert_allclose(lift, out, atol=1e-9)
    top, bottom, corner = 4, 12, 0                                       # sin = 1, -1, 0
    assert lift[top, 1] > 0.1 and lift[bottom, 1] < -0.1 and abs(lift[corner, 1]) < 1e-9
    back = sphincter_displacement(ring, ring, 0.0, 0.3, -up)            # the other side: still out
    np.testing.assert_allclose(back, lift * [1.0, 1.0, -1.0], atol=1e-12)
    both = sphincter_displacement(ring, ring, 0.4, 0.3, up)
    np.testing.assert_allclose(both, sphincter_displacement(ring, ring, 0.4) + lift, atol=1e-12)
    assert np.array_equal(sphincter_displacement(ring, ring, 0.4, 0.0, None),
                          sphincter_displacement(ring, ring, 0.4))


@pytest.fixture(scope="module")
def protruding(sphincter):
    """The ``sphincter`` fixture with a protrusion (``Muscle.protrusion``)."""
    from dataclasses import replace

    return replace(sphincter, protrusion=0.6)


def test_sphincter_forward_points_away_from_what_it_lies_on(protruding, sphere):
    """``Muscle.forward`` is the unit bottom -> top direction: on the sphere, outward (along
    the sphere's normal at the ring's centre); a full protrusion drive moves every bound
    target along it, and a passive sphincter or a zero ``protrusion`` ignores the drive."""
    from dataclasses import replace

    v, f = sphere
    fw = protruding.forward
    centre = protruding.rest_positions.mean(axis=0)
    assert np.linalg.norm(fw) == pytest.approx(1.0) and fw @ centre / np.linalg.norm(centre) > 0.95
    points = {k: line.positions(v, f) for k, line in protruding.lines.items()}
    rest = protruding.targets_from_line_points(0.0, points)
    moved = protruding.targets_from_line_points(0.0, points, 1.0) - rest
    assert np.all(moved @ fw > 0.5 * np.linalg.norm(moved, axis=1))
    assert np.array_equal(protruding.targets_from_line_points(0.0, points, 2.0) - rest, moved)   # clipped
    for inert in (replace(protruding, active=False), replace(protruding, protrusion=0.0)):
        assert np.array_equal(inert.targets_from_line_points(0.0, points, 1.0), rest)
        assert np.array_equal(inert.targets_from_line_points(0.5, points, 1.0),
                              inert.targets_from_line_points(0.5, points))


@pytest.fixture(scope="module")
def carried(sphincter):
    """The ``sphincter`` fixture with a per-row inner-loop carry (``Muscle.carry_inner``)."""
    from dataclasses import replace

    rows = np.linspace(0.0, 1.0, sphincter.topology.h)
    return replace(sphincter, carry_inner=rows)


@pytest.mark.parametrize("which", ["sphincter", "carried", "protruding"])
def test_compiled_sphincter_targets_match_the_numpy_twin(which, request, sphere):
    """Material sampling: ``targets_from_line_points`` runs the compiled ``_sphincter_grid``;
    its plain twin is ``Muscle._grid_targets`` (numpy, ``fit_ellipse`` by SVD and lstsq);
    with and without ``carry_inner``, and with a protrusion drive."""
    sphincter = request.getfixturevalue(which)
    v, f = sphere
    assert sphincter.rest_parameters
    rng = np.random.default_rng(4)
    g = sphincter.bound_grid
    scale = float(np.ptp(v, axis=0).max())
    for trial in range(8):
        a = rng.normal(size=3)
        rot = trimesh.transformations.rotation_matrix(rng.uniform(0, np.pi), a)[:3, :3]
        now = v @ rot.T * rng.uniform(0.5, 2.0) + rng.normal(size=3)
        now = now + rng.normal(scale=0.01 * trial, size=v.shape)   # and no longer rigid
        points = {k: line.positions(now, f) for k, line in sphincter.lines.items()}
        for c, p in ((0.0, 0.0), (0.2, 0.0), (0.7, 0.0), (1.0, 0.0), (0.0, 0.5), (0.7, 1.0)):
            fast = sphincter.targets_from_line_points(c, points, p)
            twin = sphincter._grid_targets(min(c, 1.0), points, sphincter._lift(p))[g[:, 0], g[:, 1]]
            assert np.allclose(fast, twin, rtol=0.0, atol=1e-12 * scale)
            if p and sphincter.protrusion:
                assert not np.allclose(fast, sphincter.targets_from_line_points(c, points))
            assert c > 0 or p > 0 or np.array_equal(fast, twin)    # the samples alone: same arithmetic


def test_sphincter_carry_inner_rest_and_drag(carried, sphere):
    """``carry_inner``: at rest the targets are the rest particles (the carry builds no offset);
    an inner sample with carry 1 follows its outer sample's displacement, with 0 its own."""
    v, f = sphere
    h = carried.topology.h
    i = np.arange(h)
    b1, b3 = carried.topology.bottom(i, 0), carried.topology.bottom(i, carried.topology.w - 1)
    g = carried.bound_grid
    rest = carried.sample_targets(0.0, v, f)
    np.testing.assert_allclose(rest, carried.rest_positions[carried.bound], atol=1e-12)
    points = {k: line.positions(v, f) for k, line in carried.lines.items()}
    points["A3"] = points["A3"] + [0.0, 0.1, 0.0]           # the outer loop dragged up
    t = carried.targets_from_line_points(0.0, points)
    inner = {int(a): k for k, a in enumerate(g[:, 0]) if g[k, 1] == 0}
    for r in (0, h - 1):
        np.testing.assert_allclose(t[inner[r]] - carried.rest_positions[b1[r]],
                                   [0.0, 0.1 * carried.carry_inner[r], 0.0], atol=1e-12)
    assert np.allclose(t[[k for k in range(len(g)) if g[k, 1] == carried.topology.w - 1]]
                       - carried.rest_positions[b3][g[g[:, 1] == carried.topology.w - 1, 0]], [0.0, 0.1, 0.0])


def test_sphincter_carry_faces_give_per_row_weights(sphere):
    """``build_sphincter_muscle(carry_inner, carry_faces)``: the rest geometry does not change,
    and each inner sample's carry is ``carry_inner`` times its share of the marked faces."""
    v, f = sphere
    plain = sphincter_on("oris", v, f, (0.0, -0.3), (0.15, 0.07), (0.32, 0.17))
    assert plain.carry_inner is None
    from faceforge.anatomy.muscles.muscle import build_sphincter_muscle

    mask = v[f].mean(axis=1)[:, 0] > 0.0                      # the faces on the +x half
    m = build_sphincter_muscle("oris", plain.lines["A1"], plain.lines["A3"], v, f, plain.topology.h,
                               plain.topology.w, plain.thickness, SPHINCTER_STIFFNESS, lies_on=("skull",),
                               layer=1, carry_inner=0.8, carry_faces=mask)
    np.testing.assert_array_equal(m.rest_positions, plain.rest_positions)
    assert m.carry_inner.shape == (plain.topology.h,)
    x = m.rest_positions[m.topology.bottom(np.arange(m.topology.h), 0)][:, 0]
    assert np.all(m.carry_inner[x > 0.05] == 0.8) and np.all(m.carry_inner[x < -0.05] == 0.0)


def test_conic_least_squares_matches_lstsq():
    from faceforge.anatomy.muscles.sphincter import _conic_lstsq

    rng = np.random.default_rng(6)
    for a, b in ((1.0, 1.0), (3.0, 0.5), (0.01, 0.002)):
        t = rng.uniform(0, 2 * np.pi, 40)
        x, y = a * np.cos(t) + rng.normal(scale=0.01 * a, size=40), b * np.sin(t)
        A = np.stack([x * x, 2 * x * y, y * y], 1)
        ref = np.linalg.lstsq(A, np.ones(40), rcond=None)[0]
        assert np.abs(_conic_lstsq(x, y) - ref).max() <= 1e-12 * np.abs(ref).max()   # lstsq's own accuracy


def test_compiled_sphincter_targets_survive_collinear_loops():
    """No conic through collinear samples: the PCA fallback, finite targets (no LinAlgError)."""
    from faceforge.anatomy.muscles.sphincter import _sphincter_grid

    p = np.stack([np.linspace(0.0, 1.0, 6), np.zeros(6), np.zeros(6)], 1)
    seg, t = np.arange(5), np.full(5, 0.5)
    for lift in (0.0, 0.2):
        grid = np.empty((5, 2, 3))
        _sphincter_grid(p, seg, t, p.copy(), seg, t, 0.3, grid, p[:5], p[:5], np.zeros(0), lift,
                        np.array([0.0, 0.0, 1.0]))
        assert np.all(np.isfinite(grid))
