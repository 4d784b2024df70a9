"""Kinematic eyelids (faceforge.animation.eyelids): FAPs 19-22 on the three sample heads.

Real data: the sample heads and their FDPs (samples/), and MakeHuman's own eye-closure
expression unit on the MakeHuman head (tests/data/mh_eye_left_closure.npz, CC0).
"""

from pathlib import Path

import numpy as np
import pytest
import trimesh
import yaml

from faceforge.animation.checks import inverted_faces
from faceforge.animation.eyelids import (
    EYELID_FAPS, MIN_OPENING, Eyelids, find_eyes, lid_field, lid_moves, move_lids)

ROOT = Path(__file__).resolve().parents[2]
HEADS = {
    "makehuman": ROOT / "samples" / "makehuman" / "mh_head_default",
    "ict": ROOT / "samples" / "ict" / "ict_face_headneck_neutral",
    "mediapipe": ROOT / "samples" / "mediapipe" / "canonical_face_model",
}
#: FDPs of the subject's left and right eye: upper lid, lower lid
LIDS = (("3.1", "3.3"), ("3.2", "3.4"))


def _load(stem: Path):
    if not stem.with_suffix(".obj").exists():
        stem = next(stem.parent.glob("*.obj")).with_suffix("")
    mesh = trimesh.load(stem.with_suffix(".obj"), process=False)
    marks = yaml.safe_load(stem.with_name(stem.name + ".fdp.yaml").read_text())["landmarks"]
    vid = {k: m["vertex"] for k, m in marks.items() if m.get("vertex") is not None}
    v = np.asarray(mesh.vertices, dtype=np.float64)
    return v, np.asarray(mesh.faces, dtype=np.int64), {k: v[i] for k, i in vid.items()}, vid


@pytest.fixture(scope="module", params=sorted(HEADS))
def head(request):
    v, f, lm, vid = _load(HEADS[request.param])
    eyes = find_eyes(lm)
    irisd = np.mean([e.gap for e in eyes]) / 1024.0       # IRISD0 = the eyelid gap
    return request.param, v, f, lm, vid, Eyelids(v, f, lm, irisd), irisd


def faps(rows: list[dict]) -> np.ndarray:
    """(F, 68) FAP frames from ``[{fap number: value}, ...]``."""
    out = np.zeros((len(rows), 68))
    for i, row in enumerate(rows):
        for k, val in row.items():
            out[i, k - 1] = val
    return out


def vertical(eye, d):
    return d @ eye.axes[1]


def test_each_eye_has_a_right_handed_frame_along_its_corners(head):
    name, v, f, lm, vid, lids, irisd = head
    eyes = find_eyes(lm)
    assert [e.upper_fap for e in eyes] == [19, 20] and lids.faps == EYELID_FAPS
    for e, (outer, inner) in zip(eyes, (("3.7", "3.11"), ("3.12", "3.8"))):
        np.testing.assert_allclose(e.axes @ e.axes.T, np.eye(3), atol=1e-12)
        assert np.linalg.det(e.axes) == pytest.approx(1.0)
        assert e.axes[0, 0] > 0.9 and e.axes[1, 1] > 0.9 and e.axes[2, 2] > 0.9   # +X, up, forward
        np.testing.assert_allclose(e.centre, 0.5 * (lm[outer] + lm[inner]))
        assert e.upper > 0 > e.lower and e.half > e.gap > 0
    assert len(find_eyes({k: p for k, p in lm.items() if k != "3.12"})) == 1


def test_the_rest_pose_and_other_faps_leave_the_skin_bit_for_bit(head):
    name, v, f, lm, vid, lids, irisd = head
    track = faps([{}, {3: 400, 31: 100, 48: 2000}])
    out = lids.apply(np.stack([v, v + 0.01]), track)
    assert np.array_equal(out, np.stack([v, v + 0.01]))


def test_a_lid_fdp_moves_by_exactly_the_requested_amount(head):
    """FAPs 19-22 are vertical displacements of the lid FDPs in IRISD: down for the upper lids,
    up for the lower ones. Closing, the lid rides forward over the eyeball; opening wider, it
    moves straight up (no forward or backward part)."""
    name, v, f, lm, vid, lids, irisd = head
    track = faps([{19: 512, 20: 300, 21: 200, 22: 100}, {19: -150, 20: -150, 21: -80}])
    out = lids.apply(np.stack([v, v]), track)
    eyes = find_eyes(lm)
    tol = 1e-12 * np.ptp(v)
    for e, (up, low), (fu, fl) in zip(eyes, LIDS, ((19, 21), (20, 22))):
        for k in range(2):
            d_up = out[k, vid[up]] - v[vid[up]]
            d_low = out[k, vid[low]] - v[vid[low]]
            assert vertical(e, d_up) == pytest.approx(-track[k, fu - 1] * irisd, rel=1e-9, abs=tol)
            assert vertical(e, d_low) == pytest.approx(track[k, fl - 1] * irisd, rel=1e-9, abs=tol)
            assert d_up @ e.axes[0] == pytest.approx(0.0, abs=tol)
            if k == 0:
                assert d_up @ e.axes[2] > 0.0          # forward, over the eyeball
            else:
                assert d_up @ e.axes[2] == pytest.approx(0.0, abs=tol)   # opening: straight up


