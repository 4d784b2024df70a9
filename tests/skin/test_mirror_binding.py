"""A symmetric head's binding made symmetric (faceforge.skin.mirror, issue 25).

A flat skin over a muscle and its mirrored twin and a bumpy bone whose triangulation is not
a mirror image of itself: after :func:`mirror_binding` every right vertex is bound as the
mirror image of its left partner (the twin's face, reversed barycentric coordinates; the
bone's closest point), whatever the rays found for it.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from faceforge.geometry.mirror import Mirror
from faceforge.skin.binding import CRANIUM, Body, bind_skin
from faceforge.skin.mirror import mirror_binding
from tests.skin.synthetic import grid

MIRROR = Mirror((0.0, 0.0, 0.0), (1.0, 0.0, 0.0))


def _scene():
    skin_v, skin_f = grid(20, 10, width=2.0)
    skin_v[:, 0] -= 1.0                                   # x in [-1, 1]: vertices pair up
    mv, mf = grid(6, 4, width=0.6, height=0.6)
    mv += (0.2, 0.2, -0.1)                               # a plate under the left half
    bv, bf = grid(13, 7, width=2.4, height=1.4)          # 13 columns: its mirror image is another mesh
    bv += (-1.2, -0.2, -0.3)
    bv[:, 2] += 0.05 * np.cos(3.0 * bv[:, 0]) * np.cos(2.0 * bv[:, 1])   # symmetric but for its triangles
    bodies = [Body("plate_L", "muscle", mv, mf),
              Body("plate_R", "muscle", MIRROR(mv), mf[:, ::-1].copy()),
              Body("cranium", "cranium", bv, bf)]
    return skin_v, skin_f, bodies


def _targets(binding, bodies):
    return binding.targets([(b.vertices, b.faces) for b in bodies])


@pytest.fixture(scope="module")
def scene():
    skin_v, skin_f, bodies = _scene()
    raw = bind_skin(skin_v, skin_f, bodies, 1.0)
    return skin_v, bodies, raw


def test_right_vertices_are_bound_as_mirror_images(scene):
    skin_v, bodies, raw = scene
    # spoil the rays' binding on the right: a vertex over the right plate bound to the bone
    over = np.flatnonzero((skin_v[:, 0] < -0.3) & (skin_v[:, 0] > -0.7) & (skin_v[:, 1] > 0.3) & (skin_v[:, 1] < 0.7))
    assert len(over)
    anchor = np.searchsorted(raw.vertex_ids, over[0])
    body = raw.body.copy()
    body[anchor] = 2
    status = raw.status.copy()
    status[over[0]] = CRANIUM
    spoilt = replace(raw, body=body, status=status, face_ids=np.where(np.arange(len(body)) == anchor, 0, raw.face_ids))
    fixed, count = mirror_binding(spoilt, skin_v, bodies, MIRROR, 1e-9)
    assert count == int((skin_v[:, 0] < -1e-9).sum())
    partner = np.array([int(np.argmin(np.linalg.norm(skin_v - MIRROR(p), axis=1))) for p in skin_v])
    t = _targets(fixed, bodies)
    names = fixed.body_names
    twin = {"plate_L": "plate_R", "plate_R": "plate_L", "cranium": "cranium"}
    for r in np.flatnonzero(skin_v[:, 0] < -1e-9):
        p = partner[r]
        a, b = np.flatnonzero(fixed.vertex_ids == r), np.flatnonzero(fixed.vertex_ids == p)
        assert [names[i] for i in fixed.body[a]] == [twin[names[i]] for i in fixed.body[b]]
        on_plate = fixed.body[a] != 2
        # on the twin plate: exactly the mirror image; on the bone: its closest point
        np.testing.assert_allclose(t[a][on_plate], MIRROR(t[b][on_plate]), atol=1e-12)
        assert np.abs(t[a][~on_plate] - MIRROR(t[b][~on_plate])).max(initial=0.0) < 0.01
    assert fixed.status[over[0]] != CRANIUM
    # the left half and the midline keep the rays' anchors
    left = np.flatnonzero(skin_v[:, 0] >= -1e-9)
    keep = np.isin(raw.vertex_ids, left)
    np.testing.assert_array_equal(fixed.face_ids[np.isin(fixed.vertex_ids, left)], raw.face_ids[keep])


def test_an_asymmetric_skin_keeps_its_binding(scene):
    skin_v, bodies, raw = scene
    bent = skin_v.copy()
    bent[0, 2] += 0.05                                    # one vertex has no mirror partner
    same, count = mirror_binding(raw, bent, bodies, MIRROR, 1e-3)
    assert count == 0 and same is raw


def test_a_midline_vertex_on_one_twin_follows_both(scene):
    skin_v, bodies, raw = scene
    mid = int(np.flatnonzero(np.abs(skin_v[:, 0]) < 1e-12)[3])
    anchor = np.searchsorted(raw.vertex_ids, mid)
    moved = replace(raw, body=np.where(np.arange(len(raw.body)) == anchor, 0, raw.body))   # on plate_L
    fixed, _ = mirror_binding(moved, skin_v, bodies, MIRROR, 1e-9)
    names = [fixed.body_names[i] for i in fixed.body[fixed.vertex_ids == mid]]
    assert names == ["plate_L", "plate_R"]


def test_a_midline_vertex_bound_off_the_plane_on_a_self_mirror_body_follows_both_sides(scene):
    """The bone is its own mirror image: a midline skin vertex bound to it off the plane (a
    closest point can fall on either of two equally near sides) also gets the bone's closest
    point to the mirrored anchor, so it follows both sides alike."""
    skin_v, bodies, raw = scene
    mid = int(np.flatnonzero(np.abs(skin_v[:, 0]) < 1e-12)[1])
    anchor = np.searchsorted(raw.vertex_ids, mid)
    bone = bodies[2]
    from faceforge.geometry.surface_points import project_to_surface

    sp = project_to_surface(np.array([[0.25, skin_v[mid, 1], -0.3]]), bone.vertices, bone.faces)
    rows = np.arange(len(raw.body)) == anchor
    moved = replace(raw, body=np.where(rows, 2, raw.body), face_ids=np.where(rows, sp.face_ids[0], raw.face_ids),
                    bary=np.where(rows[:, None], sp.bary[0], raw.bary),
                    points=np.where(rows[:, None], sp.positions(bone.vertices, bone.faces)[0], raw.points))
    fixed, _ = mirror_binding(moved, skin_v, bodies, MIRROR, 1e-9)
    pts = fixed.points[fixed.vertex_ids == mid]
    assert len(pts) == 2
    assert np.allclose(sorted(pts[:, 0]), [-0.25, 0.25], atol=0.05), pts
