"""The pieces that ride a bone (faceforge.skin.parts): eyeballs and teeth are told from the skin
and from cards on it, and sorted onto the cranium or the mandible."""

from __future__ import annotations

import numpy as np
import trimesh

from faceforge.skin.parts import ON_CRANIUM, ON_MANDIBLE, SKIN, part_counts, rigid_parts


def _mesh(*pieces):
    """(vertices, faces, first vertex id of each piece) of trimesh pieces in one mesh."""
    v, f, start, n = [], [], [], 0
    for p in pieces:
        v.append(np.asarray(p.vertices))
        f.append(np.asarray(p.faces) + n)
        start.append(n)
        n += len(p.vertices)
    return np.concatenate(v), np.concatenate(f), start


def _sphere(radius, centre, subdivisions=2):
    s = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    s.apply_translation(centre)
    return s


def _box(extents, centre):
    b = trimesh.creation.box(extents=extents)
    b.apply_translation(centre)
    return b


def _head():
    """A round head (radius 10) over a round skull (radius 8.5, its lower front the 'mandible'),
    with two eyeballs and two rows of teeth inside, a lash card and a brow card on the skin, and
    a second object beside the head. Returns the mesh, each piece's ids, the bones, the mouth."""
    skin = _sphere(10.0, (0, 0, 0), subdivisions=3)
    skull = _sphere(8.5, (0, 0, 0), subdivisions=3)
    sv, sf = np.asarray(skull.vertices), np.asarray(skull.faces)
    low_front = (sv[sf].mean(axis=1)[:, 1] < -2.0) & (sv[sf].mean(axis=1)[:, 2] > 0.0)
    cranium, mandible = (sv, sf[~low_front]), (sv, sf[low_front])
    mouth = -4.0
    pieces = {
        "skin": skin,
        "eye_l": _sphere(1.2, (3.0, 2.0, 7.5)), "eye_r": _sphere(1.2, (-3.0, 2.0, 7.5)),
        "upper_teeth": _box((4.0, 1.0, 1.0), (0.0, mouth + 0.7, 7.0)),
        "lower_teeth": _box((4.0, 1.0, 1.0), (0.0, mouth - 0.7, 7.0)),
        "lash": _box((2.0, 0.1, 0.6), (3.0, 3.2, 10.3)),
        "brow": _box((3.0, 0.3, 0.1), (3.0, 4.5, 9.2)),
        "other_object": _sphere(3.0, (30.0, 0.0, 0.0)),
    }
    v, f, start = _mesh(*pieces.values())
    ends = start[1:] + [len(v)]
    ids = {name: np.arange(a, b) for name, a, b in zip(pieces, start, ends)}
    return v, f, ids, cranium, mandible, mouth


def test_eyeballs_and_upper_teeth_ride_the_cranium_lower_teeth_the_mandible_cards_stay_skin():
    v, f, ids, cranium, mandible, mouth = _head()
    landmarks = ids["skin"][::50]
    parts = rigid_parts(v, f, landmarks, cranium, mandible, mouth=mouth)
    for name in ("eye_l", "eye_r", "upper_teeth"):
        assert np.all(parts[ids[name]] == ON_CRANIUM), name
    assert np.all(parts[ids["lower_teeth"]] == ON_MANDIBLE)
    for name in ("skin", "lash", "brow", "other_object"):
        assert np.all(parts[ids[name]] == SKIN), name
    assert part_counts(parts) == {"on_cranium": 2 * len(ids["eye_l"]) + len(ids["upper_teeth"]),
                                  "on_mandible": len(ids["lower_teeth"])}


def test_without_the_mouth_line_the_nearer_bone_decides():
    v, f, ids, cranium, mandible, _ = _head()
    parts = rigid_parts(v, f, ids["skin"][::50], cranium, mandible)
    assert np.all(parts[ids["lower_teeth"]] == ON_MANDIBLE)
    assert np.all(parts[ids["eye_l"]] == ON_CRANIUM)


def test_a_landmark_snapped_onto_an_eyeball_does_not_make_it_skin():
    """The pupils (FDP 3.5 / 3.6) lie on the eyeballs: a few landmarks there, most on the skin."""
    v, f, ids, cranium, mandible, mouth = _head()
    landmarks = np.concatenate([ids["skin"][::50], ids["eye_l"][:2], ids["eye_r"][:2]])
    parts = rigid_parts(v, f, landmarks, cranium, mandible, mouth=mouth)
    assert np.all(parts[ids["eye_l"]] == ON_CRANIUM) and np.all(parts[ids["eye_r"]] == ON_CRANIUM)


def test_one_piece_and_loose_points_are_all_skin():
    v, f, ids, cranium, mandible, mouth = _head()
    skin = ids["skin"]
    one = rigid_parts(v[skin], f[np.all(f < len(skin), axis=1)], skin[::50], cranium, mandible, mouth=mouth)
    assert not one.any()
    loose = np.concatenate([v, [[0.0, 2.0, 7.5]]])        # a point no face uses, inside the skull
    assert rigid_parts(loose, f, skin[::50], cranium, mandible, mouth=mouth)[-1] == SKIN
