"""``animate.eyelid_jaw_hold`` (faceforge.animation.eyelids.jaw_held_share): where the jaw moves and
the lids do not, the upper lids take back the skin's drift. An opening jaw pulled ICT's cheek down and,
through the skin between the cheek and the lid, dragged the upper lid's margin down and sideways (up
to 0.37 lid openings at full jawOpen, a notch in the margin); nothing asks the lid to move.

Real data: the sample heads and their FDPs (samples/), as tests/animation/test_eyelids.py loads them.
"""

import numpy as np
import pytest

from faceforge.animation.eyelids import Eyelids, find_eyes

from tests.animation.test_eyelids import HEADS, _load, faps

OPEN = np.array([[0.4, 0.0, 0.0]])    # jawOpen at full weight (radians of pitch)


@pytest.fixture(scope="module", params=sorted(HEADS))
def head(request):
    v, f, lm, vid = _load(HEADS[request.param])
    eyes = find_eyes(lm)
    irisd = np.mean([e.gap for e in eyes]) / 1024.0
    return request.param, v, f, lm, irisd


def _drag(v, lm):
    """A drag down and forward of a third of the opening, peaked half an opening below the eye's
    inner half: the cheek's skin pulling the lid, as ICT's open jaw did."""
    drag = np.zeros_like(v)
    for e in find_eyes(lm):
        r = np.linalg.norm((v - e.centre + 0.5 * e.gap * e.axes[1] + 0.3 * e.half * e.axes[0]) / e.half, axis=1)
        drag += 0.35 * e.gap * np.exp(-r * r)[:, None] * (-e.axes[1] + 0.5 * e.axes[2])
    return drag


def test_an_open_jaw_does_not_drag_the_upper_lid(head):
    """Where the upper lid's hold is (nearly) full (its margin and the skin just above it) the skin
    keeps at most a tenth of the drag with the hold (the lids do not move: no lid FAP); without it
    (0, the former behaviour) it keeps all of it, a tenth of the opening or more; the upper lid FDP
    goes back to rest."""
    name, v, f, lm, irisd = head
    drag = _drag(v, lm)
    none = faps([{}])
    lids = Eyelids(v, f, lm, irisd, fold_deg=80.0, jaw_hold=1.0)
    held = lids.apply((v + drag)[None], none, OPEN)[0]
    free = Eyelids(v, f, lm, irisd, fold_deg=80.0, jaw_hold=0.0).apply((v + drag)[None], none, OPEN)[0]
    for field, (upper, _) in zip(lids.fields, lids._lid_vertices):
        full = field.index[field.up_hold >= 0.9]
        gap = field.eye.gap
        kept, dragged = (np.linalg.norm(x[full] - v[full], axis=1) for x in (held, free))
        assert (dragged > 0.1 * gap).sum() >= 3, name
        assert np.all(kept <= 0.1 * dragged + 1e-9 * gap), name
        assert np.linalg.norm(free[upper] - v[upper]) > 0.1 * gap, name
        assert np.linalg.norm(held[upper] - v[upper]) < 0.01 * gap, name


def test_without_a_jaw_the_drift_stays_and_the_frame_is_untouched(head):
    """A brow's drag (no jaw, no lid FAP) moves the lid as before: the frame is copied bit for bit,
    and so is a frame whose jaw is at rest."""
    name, v, f, lm, irisd = head
    frame = (v + _drag(v, lm))[None]
    lids = Eyelids(v, f, lm, irisd, fold_deg=80.0, jaw_hold=1.0)
    assert np.array_equal(lids.apply(frame, faps([{}]))[0], frame[0])
    assert np.array_equal(lids.apply(frame, faps([{}]), np.zeros((1, 3)))[0], frame[0])


def test_a_driven_lid_is_held_as_before_whatever_the_jaw(head):
    """A lid FAP already takes back the whole drift (held_share): the jaw's hold adds nothing there."""
    name, v, f, lm, irisd = head
    frame = (v + _drag(v, lm))[None]
    track = faps([{19: 300, 20: 300}])
    a = Eyelids(v, f, lm, irisd, fold_deg=80.0, jaw_hold=1.0).apply(frame, track, OPEN)[0]
    b = Eyelids(v, f, lm, irisd, fold_deg=80.0, jaw_hold=0.0).apply(frame, track, OPEN)[0]
    assert np.array_equal(a, b)


def test_the_take_back_backs_off_where_it_would_turn_the_skin_over():
    """The take-back is a blend of rest and the frame whose share falls from the upper margin (1) to
    the lower one (0): the skin moved up as one (every triangle upright) by 0.6 of a lid opening, held
    at the upper margin and free at the lower, is squeezed between them, and the lids' guard and limit
    do not right all of it (MediaPipe's pride.fap turned its outer corners' triangles over so, frame
    24). Where they leave skin turned over or folded, the hold backs off: nothing is turned over on any
    sample head, fewer edges are folded than without, and each upper lid FDP is still held back."""
    from faceforge.animation.checks import folded_edges, inverted_faces

    without = {}
    for name in sorted(HEADS):
        v, f, lm, _ = _load(HEADS[name])
        eyes = find_eyes(lm)
        irisd = np.mean([e.gap for e in eyes]) / 1024.0
        lift = np.broadcast_to(0.6 * max(e.gap for e in eyes) * np.array([0.0, 1.0, 0.0]), v.shape)
        frame = (v + lift)[None]
        assert not inverted_faces(v, frame, f).any() and not folded_edges(v, frame, f).any()
        lids = Eyelids(v, f, lm, irisd, fold_deg=80.0, jaw_hold=1.0)
        held = lids.apply(frame, faps([{}]), OPEN)
        for upper, _ in lids._lid_vertices:
            assert np.linalg.norm(held[0, upper] - v[upper]) < 0.9 * np.linalg.norm(lift[upper]), name
        lids._jaw_blend = None   # the take-back whole
        whole = lids.apply(frame, faps([{}]), OPEN)
        without[name] = (int(inverted_faces(v, whole, f).sum()), int(folded_edges(v, whole, f).sum()))
        assert not inverted_faces(v, held, f).any(), name
        assert folded_edges(v, held, f).sum() <= without[name][1], name
    assert sum(t for t, _ in without.values()) > 0 and sum(e for _, e in without.values()) > 0, without
