"""fit_orbits: a modelled eye socket is kept free of bone by a map that cannot fold."""

import numpy as np
import pytest
import trimesh

from faceforge.fit.surface import SkinSurface
from faceforge.fit.orbits import (REACH_SLACK, OrbitHollow, chord_sag, fibonacci_directions, find_hollow,
                                  fit_hollow,
                                  radial_profile)
from faceforge.geometry.rays import RayCaster
from faceforge.geometry.triangles import vertex_normals


def surface(vertices, faces) -> SkinSurface:
    """A SkinSurface of exactly this mesh (no hole filling, no reorientation)."""
    v, f = np.asarray(vertices, float), np.asarray(faces, np.int64)
    return SkinSurface(v, f, vertex_normals(v, f), float(np.linalg.norm(np.ptp(v, axis=0))), RayCaster(v, f),
                       np.zeros(0, np.int64), len(v))


@pytest.fixture(scope="module")
def socket():
    """A spherical pocket of radius 1 at the origin, its skin facing the inside (a socket lining)."""
    s = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    return surface(s.vertices, s.faces[:, ::-1])


def plate(z: float, half: float = 1.6, n: int = 33):
    """A flat grid (vertices, faces) at height z: a bone wall cutting through the pocket."""
    x, y = np.meshgrid(np.linspace(-half, half, n), np.linspace(-half, half, n))
    v = np.stack([x.ravel(), y.ravel(), np.full(x.size, z)], axis=1)
    i = np.arange(n * n).reshape(n, n)
    a, b, c, d = i[:-1, :-1].ravel(), i[:-1, 1:].ravel(), i[1:, :-1].ravel(), i[1:, 1:].ravel()
    return v, np.vstack([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])


def test_profile_is_increasing_reaches_one_at_lam_and_is_identity_beyond_the_blend():
    rho = np.linspace(0.0, 2.0, 2001)
    for lam, beta in ((0.1, 0.5), (0.6, 0.5), (0.9, 0.2)):
        f = radial_profile(rho, lam, beta)
        assert np.all(np.diff(f) > 0.0)
        assert np.isclose(radial_profile(np.array([lam]), lam, beta)[0], 1.0)
        assert np.array_equal(f[rho > 1.0 + beta], rho[rho > 1.0 + beta])
        assert np.all(f[rho >= lam] >= 1.0 - 1e-12)


def test_a_socket_is_found_and_a_closed_head_without_one_is_not(socket):
    h = find_hollow(socket, np.array([[0.0, 0.0, 0.3]]), clearance=0.01, max_radius=2.0)
    assert h is not None and np.allclose(h.centre, [0.0, 0.0, 0.3])
    s = trimesh.creation.icosphere(subdivisions=3, radius=1.0)     # skin facing out: a head, no socket
    assert find_hollow(surface(s.vertices, s.faces), np.array([[0.0, 0.0, 0.3]]), 0.01, 2.0) is None
    # a centre whose rays mostly leave the skin within max_radius is no hollow either
    assert find_hollow(socket, np.array([[0.0, 0.0, 0.0]]), 0.01, 0.5) is None


