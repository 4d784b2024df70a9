"""A driven lid's hold on the skin's drift (faceforge.animation.eyelids.held_share) fades out
gently enough that taking back a raised cheek's drift does not shear the skin under the lower lid.

Real data: the sample heads and their FDPs (samples/), as tests/animation/test_eyelids.py loads them.
"""

import numpy as np
import pytest

from faceforge.animation.eyelids import Eyelids, find_eyes

from tests.animation.test_eyelids import HEADS, _load, faps


@pytest.fixture(scope="module", params=sorted(HEADS))
def head(request):
    v, f, lm, vid = _load(HEADS[request.param])
    eyes = find_eyes(lm)
    irisd = np.mean([e.gap for e in eyes]) / 1024.0
    return request.param, v, f, lm, Eyelids(v, f, lm, irisd)


def held_shear(v, f, lids, drag, track):
    """The largest vertical shear (change of the vertical displacement per unit length along an
    edge) of the lids laid over ``v + drag`` by FAP frame ``track`` (1, 68), over the skin edges
    in the lids' reach (both ends), less the drag's own shear there; and the drag's own."""
    out = lids.apply((v + drag)[None], track)[0]
    e = np.unique(np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1), axis=0)
    worst, own = 0.0, 0.0
    for field in lids.fields:
        up = field.eye.axes[1]
        inside = np.zeros(len(v), bool)
        inside[field.index] = True
        k = e[inside[e].all(axis=1)]
        length = np.linalg.norm(v[k[:, 0]] - v[k[:, 1]], axis=1)
        d, d0 = (out - v) @ up, drag @ up
        worst = max(worst, float(np.max(np.abs(d[k[:, 0]] - d[k[:, 1]]) / length)))
        own = max(own, float(np.max(np.abs(d0[k[:, 0]] - d0[k[:, 1]]) / length)))
    return worst, own


def test_a_raised_cheek_held_back_under_a_driven_lower_lid_is_not_sheared(head):
    """Joy's cheek raiser lifts the skin under the eye 2-3 mm (a third of the opening) and joy's
    lower-lid FAP raises the lid: the lid takes the drift back (the margin goes where its FAP
    says) and the skin below keeps it. Over the lids' own fade (half a reach of the opening)
    that change sheared MakeHuman's lower lid by most of the drift's height per edge length
    and folded it (joy's 6 lid folds); the hold now fades over HOLD_BELOW reaches."""
    name, v, f, lm, lids = head
    drag = np.zeros_like(v)
    for e in find_eyes(lm):   # a bump of a third of the opening, peaked one opening below the eye
        r = np.linalg.norm((v - e.centre + 1.0 * e.gap * e.axes[1]) / e.half, axis=1)
        drag += 0.35 * e.gap * np.exp(-r * r)[:, None] * e.axes[1]
    worst, own = held_shear(v, f, lids, drag, faps([{21: 100, 22: 100}]))
    assert worst < 0.45, (worst, own)


def test_a_driven_lid_takes_back_the_whole_drift_not_only_its_height(head):
    """Surprise on ICT: the frontalis drew the upper lid's skin up and 1-2 mm forward, unevenly.
    A hold that took back only the vertical drift put the margin back on its curve at the
    dragged depths, and the margin folded along its inner half (12 folded edges). The driven
    lid now takes back the whole drift: where the hold is full (between the margins, at the
    corners) the skin ends where the lid field alone puts it."""
    name, v, f, lm, lids = head
    drag = np.zeros_like(v)
    for e in find_eyes(lm):   # up and forward, peaked above the eye's inner half
        r = np.linalg.norm((v - e.centre - 0.6 * e.gap * e.axes[1] + 0.3 * e.half * e.axes[0]) / e.half, axis=1)
        drag += 0.3 * e.gap * np.exp(-r * r)[:, None] * (e.axes[1] + 0.8 * e.axes[2])
    track = faps([{19: -200, 20: -200}])
    alone = lids.apply(v[None], track)[0]
    held = lids.apply((v + drag)[None], track)[0]
    for field in lids.fields:
        full = field.index[field.hold >= 1.0]
        moved = np.linalg.norm(drag[full], axis=1) > 0.05 * field.eye.gap
        assert moved.sum() >= 3, name                                  # the drag reached them
        assert np.abs(held[full] - alone[full]).max() < 1e-9 * field.eye.gap


def test_a_raised_lower_lid_does_not_stretch_the_skin_under_it_past_its_height(head):
    """Anger raises the lower lids 350 IRISD, a third of the opening (ICT 3.5 mm). Faded out over
    half a reach below the margin, that stretched the skin under ICT's lower lid to more than
    twice its height and turned the margin's rim over (4 folded edges); faded over LOWER_FADE
    reaches, the vertical stretch per edge length down the lid stays under 1.2 on the three heads
    (MakeHuman 1.37 -> 0.69, ICT 1.69 -> 1.07 at the worst edge; MediaPipe's coarse mask 0.1)."""
    name, v, f, lm, lids = head
    out = lids.apply(v[None], faps([{21: 350, 22: 350}]))[0]
    e = np.unique(np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1), axis=0)
    for field in lids.fields:
        up = field.eye.axes[1]
        x = (v - field.eye.centre) @ field.eye.axes.T
        below = np.zeros(len(v), bool)      # skin under the lower margin, in front of the socket
        below[field.index] = (x[field.index, 1] < field.eye.margins[1] * field.eye.taper(x[field.index, 0])) \
            & (np.abs(x[field.index, 0]) < 0.7 * field.eye.half)
        k = e[below[e].all(axis=1)]
        dv = (out - v) @ up
        rise = np.abs(((v[k[:, 0]] - v[k[:, 1]]) @ up))
        steep = rise > 0.5 * np.linalg.norm(v[k[:, 0]] - v[k[:, 1]], axis=1)   # edges running down the lid
        assert steep.sum() >= 3, name
        stretch = np.abs(dv[k[:, 0]] - dv[k[:, 1]])[steep] / rise[steep]
        assert stretch.max() < 1.2, (name, stretch.max())
