"""The lids' fold limit (``animate.eyelid_fold_deg``): a blink gathers the socket's lining onto the
dipping line where the lids meet, and near the canthi its sub-mm triangles folded (the bake's
eyeBlink shapes: MakeHuman 4 / 4, ICT 18 / 17, MediaPipe 1 / 1 folded edges). With the limit the
skin the lids move, flat at rest, bends at most that far, alternating with the orientation guard
(no triangle turned over either).

Real data: the sample heads and their FDPs (samples/), as tests/animation/test_eyelids.py loads them.
"""

import numpy as np
import pytest

from faceforge.animation.checks import folded_edges, inverted_faces
from faceforge.animation.eyelids import Eyelids, find_eyes

from tests.animation.test_eyelids import HEADS, _load, faps


@pytest.mark.parametrize("name", sorted(HEADS))
def test_a_blink_with_the_fold_limit_folds_less_and_turns_nothing_over(name):
    v, f, lm, _ = _load(HEADS[name])
    irisd = np.mean([e.gap for e in find_eyes(lm)]) / 1024.0
    blink = faps([{19: 900, 21: 124, 20: 900, 22: 124}])      # the bake's eyeBlink, both eyes
    free = Eyelids(v, f, lm, irisd).apply(v[None], blink)
    held = Eyelids(v, f, lm, irisd, fold_deg=80.0).apply(v[None], blink)
    n_free = int(folded_edges(v, free, f).sum())
    n_held = int(folded_edges(v, held, f).sum())
    # the raw sample meshes (not the bound working mesh): MakeHuman / MediaPipe fold a few edges, ICT 35
    assert n_free > 0
    assert n_held <= n_free // 2, (n_free, n_held)
    assert int(inverted_faces(v, held, f).sum()) <= int(inverted_faces(v, free, f).sum())
    # the lid FDPs still close as far (the limit moves sub-mm wings, not the margins)
    for fdp in ("3.1", "3.2"):
        i = int(np.argmin(np.linalg.norm(v - lm[fdp], axis=1)))
        assert np.linalg.norm(held[0, i] - free[0, i]) < 0.05 * 1024 * irisd


def test_the_fold_limit_off_changes_nothing():
    v, f, lm, _ = _load(HEADS["mediapipe"])
    irisd = np.mean([e.gap for e in find_eyes(lm)]) / 1024.0
    blink = faps([{19: 900, 21: 124}])
    a = Eyelids(v, f, lm, irisd).apply(v[None], blink)
    b = Eyelids(v, f, lm, irisd, fold_deg=0.0).apply(v[None], blink)
    np.testing.assert_array_equal(a, b)
