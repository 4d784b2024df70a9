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