def test_an_upper_lid_opens_as_wide_as_a_real_upper_lid_raise(head):
    """AU5 (the upper lid raised, surprise and fear) lifts a real lid 2-4 mm, a third of a 10 mm
    opening: MakeHuman's own eye-opened-up unit raises its lid FDP 312 IRISD. The upper lid FDP
    goes exactly as high as asked up to 0.35 openings (the opening limit was a quarter: surprise's
    lids opened 1.30 times on every sample head whatever it asked), the margin stays clean (no
    triangle turned over), and past the limit the lid stops, a little higher still."""
    name, v, f, lm, vid, lids, irisd = head
    track = faps([{19: -358, 20: -300}, {19: -2000, 20: -2000}])
    out = lids.apply(np.stack([v, v]), track)
    eyes = find_eyes(lm)
    tol = 1e-12 * np.ptp(v)
    for e, (up, _), fu in zip(eyes, LIDS, (19, 20)):
        rise = vertical(e, out[0, vid[up]] - v[vid[up]])
        assert rise == pytest.approx(-track[0, fu - 1] * irisd, rel=1e-9, abs=tol)
        assert rise > 0.29 * e.gap
        assert 0.35 * e.gap < vertical(e, out[1, vid[up]] - v[vid[up]]) < 0.5 * e.gap
    assert not inverted_faces(v, out, f).any()


def test_a_full_blink_meets_the_lids_and_turns_no_triangle_over(head):
    """1024 IRISD closes the upper lid onto the lower one (leaving MIN_OPENING of the gap); a
    request past that (with the lower lid rising too) stops where the lids meet. No skin
    triangle turns over, the gathered skin between the lids included."""
    name, v, f, lm, vid, lids, irisd = head
    track = faps([{19: 1024, 20: 1024}, {19: 1024, 20: 700, 21: 400, 22: 400}, {19: -300, 21: -200}])
    out = lids.apply(np.stack([v] * 3), track)
    for e, field, (up, low) in zip(find_eyes(lm), lids.fields, LIDS):
        moves = lid_moves(field, track, irisd)
        for k in range(2):
            gap = vertical(e, out[k, vid[up]] - out[k, vid[low]])
            assert gap == pytest.approx(e.gap - moves[k].sum(), rel=1e-9)
            assert gap == pytest.approx(MIN_OPENING * e.gap, rel=1e-3)
    assert not inverted_faces(v, out, f).any()
    bare = move_lids(np.stack([v] * 3), lids.fields, track, irisd, v)   # the field alone, no guard
    moved = np.abs(out - bare).max() / np.mean([e.gap for e in find_eyes(lm)])
    assert moved < 0.05                                # the guard only mends slivers


def test_the_vertical_moves_of_the_two_lids_add_up(head):
    """Within the lids' range the field is linear: the upper lid's move plus the lower lid's is
    the move of both at once (vertically; the ride over the eyeball is not linear)."""
    name, v, f, lm, vid, lids, irisd = head
    both, upper, lower = (move_lids(v[None], lids.fields, faps([row]), irisd, v)[0] - v
                          for row in ({19: 300, 21: 250}, {19: 300}, {21: 250}))
    e = find_eyes(lm)[0]
    np.testing.assert_allclose(vertical(e, both), vertical(e, upper) + vertical(e, lower),
                               atol=1e-12 * np.ptp(v))


def test_each_eye_moves_only_its_own_lids(head):
    name, v, f, lm, vid, lids, irisd = head
    left, right = lids.fields
    out = lids.apply(v[None], faps([{19: 800, 21: 100}]))[0]
    moved = np.flatnonzero(np.any(out != v, axis=1))
    assert len(moved) and np.isin(moved, left.index).all()
    assert not np.isin(moved, right.index).any()
    near = np.linalg.norm(v - left.eye.centre, axis=1) <= 3.0 * left.eye.half
    assert np.all(near[moved])