def test_bone_cutting_through_the_socket_ends_outside_without_folding(socket):
    h = find_hollow(socket, np.array([[0.0, 0.0, 0.0]]), clearance=0.02, max_radius=2.0)
    v, f = plate(-0.4)
    h = h.fitted(v)
    assert 0.0 < h.lam < 1.0
    moved = h(v)
    r, _, big_t = h.radius(moved)
    assert np.all(r >= big_t)                                      # clearance beyond the socket skin
    far = np.linalg.norm(v, axis=1) > (1.0 + h.beta) * 1.02 + 1e-9
    assert far.any() and np.array_equal(moved[far], v[far])        # nothing moves beyond the blend
    # one-to-one along each ray: order by distance from the centre is kept for collinear points
    u = np.array([[0.3, -0.2, -0.9]]) / np.linalg.norm([0.3, -0.2, -0.9])
    line = u * np.linspace(0.05, 2.0, 200)[:, None]
    out = np.linalg.norm(h(line), axis=1)
    assert np.all(np.diff(out) > 0.0)
    # the moved plate does not cross itself: no edge passes through a face it does not touch
    mesh = RayCaster(moved, f)
    e = np.unique(np.sort(np.vstack([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1), axis=0)
    o, d = moved[e[:, 0]], moved[e[:, 1]] - moved[e[:, 0]]
    length = np.linalg.norm(d, axis=1)
    ray, tri, _, t = mesh.all_hits(o, d / length[:, None])
    crossing = (t > 1e-9 * length[ray]) & (t < (1 - 1e-9) * length[ray])
    crossing &= ~(f[tri] == e[ray, 0][:, None]).any(1) & ~(f[tri] == e[ray, 1][:, None]).any(1)
    assert not crossing.any()


def test_a_hollow_with_nothing_inside_moves_nothing(socket):
    h = find_hollow(socket, np.array([[0.0, 0.0, 0.0]]), clearance=0.02, max_radius=2.0)
    v, _ = plate(-1.3)
    h = h.fitted(v)
    assert h.lam == 1.0
    assert np.array_equal(h(v), v)


def test_fibonacci_directions_are_unit_and_spread():
    d = fibonacci_directions(200)
    assert np.allclose(np.linalg.norm(d, axis=1), 1.0)
    assert np.allclose(d.mean(axis=0), 0.0, atol=0.02)


def test_the_inside_query_agrees_with_the_socket_radius(socket):
    h = OrbitHollow(np.zeros(3), socket.caster, 0.05, 1.0)
    pts = np.array([[0.0, 0.0, 0.5], [0.0, 0.0, 1.03], [0.0, 0.0, 1.06], [0.0, 0.9, 0.0]])
    assert h.inside(pts).tolist() == [True, True, False, True]


def test_the_chord_margin_covers_the_sag_of_the_longest_nearby_edge(socket):
    h = find_hollow(socket, np.array([[0.0, 0.0, 0.0]]), clearance=0.02, max_radius=2.0)
    v, f = plate(-0.4, n=9)                                        # sides 0.4, diagonals 0.4 sqrt(2)
    wide = h.with_chord_margin(v, f)
    assert np.isclose(wide.clearance - h.clearance, chord_sag(0.4 * np.sqrt(2.0), h.socket_radius), rtol=1e-9)
    assert np.isclose(chord_sag(0.4 * np.sqrt(2.0), 1.0), 1.0 - np.sqrt(1.0 - 0.08), rtol=1e-12)
    assert 0.95 < h.socket_radius <= 1.0                           # the icosphere's faces lie inside r = 1
    # after the map with the margin measured on the mapped plate, no point of any face of
    # the plate is inside the socket
    moved = fit_hollow(h, v, f)(v)
    w = np.random.default_rng(0).dirichlet(np.ones(3), size=(len(f), 20))
    inner = np.einsum("fkc,fcd->fkd", w, moved[f]).reshape(-1, 3)
    assert not h.inside(inner).any()


def test_chord_sag_is_bounded_by_the_radius():
    """The small-chord formula L^2 / 8R grows without bound: an edge four socket radii long
    asked for a clearance ten times the socket and blew the skull into a sphere (issue 28)."""
    assert np.isclose(chord_sag(0.01, 1.0), 0.01 ** 2 / 8.0, rtol=1e-4)
    assert chord_sag(2.0, 1.0) == 1.0
    assert chord_sag(40.0, 1.0) == 1.0


def test_the_map_ignores_skin_beyond_the_reach_of_the_socket(socket):
    """A ray leaving the pocket meets skin far away (the back of the head): that is no
    constraint, and bone in that direction does not move by a head's size."""
    h = OrbitHollow(np.zeros(3), socket.caster, 0.02, 0.4, lam=0.5)
    r, _, big_t = h.radius(np.array([[0.0, 0.0, 0.3]]))
    assert not np.isfinite(big_t).any()           # the socket wall (r = 1) lies beyond 1.5 x 0.4
    h = OrbitHollow(np.zeros(3), socket.caster, 0.02, 1.0 / REACH_SLACK + 0.01, lam=0.5)
    _, _, big_t = h.radius(np.array([[0.0, 0.0, 0.3]]))
    assert np.isfinite(big_t).all()


def test_a_ray_that_meets_the_skin_from_inside_puts_no_bound_on_the_bone(socket):
    """From the centre a ray that meets the skin from inside leaves the head (it sees flesh,
    not the socket): bone that way stays. Bounding it by the skin pushed bone out through
    the lids (issue 28, MakeHuman with detected eye corners)."""
    h = find_hollow(socket, np.array([[0.0, 0.0, 0.0]]), clearance=0.02, max_radius=2.0)
    assert h.face_normal is not None
    _, _, big_t = h.radius(np.array([[0.0, 0.0, 0.3], [0.3, 0.0, 0.0]]))
    assert np.isfinite(big_t).all()                      # the lining faces the centre: a bound
    s = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    head = surface(s.vertices, s.faces)                  # skin facing out: rays leave the head
    tri = head.vertices[head.faces]
    out = OrbitHollow(np.zeros(3), head.caster, 0.02, 1.0, lam=0.5,
                      face_normal=np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]),
                      fan_face=np.zeros(len(head.faces), bool))
    _, _, big_t = out.radius(np.array([[0.0, 0.0, 0.3], [0.3, 0.0, 0.0]]))
    assert not np.isfinite(big_t).any()
    bone = np.array([[0.0, 0.0, 0.5], [0.0, 0.6, 0.0]])
    assert np.array_equal(out(bone), bone) and not out.inside(bone).any()
