"""pbd.dihedral_limit: the unilateral dihedral limit and its plain-numpy twin."""

import numpy as np
import pytest

from faceforge.pbd.constraints.bending import dihedral_angle
from faceforge.pbd.dihedral_limit import limit_dihedrals


def twin_limit(p, quads, limit, sweeps=2, w=None, tol=0.0):
    """Plain numpy: turn both wings of a quad about its edge, apart, by half the excess
    (Rodrigues' rotation), quad after quad; with inverse masses ``w (n,)``, each wing by the
    share of the excess its opposite vertex's ``w`` has of the two (none when both are 0); an
    excess up to ``tol`` is left."""
    p = np.array(p, dtype=float)
    w = np.ones(len(p)) if w is None else np.asarray(w, dtype=float)
    for _ in range(sweeps):
        for i0, i1, i2, i3 in np.asarray(quads):
            if w[i2] + w[i3] <= 0:
                continue
            a = p[i1] - p[i0]
            a = a / np.linalg.norm(a)
            w2 = (p[i2] - p[i0]) - a * np.dot(a, p[i2] - p[i0])
            w3 = (p[i3] - p[i0]) - a * np.dot(a, p[i3] - p[i0])
            u2, u3 = w2 / np.linalg.norm(w2), w3 / np.linalg.norm(w3)
            phi = np.arccos(np.clip(np.dot(u2, u3), -1, 1))
            excess = (np.pi - limit) - phi
            if excess <= tol:
                continue
            # the sign that turns each wing away from the other
            s3 = -1.0 if np.dot(u2, np.cross(a, u3)) >= 0 else 1.0
            s2 = -1.0 if np.dot(u3, np.cross(a, u2)) > 0 else 1.0
            for i, s in ((i3, s3), (i2, s2)):
                if w[i] == 0:
                    continue
                t = s * excess * w[i] / (w[i2] + w[i3])
                r = p[i] - p[i0]
                p[i] = p[i0] + r * np.cos(t) + np.cross(a, r) * np.sin(t) + a * np.dot(a, r) * (1 - np.cos(t))
    return p


def folded_quad(theta):
    """Edge (0, 1) on the x axis, wing 2 flat along -y, wing 3 turned by theta out of the plane."""
    return np.array([[0.0, 0, 0], [1.0, 0, 0], [0.4, -1.0, 0.0],
                     [0.6, np.cos(theta), np.sin(theta)]]), np.array([[0, 1, 2, 3]])


@pytest.mark.parametrize("theta", [2.0, 2.6, 3.0, -2.8])
def test_a_quad_folded_past_the_limit_comes_back_to_it_with_its_edges_kept(theta):
    p, q = folded_quad(theta)
    assert abs(dihedral_angle(p, q)[0]) > np.radians(90)
    before = np.linalg.norm(p[:, None] - p[None], axis=2)
    x = p.copy()
    assert limit_dihedrals(x, q, np.radians(75)) >= 1
    assert abs(dihedral_angle(x, q)[0]) == pytest.approx(np.radians(75), abs=1e-9)
    after = np.linalg.norm(x[:, None] - x[None], axis=2)
    # the four edges of the two triangles and the shared edge keep their lengths
    for i, j in ((0, 1), (0, 2), (1, 2), (0, 3), (1, 3)):
        assert after[i, j] == pytest.approx(before[i, j], abs=1e-12)
    np.testing.assert_allclose(x[:2], p[:2])     # the edge does not move
    np.testing.assert_allclose(x, twin_limit(p, q, np.radians(75)), atol=1e-12)


def test_a_quad_within_the_limit_does_not_move():
    p, q = folded_quad(1.0)      # 57 deg
    x = p.copy()
    assert limit_dihedrals(x, q, np.radians(75)) == 0
    np.testing.assert_array_equal(x, p)


def crumpled_strip(rng):
    """A 5 x 3 grid of points jittered out of its plane, and its eight quads ((i+1, j), (i, j+1)
    the diagonal, opposite (i, j) and (i+1, j+1))."""
    g = np.stack(np.meshgrid(np.arange(5.0), np.arange(3.0), indexing="ij"), -1).reshape(-1, 2)
    p = np.c_[g, np.zeros(len(g))] + rng.normal(0, 0.6, (len(g), 3))
    idx = np.arange(15).reshape(5, 3)
    return p, np.array([[idx[i + 1, j], idx[i, j + 1], idx[i, j], idx[i + 1, j + 1]]
                        for i in range(4) for j in range(2)])


