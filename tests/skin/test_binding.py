"""Ray-cast binding (§8) on nested synthetic spheres."""

import numpy as np
import pytest

from faceforge.skin.binding import CRANIUM, MANDIBLE, MUSCLE, UNBOUND, Body, InsertionRegions, bind_skin
from tests.skin.synthetic import sphere


def _cap(radius, zmin, subdivisions=3):
    """The part of a sphere above z = zmin * radius (an open muscle sheet)."""
    v, f = sphere(radius, subdivisions)
    keep = (v[f][:, :, 2] > zmin * radius).all(axis=1)
    return v, f[keep]


@pytest.fixture(scope="module")
def skin():
    return sphere(1.0, 2)


def test_inward_rays_bind_to_muscle_over_skull(skin):
    v, f = skin
    muscle = Body("m", "muscle", *_cap(0.9, 0.3))
    skull = Body("cranium", "cranium", *sphere(0.8, 3))
    b = bind_skin(v, f, [muscle, skull], max_distance=0.5)
    assert np.all(b.status != UNBOUND)  # every ray meets the skull sphere at 0.2
    over = v[:, 2] > 0.5  # well inside the cap's shadow
    assert np.all(b.status[over] == MUSCLE)
    assert np.all(b.status[v[:, 2] < 0.2] == CRANIUM)
    np.testing.assert_allclose(b.distance[b.body == 0], 0.1, atol=0.01)
    np.testing.assert_allclose(b.distance[b.body == 1], 0.2, atol=0.01)
    assert not b.outward.any()
    # hits lie on the body surfaces: |point| = that body's radius (up to facets)
    r = np.linalg.norm(b.points, axis=1)
    assert np.all(np.abs(r - np.where(b.body == 0, 0.9, 0.8)) < 0.01)


def test_outward_muscle_wins_first(skin):
    v, f = skin
    outer = Body("outer", "muscle", *_cap(1.1, 0.6))
    inner = Body("inner", "muscle", *_cap(0.9, 0.0))
    b = bind_skin(v, f, [outer, inner], max_distance=0.5)
    top = b.vertex_ids[v[b.vertex_ids, 2] > 0.75]
    sel = np.isin(b.vertex_ids, top)
    assert len(top) and np.all(b.body[sel] == 0) and np.all(b.outward[sel])


def test_muscle_order_not_distance_decides(skin):
    v, f = skin
    near = Body("near", "muscle", *_cap(0.9, 0.3))
    far = Body("far", "muscle", *_cap(0.7, 0.3))
    # listed superficial first: "far" is declared the most superficial, so it wins
    b = bind_skin(v, f, [far, near], max_distance=0.5)
    top = v[b.vertex_ids, 2] > 0.6
    assert np.all(b.body[top] == 0)
    b2 = bind_skin(v, f, [near, far], max_distance=0.5)
    assert np.all(b2.body[v[b2.vertex_ids, 2] > 0.6] == 0)
    assert b2.body_names[0] == "near"


def test_rays_beyond_max_distance_miss(skin):
    v, f = skin
    skull = Body("cranium", "cranium", *sphere(0.5, 2))
    b = bind_skin(v, f, [skull], max_distance=0.3)
    assert np.all(b.status == UNBOUND) and len(b.vertex_ids) == 0
    b = bind_skin(v, f, [skull], max_distance=0.6)
    assert np.all(b.status == CRANIUM)