def test_the_lids_of_a_mirror_symmetric_head_move_as_mirror_images():
    """The MakeHuman head and its FDPs are exactly mirror-symmetric: the left lid's field under
    FAP 19 is the mirror image of the right lid's under FAP 20."""
    from scipy.spatial import cKDTree

    v, f, lm, vid = _load(HEADS["makehuman"])
    dist, mirror = cKDTree(v).query(v * [-1.0, 1.0, 1.0])
    assert dist.max() == 0.0
    lids = Eyelids(v, f, lm, find_eyes(lm)[0].gap / 1024)
    left = lids.apply(v[None], faps([{19: 700, 21: 150}]))[0] - v
    right = lids.apply(v[None], faps([{20: 700, 22: 150}]))[0] - v
    assert np.abs(left).max() > 0
    np.testing.assert_allclose(left, right[mirror] * [-1.0, 1.0, 1.0], atol=1e-12 * np.ptp(v))


def test_makehuman_blink_agrees_with_makehuman_eye_closure_unit():
    """MakeHuman's artists made an eye-closure unit for this very head. Scaled to the same drop
    of the lid FDP, its vertical offsets and the lid field's agree: cosine 0.80 over the
    vertices either moves, and the vertices the unit moves most (more than 0.3 of the lid
    opening) move as far, at the median, in the field."""
    v, f, lm, vid = _load(HEADS["makehuman"])
    unit = np.load(ROOT / "tests" / "data" / "mh_eye_left_closure.npz")
    eye = find_eyes(lm)[0]
    ref = np.zeros(len(v))
    ref[unit["vertices"]] = vertical(eye, unit["deltas"].astype(np.float64))
    ours = vertical(eye, Eyelids(v, f, lm, eye.gap / 1024).apply(v[None], faps([{19: 1024}]))[0] - v)
    ref *= ours[vid["3.1"]] / ref[vid["3.1"]]
    either = (np.abs(ref) > 0.02 * eye.gap) | (np.abs(ours) > 0.02 * eye.gap)
    cosine = ref[either] @ ours[either] / np.linalg.norm(ref[either]) / np.linalg.norm(ours[either])
    assert cosine > 0.75
    big = np.abs(ref) > 0.3 * eye.gap
    assert big.sum() > 20
    assert 0.8 < np.median(ours[big] / ref[big]) < 1.25


def test_bad_parameters_are_refused():
    v, f, lm, vid = _load(HEADS["mediapipe"])
    with pytest.raises(ValueError, match="reach and depth"):
        lid_field(find_eyes(lm)[0], v, reach=0.0)


def test_an_eyeball_in_the_same_mesh_stays_put():
    """A head mesh that carries its eyeballs as separate pieces: the lids close over them, the
    eyeballs themselves do not move (nor squash with the skin between the lids)."""
    v, f, lm, vid = _load(HEADS["makehuman"])
    eye = find_eyes(lm)[0]
    ball = trimesh.creation.icosphere(subdivisions=3, radius=0.8 * eye.half)
    centre = eye.centre - 0.5 * eye.half * eye.axes[2]            # its front just behind the lids
    vb = np.concatenate([v, ball.vertices + centre])
    fb = np.concatenate([f, ball.faces + len(v)])
    lids = Eyelids(vb, fb, lm, eye.gap / 1024)
    out = lids.apply(vb[None], faps([{19: 1024, 21: 200}]))[0]
    assert np.array_equal(out[len(v):], vb[len(v):])
    alone = Eyelids(v, f, lm, eye.gap / 1024).apply(v[None], faps([{19: 1024, 21: 200}]))[0]
    np.testing.assert_array_equal(out[:len(v)], alone)            # the skin moves as without them
    reached = lid_field(eye, vb).index
    assert np.any(reached >= len(v))                                # the field alone would move them