def test_kernel_matches_the_twin_on_a_crumpled_strip():
    rng = np.random.default_rng(3)
    p, quads = crumpled_strip(rng)
    x = p.copy()
    limit_dihedrals(x, quads, np.radians(80), sweeps=3)
    np.testing.assert_allclose(x, twin_limit(p, quads, np.radians(80), 3), atol=1e-10)


def test_bad_arguments_are_refused():
    p, q = folded_quad(2.0)
    with pytest.raises(ValueError):
        limit_dihedrals(p, q, 0.0)
    with pytest.raises(ValueError):
        limit_dihedrals(p, q + 5, 1.0)
    with pytest.raises(ValueError):
        limit_dihedrals(p, q, 1.0, inv_mass=np.ones(3))
    with pytest.raises(ValueError):
        limit_dihedrals(p, q, 1.0, inv_mass=-np.ones(4))


@pytest.mark.parametrize("pinned", [2, 3])
def test_a_pinned_particle_stays_and_the_other_wing_turns_by_the_whole_excess(pinned):
    """inv_mass 0 at one opposite vertex: it does not move, the quad still comes back to the limit
    with its edges kept; with both opposite vertices pinned nothing moves."""
    p, q = folded_quad(2.8)
    w = np.ones(4)
    w[pinned] = 0.0
    x = p.copy()
    assert limit_dihedrals(x, q, np.radians(75), inv_mass=w) == 1
    np.testing.assert_array_equal(x[[0, 1, pinned]], p[[0, 1, pinned]])
    assert abs(dihedral_angle(x, q)[0]) == pytest.approx(np.radians(75), abs=1e-9)
    for i, j in ((0, 2), (1, 2), (0, 3), (1, 3)):
        assert np.linalg.norm(x[i] - x[j]) == pytest.approx(np.linalg.norm(p[i] - p[j]), abs=1e-12)
    np.testing.assert_allclose(x, twin_limit(p, q, np.radians(75), 1, w), atol=1e-12)
    y = p.copy()
    assert limit_dihedrals(y, q, np.radians(75), inv_mass=np.array([1.0, 1.0, 0.0, 0.0])) == 0
    np.testing.assert_array_equal(y, p)


def test_equal_masses_are_the_unweighted_projection_bit_for_bit():
    p, q = folded_quad(2.6)
    a, b = p.copy(), p.copy()
    limit_dihedrals(a, q, np.radians(75))
    limit_dihedrals(b, q, np.radians(75), inv_mass=np.full(4, 1.0))
    np.testing.assert_array_equal(a, b)


def test_weighted_kernel_matches_the_twin_on_a_crumpled_strip():
    rng = np.random.default_rng(5)
    p, quads = crumpled_strip(rng)
    w = rng.uniform(0.0, 2.0, len(p))
    w[[0, 7, 9]] = 0.0
    x = p.copy()
    assert limit_dihedrals(x, quads, np.radians(80), sweeps=3, inv_mass=w) > 0
    np.testing.assert_allclose(x, twin_limit(p, quads, np.radians(80), 3, w), atol=1e-10)
    np.testing.assert_array_equal(x[[0, 7, 9]], p[[0, 7, 9]])


def test_a_quad_bent_past_the_limit_at_rest_keeps_its_rest_angle():
    """rest_limits: a quad bent 120 deg at rest may stay so (the rest is a fixed point); bent
    further it comes back to 120, not to the limit."""
    from faceforge.pbd.dihedral_limit import rest_limits

    p, q = folded_quad(np.radians(120))
    lim = rest_limits(p, q, np.radians(75))
    assert np.degrees(lim[0]) == pytest.approx(120)
    x = p.copy()
    assert limit_dihedrals(x, q, lim) == 0
    np.testing.assert_array_equal(x, p)
    y, _ = folded_quad(np.radians(150))
    limit_dihedrals(y, q, lim)
    assert np.degrees(abs(dihedral_angle(y, q)[0])) == pytest.approx(120)


def test_touched_marks_the_particles_that_moved():
    """``touched``: set where a particle moved, never cleared, and the positions are those of a
    call without it; a quad within its limit marks nothing."""
    rng = np.random.default_rng(7)
    p, quads = crumpled_strip(rng)
    w = np.ones(len(p))
    w[4] = 0.0
    x, y = p.copy(), p.copy()
    touched = np.zeros(len(p), dtype=bool)
    touched[0] = True
    limit_dihedrals(x, quads, np.radians(80), sweeps=3, inv_mass=w, touched=touched)
    limit_dihedrals(y, quads, np.radians(80), sweeps=3, inv_mass=w)
    np.testing.assert_array_equal(x, y)
    moved = np.any(x != p, axis=1)
    assert moved.any()
    np.testing.assert_array_equal(touched[1:], moved[1:])
    assert touched[0] and not touched[4]
    q, one = folded_quad(1.0)
    none = np.zeros(4, dtype=bool)
    assert limit_dihedrals(q, one, np.radians(75), touched=none) == 0 and not none.any()
    with pytest.raises(ValueError):
        limit_dihedrals(q, one, 1.0, touched=np.zeros(3, dtype=bool))