def test_lip_sides_pick_cranium_or_mandible(skin):
    v, f = skin
    cranium = Body("cranium", "cranium", *sphere(0.8, 3))
    mandible = Body("mandible", "mandible", *sphere(0.9, 3))
    sides = np.zeros(len(v), int)
    sides[: len(v) // 2] = 1
    sides[len(v) // 2:] = -1
    b = bind_skin(v, f, [cranium, mandible], max_distance=0.5, lip_sides=sides)
    assert np.all(b.status[sides > 0] == CRANIUM)
    assert np.all(b.status[sides < 0] == MANDIBLE)
    # without sides the nearer (mandible) wins everywhere
    b = bind_skin(v, f, [cranium, mandible], max_distance=0.5)
    assert np.all(b.status == MANDIBLE)


def test_targets_round_trip_and_follow_rigid_motion(skin):
    v, f = skin
    muscle = Body("m", "muscle", *_cap(0.9, 0.3))
    skull = Body("cranium", "cranium", *sphere(0.8, 3))
    b = bind_skin(v, f, [muscle, skull], max_distance=0.5)
    rest = b.targets([(muscle.vertices, muscle.faces), (skull.vertices, skull.faces)])
    np.testing.assert_allclose(rest, b.points, atol=1e-12)
    shift = np.array([0.1, -0.2, 0.3])
    moved = b.targets([(muscle.vertices + shift, muscle.faces), (skull.vertices, skull.faces)])
    d = moved - b.points
    np.testing.assert_allclose(d[b.body == 0], np.broadcast_to(shift, d[b.body == 0].shape), atol=1e-12)
    np.testing.assert_allclose(d[b.body == 1], 0.0, atol=1e-12)


def test_arrays_round_trip(skin):
    from faceforge.skin.binding import Binding

    v, f = skin
    b = bind_skin(v, f, [Body("cranium", "cranium", *sphere(0.8, 2))], max_distance=0.5)
    again = Binding.from_arrays({"anchor_" + k if k not in ("status", "normals", "body_names") else k: a
                                 for k, a in b.as_arrays().items()})
    for key, a in b.as_arrays().items():
        np.testing.assert_array_equal(getattr(again, key), a)


def test_side_of_drops_hits_across_the_lip_line(skin):
    v, f = skin
    muscle = Body("ring", "muscle", *sphere(0.9, 3))
    sides = np.where(v[:, 1] >= 0, 1, -1)

    def side_of(points):  # the "lip line" is y = 0.3: hits above it are "upper"
        return np.where(points[:, 1] >= 0.3, 1, -1)

    b = bind_skin(v, f, [muscle], max_distance=0.5, lip_sides=sides, side_of=side_of, fallback=False)
    bound = b.vertex_ids
    hit_side = side_of(b.points)
    assert np.all(hit_side * sides[bound] >= 0)
    # vertices in 0 <= y < 0.3 (upper side, hits below the line) are left unbound by the rays
    band = (v[:, 1] >= 0) & (v[:, 1] < 0.3 * 0.9)
    assert band.any() and np.all(b.status[band] == UNBOUND)
    # the closest-point fallback binds them to the muscle's own (upper) half: its faces
    # above the line, at their lower edge
    from faceforge.skin.mouth import AROUND_MOUTH

    b = bind_skin(v, f, [muscle], max_distance=0.5, lip_sides=sides, side_of=side_of,
                  body_sides=[AROUND_MOUTH])
    sel = np.isin(b.vertex_ids, np.flatnonzero(band))
    assert np.all(b.status[band] == MUSCLE) and np.all(b.closest[sel])
    centroids = muscle.vertices[muscle.faces[b.face_ids[sel]]].mean(axis=1)
    assert np.all(side_of(centroids) == 1)


def test_face_sides_decide_a_rings_half_instead_of_the_lip_line(skin):
    """With ``face_sides`` (a ring's rows, mouth.ring_face_sides) a lip vertex binds only to
    the faces labelled with its own lip, by ray or by closest point, wherever they lie."""
    from faceforge.skin.mouth import AROUND_MOUTH

    v, f = skin
    muscle = Body("ring", "muscle", *sphere(0.9, 3))
    sides = np.where(v[:, 1] >= 0, 1, -1)

    def side_of(points):  # the "lip line" is y = 0.3
        return np.where(points[:, 1] >= 0.3, 1, -1)

    centroids = muscle.vertices[muscle.faces].mean(axis=1)
    # the rows' labels disagree with the line: the band 0 <= y < 0.3 belongs to the upper lip
    labels = np.where(centroids[:, 1] >= 0.0, 1, -1).astype(np.int8)
    b = bind_skin(v, f, [muscle], max_distance=0.5, lip_sides=sides, side_of=side_of,
                  body_sides=[AROUND_MOUTH], face_sides=[labels])
    on = b.body == 0
    assert on.any()
    assert np.all(labels[b.face_ids[on]] == sides[b.vertex_ids[on]])
    band = (v[:, 1] >= 0) & (v[:, 1] < 0.25)       # unbound by their rays under the line rule
    sel = np.isin(b.vertex_ids, np.flatnonzero(band))
    assert band.any() and np.all(b.status[band] == MUSCLE)
    assert np.mean(b.closest[sel]) < 0.5               # mostly by their own rays now
    # all faces labelled lower: no upper-lip vertex binds to the ring at all
    lower = np.full(len(muscle.faces), -1, np.int8)
    b = bind_skin(v, f, [muscle], max_distance=0.5, lip_sides=sides, side_of=side_of,
                  body_sides=[AROUND_MOUTH], face_sides=[lower])
    assert not np.any(sides[b.vertex_ids[b.body == 0]] == 1)
    assert np.any(sides[b.vertex_ids[b.body == 0]] == -1)


def test_rays_into_a_hole_fall_back_to_the_closest_skull_point(skin):
    v, f = skin
    sv, sf = sphere(0.8, 3)
    hole = (sv[sf][:, :, 2] > 0.6).any(axis=1)  # an "orbit": no bone over the front cap
    skull = Body("cranium", "cranium", sv, sf[~hole])
    b = bind_skin(v, f, [skull], max_distance=0.8)
    over = v[:, 2] > 0.85  # their rays pass through the hole and the far wall is 1.8 away
    assert over.any() and np.all(b.status[over] == CRANIUM)
    sel = np.isin(b.vertex_ids, np.flatnonzero(over))
    assert np.all(b.closest[sel])
    # only vertices looking into the (jagged-edged) hole needed the fallback
    assert np.all(v[b.vertex_ids[b.closest], 2] > 0.6)
    # the fallback anchor is the nearest bone point: on the rim, within max_distance
    assert np.all(b.distance[sel] <= 0.8) and np.all(b.points[sel, 2] <= 0.6 + 1e-9)
    near = np.linalg.norm(b.points[sel][:, None] - sv[None], axis=2).min(axis=1)
    assert np.all(near < 0.2)  # on the bone that is left, by the rim


def test_lip_vertices_whose_rays_miss_fall_back_to_their_own_half_of_a_muscle(skin):
    """A lip vertex whose rays miss binds to the nearer of its own jaw's bone and its own
    side of a muscle around the mouth (never the other side's); non-lip vertices still fall
    back to bone only."""
    v, f = skin
    sv, sf = sphere(0.8, 3)
    hole = (sv[sf][:, :, 2] > 0.6).any(axis=1)
    skull = Body("cranium", "cranium", sv, sf[~hole])
    jaw = Body("mandible", "mandible", sv, sf[~hole])
    mv, mf = sphere(0.7, 3)                          # a "ring" muscle behind the hole, nearer than the rim
    ring = Body("ring", "muscle", mv, mf[(mv[mf][:, :, 2] > 0.6).all(axis=1)])
    sides = np.where(v[:, 0] > 0.2, 1, np.where(v[:, 0] < -0.2, -1, 0))

    def side_of(points):
        return np.where(points[:, 0] >= 0.0, 1, -1)

    b = bind_skin(v, f, [ring, skull, jaw], max_distance=0.8, lip_sides=sides, side_of=side_of)
    lips = b.closest & (sides[b.vertex_ids] != 0)
    on_ring = lips & (b.body == 0)
    assert on_ring.any()
    assert np.all(side_of(b.points[on_ring]) == sides[b.vertex_ids[on_ring]])
    assert np.all(b.body[b.closest & (sides[b.vertex_ids] == 0)] != 0)


def test_insertions_add_a_second_anchor_through_the_muscle_above(skin):
    """Skin bound to a superficial muscle whose ray also meets a deeper muscle listed in
    ``insertions`` gets a second anchor on it; other vertices keep their one anchor."""
    v, f = skin
    top = Body("frontalis", "muscle", *_cap(0.9, 0.3))
    deep = Body("depressor", "muscle", *_cap(0.85, 0.6))
    skull = Body("cranium", "cranium", *sphere(0.8, 3))
    plain = bind_skin(v, f, [top, deep, skull], max_distance=0.5)
    b = bind_skin(v, f, [top, deep, skull], max_distance=0.5, insertions=[1])
    np.testing.assert_array_equal(b.status, plain.status)      # the first anchors are the same
    first = np.r_[True, b.vertex_ids[1:] != b.vertex_ids[:-1]]
    np.testing.assert_array_equal(b.vertex_ids[first], plain.vertex_ids)
    np.testing.assert_array_equal(b.body[first], plain.body)
    assert np.all(np.diff(b.vertex_ids) >= 0)
    second = ~first
    over = np.flatnonzero(v[:, 2] > 0.75)            # well inside the deep cap's shadow
    assert set(over) <= set(b.vertex_ids[second])
    assert np.all(b.body[second] == 1) and np.all(b.body[first][np.isin(plain.vertex_ids, over)] == 0)
    assert np.all(v[b.vertex_ids[second], 2] > 0.5)  # only where the deep muscle lies under the skin
    np.testing.assert_allclose(b.distance[second], 0.15, atol=0.01)
    np.testing.assert_allclose(np.linalg.norm(b.points[second], axis=1), 0.85, atol=0.01)
    # the targets of both anchors follow their own bodies
    shift = np.array([0.0, -0.1, 0.0])
    moved = b.targets([(top.vertices, top.faces), (deep.vertices + shift, deep.faces),
                       (skull.vertices, skull.faces)])
    np.testing.assert_allclose(moved[second] - b.points[second], np.broadcast_to(shift, (second.sum(), 3)),
                               atol=1e-12)
    np.testing.assert_allclose(moved[first] - b.points[first], 0.0, atol=1e-12)


def _band(radius, ymin, ymax, zmin, subdivisions=3):
    """The part of a sphere with ymin < y < ymax and z > zmin (times radius): a muscle sheet."""
    v, f = sphere(radius, subdivisions)
    c = v[f] / radius
    keep = ((c[:, :, 1] > ymin) & (c[:, :, 1] < ymax) & (c[:, :, 2] > zmin)).all(axis=1)
    return v, f[keep]


def _lip_line_side(points):
    """Synthetic lip line y = 0: +1 above, -1 below, 0 farther than 0.5 from it."""
    y = np.asarray(points)[:, 1]
    return np.where(np.abs(y) > 0.5, 0, np.where(y >= 0.0, 1, -1))


def _above_or_below(points):
    """+1 at or above y = 0, -1 below (the lips' side of a point, for ``bind_skin``'s ``side_of``)."""
    return np.where(points[:, 1] >= 0, 1, -1)


def test_a_lip_never_binds_to_the_other_lips_muscle_or_to_one_far_away(skin):
    """A lower-lip "depressor" whose end crosses the lip line (y = 0) by a little no longer
    takes the upper lip's rays that meet that end; a muscle far up ("brow") keeps no lip
    vertex."""
    v, f = skin
    dep = Body("dep", "muscle", *_band(0.9, -0.55, 0.1, 0.3))    # mostly below the line
    lev = Body("lev", "muscle", *_band(0.85, 0.0, 0.45, 0.3))    # deeper, above the line
    brow = Body("brow", "muscle", *_band(0.9, 0.6, 0.95, 0.0))   # far from the lips
    skull = Body("cranium", "cranium", *sphere(0.7, 3))
    bodies = [dep, brow, lev, skull]
    body_sides = [-1, 0, 1, 0]      # as faceforge.skin.mouth.muscle_lip_side says of them
    sides = _lip_line_side(v)
    sides[np.abs(v[:, 1]) > 0.7] = 1                               # lip skin reaching up the "nose"
    front = v[:, 2] > 0.5
    # the old rule (only the hit point's side, far hits allowed): upper-lip skin on dep and brow
    old = bind_skin(v, f, bodies, max_distance=0.5, lip_sides=sides)
    upper = np.isin(old.vertex_ids, np.flatnonzero((sides > 0) & front))
    assert (old.body[upper] == 0).any() and (old.body[upper] == 1).any()
    b = bind_skin(v, f, bodies, max_distance=0.5, lip_sides=sides, side_of=_lip_line_side,
                  body_sides=body_sides)
    up = sides[b.vertex_ids] > 0
    assert not np.isin(b.body[up], [0, 1]).any()
    # those that met dep's end above the line now bind deeper: to lev or the skull
    was_dep = old.vertex_ids[upper & (old.body == 0)]
    again = b.body[np.isin(b.vertex_ids, was_dep)]
    assert len(again) == len(was_dep) and np.all(np.isin(again, (2, 3)))
    # the lower lip still binds to dep
    low = np.isin(b.vertex_ids, np.flatnonzero(front & (v[:, 1] < -0.1) & (v[:, 1] > -0.35)))
    assert low.any() and np.all(b.body[low] == 0)



def test_lips_to_ring_puts_a_missed_lip_on_its_arc_before_the_teeth(skin):
    """A lip vertex whose rays miss takes the nearer of its own arc of the ring and the bone,
    and with ``lips_to_ring`` its own arc whenever one is within reach (ICT's FDP 8.1: its arc
    1.66 cm away, the teeth 1.59). Out of reach it still takes the bone."""
    from faceforge.skin.mouth import AROUND_MOUTH

    v, f = skin
    sv, sf = sphere(0.8, 3)
    skull = Body("cranium", "cranium", sv, sf[~(sv[sf][:, :, 2] > 0.6).any(axis=1)])   # a hole in front
    rv, rf = sphere(0.9, 3)
    ring = Body("ring", "muscle", rv, rf[(rv[rf][:, :, 1] > 0.6).all(axis=1)])          # its arc, high up
    sides = np.where(v[:, 1] >= 0, 1, -1)

    kw = dict(lip_sides=sides, side_of=_above_or_below, body_sides=[AROUND_MOUTH, 0],
              face_sides=[np.ones(len(ring.faces), np.int8), None])
    lip = np.flatnonzero((v[:, 2] > 0.9) & (v[:, 1] >= 0) & (v[:, 1] < 0.15))
    assert len(lip)
    near = bind_skin(v, f, [ring, skull], max_distance=0.8, **kw)
    first = bind_skin(v, f, [ring, skull], max_distance=0.8, lips_to_ring=True, **kw)
    for b in (near, first):
        assert np.all(b.closest[np.isin(b.vertex_ids, lip)])            # their rays missed
    assert np.all(near.status[lip] == CRANIUM)                           # the bone is nearer
    assert np.all(first.status[lip] == MUSCLE)
    sel = np.isin(first.vertex_ids, lip)
    assert np.all(first.distance[sel] <= 0.8)
    assert np.all(first.distance[sel] > near.distance[np.isin(near.vertex_ids, lip)])
    short = bind_skin(v, f, [ring, skull], max_distance=0.72, lips_to_ring=True, **kw)   # bone 0.71, arc 0.73
    assert np.all(short.status[lip] == CRANIUM)                          # the arc is out of reach


def test_modiolus_moves_corner_skin_from_another_muscle_to_its_arc_of_the_ring(skin):
    """Skin in the ``modiolus`` mask that its ray bound to another muscle binds instead to the
    closest point of the muscles around the mouth within reach -- a lip vertex on its own arc,
    a corner vertex anywhere -- with no second anchor; corner skin on the bone stays there,
    the rest of the skin binds as before, and out of reach the rays decide."""
    from faceforge.skin.mouth import AROUND_MOUTH
    from faceforge.geometry.surface_points import closest_points

    v, f = skin
    ov, of = _cap(0.95, 0.3)
    over = Body("risorius", "muscle", ov, of[(ov[of][:, :, 0] > 0.0).all(axis=1)])   # x > 0 only
    ring = Body("ring", "muscle", *_cap(0.85, 0.9, 4))
    skull = Body("cranium", "cranium", *sphere(0.8, 3))
    labels = np.where(ring.vertices[ring.faces].mean(axis=1)[:, 1] >= 0, 1, -1).astype(np.int8)
    sides = np.where(v[:, 2] > 0.6, np.where(v[:, 1] > 0.1, 1, np.where(v[:, 1] < -0.1, -1, 0)), 0)

    corner = v[:, 2] > 0.75
    kw = dict(lip_sides=sides, side_of=_above_or_below, body_sides=[0, AROUND_MOUTH, 0],
              face_sides=[None, labels, None], insertions=[0])
    rays = bind_skin(v, f, [over, ring, skull], max_distance=0.5, **kw)
    b = bind_skin(v, f, [over, ring, skull], max_distance=0.5, regions=InsertionRegions(modiolus=corner), **kw)

    def first(bb, ids):   # the body of each vertex's (first) anchor
        return bb.body[np.searchsorted(bb.vertex_ids, ids)]

    ids = np.flatnonzero(corner)
    moved = ids[first(rays, ids) == 0]                         # by their rays: the risorius
    bone = ids[first(rays, ids) == 2]                          # by their rays: the cranium
    assert {1, -1, 0} <= set(sides[moved]) and len(bone)
    assert np.all(first(b, moved) == 1)                        # the modiolus: the ring
    assert np.all(first(b, bone) == 2)                         # bone stays bone
    sel = np.isin(b.vertex_ids, moved)
    assert len(np.unique(b.vertex_ids[sel])) == sel.sum()     # no second anchor on the risorius
    assert not b.outward[sel].any() and not b.closest[sel].any()
    for s in (1, -1, 0):                                       # the closest point of the own arc
        mine = np.flatnonzero(sel & (sides[b.vertex_ids] == s))
        faces = ring.faces if s == 0 else ring.faces[labels == s]
        _, d, _ = closest_points(v[b.vertex_ids[mine]], ring.vertices, faces)
        np.testing.assert_allclose(b.distance[mine], d, atol=1e-12)
        if s:
            assert np.all(labels[b.face_ids[mine]] == s)
    rest = ~np.isin(rays.vertex_ids, moved)
    keep = ~np.isin(b.vertex_ids, moved)
    np.testing.assert_array_equal(rays.vertex_ids[rest], b.vertex_ids[keep])
    np.testing.assert_array_equal(rays.body[rest], b.body[keep])
    np.testing.assert_array_equal(rays.points[rest], b.points[keep])
    far = bind_skin(v, f, [over, ring, skull], max_distance=0.06, regions=InsertionRegions(modiolus=corner), **kw)
    near = bind_skin(v, f, [over, ring, skull], max_distance=0.06, **kw)
    assert np.any(far.body[np.isin(far.vertex_ids, ids)] == 0)   # the risorius, 0.05 away
    np.testing.assert_array_equal(far.body, near.body)        # no ring point within 0.06
    with pytest.raises(ValueError, match="modiolus"):
        bind_skin(v, f, [over, ring, skull], max_distance=0.5, regions=InsertionRegions(modiolus=corner[:-1]), **kw)


def test_modiolus_mask_is_the_skin_near_the_corner_fdps():
    from faceforge.skin.rules import modiolus_mask

    lm = {"8.3": np.array([1.0, 0.0, 0.0]), "8.4": np.array([-1.0, 0.0, 0.0]),
          "2.4": np.array([0.9, 0.0, 0.0])}
    pts = np.array([[1.2, 0.0, 0.0], [1.25, 0.0, 0.0], [0.65, 0.0, 0.0], [0.67, 0.0, 0.0],
                    [-1.0, 0.23, 0.0], [-1.0, 0.25, 0.0], [0.0, 0.0, 0.0]])
    np.testing.assert_array_equal(modiolus_mask(pts, lm, 0.12),      # reach 0.24 (MW0 = 2)
                                  [True, False, False, True, True, False, False])
    assert not modiolus_mask(pts, lm, 0.0).any()
    assert not modiolus_mask(pts, {k: lm[k] for k in ("8.3", "2.4")}, 0.12).any()   # no MW0


def test_commissure_binds_both_lips_at_the_corner_to_either_arc_of_the_ring(skin):
    """Lip skin in the ``commissure`` mask bound to the ring binds to the closest point of the
    whole ring, either lip's arc (the two arcs meet under the corner: vertices a fraction of a
    mm apart, bound each to its own arc, moved apart and folded); out of the mask, and without
    it, a lip vertex keeps its own arc; skin on the bone stays."""
    from faceforge.skin.mouth import AROUND_MOUTH
    from faceforge.geometry.surface_points import closest_points

    v, f = skin
    ring = Body("ring", "muscle", *_cap(0.85, 0.9, 4))
    skull = Body("cranium", "cranium", *sphere(0.8, 3))
    # the ring's rows part 0.15 above the skin's lip line (a fitted ring is not the lips)
    labels = np.where(ring.vertices[ring.faces].mean(axis=1)[:, 1] >= 0.15, 1, -1).astype(np.int8)
    sides = np.where(v[:, 2] > 0.6, np.where(v[:, 1] >= 0.0, 1, -1), 0)

    comm = (v[:, 2] > 0.9) & (np.abs(v[:, 1]) < 0.2)
    kw = dict(lip_sides=sides, side_of=_above_or_below, body_sides=[AROUND_MOUTH, 0], face_sides=[labels, None])
    own = bind_skin(v, f, [ring, skull], max_distance=0.5, **kw)
    both = bind_skin(v, f, [ring, skull], max_distance=0.5, regions=InsertionRegions(commissure=comm), **kw)
    on_ring = (both.body == 0) & np.isin(both.vertex_ids, np.flatnonzero(comm & (sides != 0)))
    assert on_ring.sum() >= 4
    _, d, _ = closest_points(v[both.vertex_ids[on_ring]], ring.vertices, ring.faces)
    np.testing.assert_allclose(both.distance[on_ring], d, atol=1e-12)   # the whole ring
    crossed = labels[both.face_ids[on_ring]] != sides[both.vertex_ids[on_ring]]
    assert crossed.any()                                          # some on the other lip's arc
    ring_own = (own.body == 0) & (sides[own.vertex_ids] != 0)      # without: each on its own arc
    assert np.all(labels[own.face_ids[ring_own]] == sides[own.vertex_ids[ring_own]])
    out = ~np.isin(both.vertex_ids, np.flatnonzero(comm))          # out of the mask: as before
    keep = ~np.isin(own.vertex_ids, np.flatnonzero(comm))
    np.testing.assert_array_equal(own.body[keep], both.body[out])
    np.testing.assert_array_equal(own.points[keep], both.points[out])
    bone = np.isin(own.vertex_ids, np.flatnonzero(comm)) & (own.body == 1)
    assert np.all(both.body[np.isin(both.vertex_ids, own.vertex_ids[bone])] == 1)
    with pytest.raises(ValueError, match="commissure"):
        bind_skin(v, f, [ring, skull], max_distance=0.5, regions=InsertionRegions(commissure=comm[:-1]), **kw)


def test_commissure_mask_is_the_skin_near_the_inner_lip_corners():
    from faceforge.skin.rules import commissure_mask

    lm = {"8.3": np.array([1.0, 0.0, 0.0]), "8.4": np.array([-1.0, 0.0, 0.0]),
          "2.4": np.array([0.9, 0.0, 0.0]), "2.5": np.array([-0.9, 0.0, 0.0])}
    pts = np.array([[0.95, 0.0, 0.0], [1.05, 0.0, 0.0], [-0.9, 0.09, 0.0], [-0.9, 0.11, 0.0],
                    [0.0, 0.0, 0.0]])
    np.testing.assert_array_equal(commissure_mask(pts, lm, 0.05),   # reach 0.1 (MW0 = 2)
                                  [True, False, True, False, False])
    assert not commissure_mask(pts, lm, 0.0).any()
    assert not commissure_mask(pts, {k: lm[k] for k in ("8.3", "2.4", "2.5")}, 0.05).any()
    assert not commissure_mask(pts, {k: lm[k] for k in ("8.3", "8.4")}, 0.05).any()


def _gapped_ring_lips(v):
    """A ring cap with a gap in front at the midline (as ICT's upper lip meets the teeth there), its
    faces' lip labels (+1 upper, -1 lower), the skin's lip sides (``v`` (n, 3) front of z 0.6) and the
    vermilion (front of z 0.9): ``(ring Body, labels (m,) int8, sides (n,) int, vermilion (n,) bool)``."""
    rv, rf = _cap(0.85, 0.9, 4)
    ring = Body("ring", "muscle", rv, rf[~(np.abs(rv[rf][:, :, 0]) < 0.2).all(axis=1)])
    labels = np.where(ring.vertices[ring.faces].mean(axis=1)[:, 1] >= 0.0, 1, -1).astype(np.int8)
    sides = np.where(v[:, 2] > 0.6, np.where(v[:, 1] >= 0.0, 1, -1), 0)
    return ring, labels, sides, (sides != 0) & (v[:, 2] > 0.9)


def test_vermilion_on_the_skull_binds_to_its_own_arc_of_the_ring(skin):
    """Lip skin in the ``vermilion`` mask whose rays met the skull (here through a gap of the ring at
    the midline, as ICT's upper lip meets the teeth) binds to its own lip's arc of the ring; without
    the mask it stays on the skull; skin out of the mask, or already on the ring, keeps its anchor."""
    from faceforge.skin.mouth import AROUND_MOUTH

    v, f = skin
    ring, labels, sides, verm = _gapped_ring_lips(v)
    skull = Body("cranium", "cranium", *sphere(0.8, 3))
    kw = dict(lip_sides=sides, side_of=_above_or_below, body_sides=[AROUND_MOUTH, 0], face_sides=[labels, None])
    before = bind_skin(v, f, [ring, skull], max_distance=0.5, **kw)
    after = bind_skin(v, f, [ring, skull], max_distance=0.5, regions=InsertionRegions(vermilion=verm), **kw)
    in_mask = np.isin(before.vertex_ids, np.flatnonzero(verm))
    on_bone = in_mask & (before.body == 1)
    assert on_bone.sum() >= 1                                  # the gap: some vermilion on the skull
    moved = np.isin(after.vertex_ids, before.vertex_ids[on_bone])
    assert np.all(after.body[moved] == 0) and not after.closest[moved].any()
    assert np.all(labels[after.face_ids[moved]] == sides[after.vertex_ids[moved]])   # its own arc
    stay, same = ~on_bone, ~moved
    np.testing.assert_array_equal(before.body[stay], after.body[same])
    np.testing.assert_array_equal(before.points[stay], after.points[same])
    with pytest.raises(ValueError, match="vermilion"):
        bind_skin(v, f, [ring, skull], max_distance=0.5, regions=InsertionRegions(vermilion=verm[:-1]), **kw)


def test_vermilion_mask_is_each_lip_within_its_midline_height_of_its_inner_contour():
    from types import SimpleNamespace

    from faceforge.skin.rules import vermilion_mask

    # a strip of vertices up the face at x = 0 and 1 (rows y = -3.5..3.5, 1 apart); inner contours at y = +-0.5
    ys = np.arange(-3.5, 4.0, 1.0)
    v = np.array([[x, y, 0.0] for y in ys for x in (0.0, 1.0)])
    faces = []
    for r in range(len(ys) - 1):
        a, b, c, d = 2 * r, 2 * r + 1, 2 * r + 2, 2 * r + 3
        faces += [[a, b, d], [a, d, c]]
    cut = SimpleNamespace(vertices=v, faces=np.array(faces), upper=np.array([8, 9]), lower=np.array([6, 7]))
    sides = np.where(v[:, 1] > 0, 1, -1)
    lm = {"2.2": [0.0, 0.5, 0.0], "8.1": [0.0, 1.6, 0.0], "2.3": [0.0, -0.5, 0.0], "8.2": [0.0, -2.6, 0.0]}
    got = vermilion_mask(cut, sides, lm)
    # upper lip: reach 1.1 -> rows y 0.5, 1.5; lower: reach 2.1 -> rows -0.5, -1.5, -2.5
    np.testing.assert_array_equal(got, np.isin(np.round(v[:, 1], 6), [0.5, 1.5, -0.5, -1.5, -2.5]))
    assert not vermilion_mask(cut, sides, {k: lm[k] for k in ("2.2", "8.1")})[sides < 0].any()
    assert not vermilion_mask(cut, sides, lm, 0.0).any()
    wide = vermilion_mask(cut, sides, lm, 2.0)     # reach 2.2 upper, 4.2 lower
    np.testing.assert_array_equal(wide, np.isin(np.round(v[:, 1], 6), [0.5, 1.5, 2.5, -0.5, -1.5, -2.5, -3.5]))


def test_vermilion_on_a_deep_muscle_binds_to_its_own_arc_of_the_ring(skin):
    """Lip skin in the ``deep`` mask whose rays met a muscle not around the mouth deeper than
    ``deep_depth`` (here through a gap of the ring, as ICT's lower lip meets the depressor labii
    inferioris 2 cm down) binds to its own lip's arc of the ring; with a depth past theirs, or
    without the mask, it keeps the deep muscle; the rest keeps its anchors."""
    from faceforge.skin.mouth import AROUND_MOUTH

    v, f = skin
    ring, labels, sides, verm = _gapped_ring_lips(v)
    deep = Body("depressor", "muscle", *sphere(0.6, 3))
    skull = Body("cranium", "cranium", *sphere(0.5, 3))
    kw = dict(lip_sides=sides, side_of=_above_or_below, body_sides=[AROUND_MOUTH, 0, 0], face_sides=[labels, None, None])
    bodies = [ring, deep, skull]
    before = bind_skin(v, f, bodies, max_distance=0.5, **kw)
    after = bind_skin(v, f, bodies, max_distance=0.5, regions=InsertionRegions(deep=verm, deep_depth=0.2), **kw)
    too_deep = bind_skin(v, f, bodies, max_distance=0.5, regions=InsertionRegions(deep=verm, deep_depth=0.5), **kw)
    off = bind_skin(v, f, bodies, max_distance=0.5, regions=InsertionRegions(deep=verm), **kw)
    on_deep = np.isin(before.vertex_ids, np.flatnonzero(verm)) & (before.body == 1)
    assert on_deep.sum() >= 1 and np.all(before.distance[on_deep] > 0.2)   # the gap: vermilion on the deep muscle
    moved = np.isin(after.vertex_ids, before.vertex_ids[on_deep])
    assert np.all(after.body[moved] == 0) and not after.closest[moved].any()
    assert np.all(labels[after.face_ids[moved]] == sides[after.vertex_ids[moved]])   # its own arc
    np.testing.assert_array_equal(before.body[~on_deep], after.body[~moved])
    np.testing.assert_array_equal(before.points[~on_deep], after.points[~moved])
    for same in (too_deep, off):                                   # deeper than theirs, or 0: as before
        np.testing.assert_array_equal(before.body, same.body)
        np.testing.assert_array_equal(before.points, same.points)