def test_a_driven_lid_takes_back_the_skins_drift_so_its_margin_stays_clean(head):
    """Surprise: the frontalis drags the skin round the eye up, hardest under the brow's
    middle; laid over that, the lid's own raise used to peak and skew the opening. A driven
    lid takes the skin's vertical drift back: the lid FDPs land exactly ``FAP x IRISD`` from
    rest, the corners (canthi) stay at their rest height, and along the upper margin the
    opening follows the smooth modelled curve ``d s(u)``: no spike where the drag peaked."""
    from faceforge.animation.eyelids import held_share

    name, v, f, lm, vid, lids, irisd = head
    eyes = find_eyes(lm)
    drag = np.zeros_like(v)
    for e in eyes:   # a bump of 0.4 openings, peaked above the eye's middle, fading over a brow
        r = np.linalg.norm((v - e.centre - 0.8 * e.gap * e.axes[1]) / e.half, axis=1)
        drag += 0.4 * e.gap * np.exp(-r * r)[:, None] * e.axes[1]
    track = faps([{19: -200, 20: -200}, {}])
    frames = np.stack([v + drag, v + drag])
    out = lids.apply(frames, track)
    assert np.array_equal(out[1], frames[1])                      # no lid FAP: left as it was
    for e, field, (up, low), (outer, inner) in zip(eyes, lids.fields, LIDS, (("3.7", "3.11"), ("3.12", "3.8"))):
        assert vertical(e, out[0, vid[up]] - v[vid[up]]) == pytest.approx(200 * irisd, rel=1e-9)
        assert vertical(e, out[0, vid[low]] - v[vid[low]]) == pytest.approx(0.0, abs=1e-9 * e.gap)
        for corner in (outer, inner):
            i = int(np.argmin(np.linalg.norm(v - lm[corner], axis=1)))
            assert abs(vertical(e, out[0, i] - v[i])) < 0.02 * e.gap, corner
        # the upper margin: skin within 0.1 openings above the modelled margin, along its middle
        x = (v[field.index] - e.centre) @ e.axes.T
        top = e.margins[0] * e.taper(x[:, 0])
        rim = field.index[(x[:, 1] >= top) & (x[:, 1] <= top + 0.1 * e.gap) & (np.abs(x[:, 0]) < 0.8 * e.half)
                          & (np.abs(x[:, 2] - e.lid_depth) < 0.5 * e.gap)]
        assert len(rim) >= 3
        want = 200 * irisd * e.taper((v[rim] - e.centre) @ e.axes[0]) / e.taper(e.upper_u)
        got = vertical(e, out[0, rim] - v[rim])
        assert vertical(e, drag[rim]).max() > 0.25 * e.gap          # the drag was there
        assert np.abs(got - want).max() < 0.1 * e.gap               # and is (mostly) gone
        assert np.all(held_share(field, np.zeros((1, 2))) == 0.0)


def test_the_lining_behind_a_closing_margin_rides_forward_with_it():
    """A vertex behind the margins' surface takes the forward move of the surface point in front of
    it: before, it was pushed only by its own distance from the eyeball's axis (nothing at all behind
    the axis), the margin rode forward over it and the lid's rim folded (ICT's blinks)."""
    from faceforge.animation.eyelids import over_eyeball

    r = 10.0
    y0 = np.array([6.0, 6.0, 6.0, 6.0])
    z_front = np.sqrt(r * r - 36.0)                      # on the eyeball: 8
    z0 = np.array([z_front, z_front - 3.0, -1.0, z_front + 1.0])   # surface, lining, behind the axis, in front
    surface = np.full(4, z_front)
    y1 = (y0 - 6.0)[None, :]                              # closed down to the axis' height
    push = over_eyeball(y0, z0, y1, surface)[0]
    expected = r - z_front                               # the surface point's move, 2
    assert push[0] == pytest.approx(expected)
    assert push[1] == pytest.approx(expected)            # the lining: as much as the surface in front of it
    assert push[2] == pytest.approx(expected)
    far = np.hypot(6.0, z_front + 1.0) - (z_front + 1.0)
    assert push[3] == pytest.approx(far)                 # in front of the surface: its own distance
    up = over_eyeball(y0, z0, (y0 + 2.0)[None, :], surface)[0]
    assert np.all(up == 0.0)                              # a lid opening wider never moves forward or back
    behind_skin = over_eyeball(y0, np.array([-20.0] * 4), y1, np.array([-15.0] * 4))[0]
    assert np.all(behind_skin == 0.0)                     # a surface behind the axis: no push


def test_a_lash_card_rides_its_closing_lid_and_an_iris_disc_does_not():
    """Two small pieces beside MakeHuman's left upper lid: a card at its margin (the lashes) takes
    its lid vertex's move as the lid closes; a disc in the middle of the opening (an iris) stays."""
    v, f, lm, _ = _load(HEADS["makehuman"])
    eye = find_eyes(lm)[0]
    top = eye.centre + eye.upper * eye.axes[1] + 0.05 * eye.half * eye.axes[2]
    card = trimesh.creation.box(extents=[eye.half, 0.05 * eye.half, 0.02 * eye.half])
    card.apply_translation(top + 0.04 * eye.half * eye.axes[1])
    disc = trimesh.creation.cylinder(radius=0.2 * eye.half, height=0.01 * eye.half, sections=8)
    disc.apply_translation(eye.centre + (eye.lid_depth + 0.01 * eye.half) * eye.axes[2])
    n, k = len(v), len(card.vertices)
    verts = np.concatenate([v, card.vertices, disc.vertices])
    faces = np.concatenate([f, card.faces + n, disc.faces + n + k])
    lids = Eyelids(verts, faces, lm, irisd=eye.gap / 1024.0)
    assert set(lids.lashes[0].tolist()) == set(range(n, n + k))
    out = lids.apply(verts[None], faps([{eye.upper_fap: 600}]))[0]   # the upper lid closes 600 IRISD
    assert vertical(eye, out[n:n + k] - verts[n:n + k]).mean() < -0.2 * eye.gap   # down with the lid
    assert np.array_equal(out[n + k:], verts[n + k:])