def test_a_tolerance_leaves_small_excesses_and_matches_the_twin():
    """tol: a quad past its limit by less than tol stays; the rest come back to the limit, as the
    twin does."""
    p, q = folded_quad(np.radians(75) + 0.002)    # 0.002 rad past 75 deg
    x = p.copy()
    assert limit_dihedrals(x, q, np.radians(75), tol=0.005) == 0
    np.testing.assert_array_equal(x, p)
    assert limit_dihedrals(x, q, np.radians(75), tol=0.001) == 1
    rng = np.random.default_rng(11)
    p, quads = crumpled_strip(rng)
    x = p.copy()
    limit_dihedrals(x, quads, np.radians(80), sweeps=3, tol=0.05)
    np.testing.assert_allclose(x, twin_limit(p, quads, np.radians(80), 3, tol=0.05), atol=1e-10)
    with pytest.raises(ValueError):
        limit_dihedrals(p, quads, 1.0, tol=-1.0)


def test_an_incremental_limit_is_a_full_pass_bit_for_bit_and_checks_only_what_moved():
    """``DihedralLimit(incremental=True)``, applied again and again to positions of which a few
    particles move between calls (as the skin's guards do within a frame), gives the full pass's
    positions, counts and touched particles bit for bit, and checks again only the quads of
    what moved."""
    from faceforge.pbd.dihedral_limit import DihedralLimit

    rng = np.random.default_rng(5)
    g = np.stack(np.meshgrid(np.arange(30.0), np.arange(30.0), indexing="ij"), -1).reshape(-1, 2)
    p = np.c_[g, np.zeros(len(g))] + rng.normal(0, 0.3, (len(g), 3))
    idx = np.arange(900).reshape(30, 30)
    quads = np.array([[idx[i + 1, j], idx[i, j + 1], idx[i, j], idx[i + 1, j + 1]]
                      for i in range(29) for j in range(29)])
    w = np.ones(len(p))
    w[::37] = 0.0
    full = DihedralLimit(quads, np.radians(60), len(p), inv_mass=w, tol=1e-3)
    inc = DihedralLimit(quads, np.radians(60), len(p), inv_mass=w, tol=1e-3, incremental=True)
    x, y = p.copy(), p.copy()
    checked = []
    for call in range(12):
        tx, ty = np.zeros(len(p), bool), np.zeros(len(p), bool)
        before = inc.checked
        assert full(x, sweeps=2, touched=tx) == inc(y, sweeps=2, touched=ty)
        checked.append(inc.checked - before)
        np.testing.assert_array_equal(x.view(np.int64), y.view(np.int64))
        np.testing.assert_array_equal(tx, ty)
        some = rng.choice(len(p), 3, replace=False)        # a few particles move between calls
        kick = rng.normal(0, 0.5, (3, 3))
        x[some] += kick
        y[some] += kick
    assert checked[0] >= len(quads)                        # the first call checks them all
    assert np.mean(checked[4:]) < len(quads) / 4          # later ones what moved and round it (a full
    # pass: len(quads) a sweep)
    assert full.checked == 0


@pytest.mark.parametrize("incremental", [False, True])
def test_set_limit_holds_the_quads_to_the_new_limit(incremental):
    """A quad bent 115 deg: a limit raised past it leaves it; lowered again to 75, the next pass brings it
    back to 75 (an incremental limit checks it again though none of its particles moved)."""
    from faceforge.pbd.dihedral_limit import DihedralLimit

    p, q = folded_quad(np.radians(115))
    lim = DihedralLimit(q, np.radians(75), 4, incremental=incremental)
    lim.set_limit(np.radians(120))
    x = p.copy()
    assert lim(x) == 0
    np.testing.assert_array_equal(x, p)
    lim.set_limit(np.radians(75))
    assert lim(x) >= 1
    assert abs(dihedral_angle(x, q)[0]) == pytest.approx(np.radians(75), abs=1e-9)
    with pytest.raises(ValueError):
        lim.set_limit(np.radians(180))
