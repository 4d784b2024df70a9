"""The lids' fold limit (``animate.eyelid_fold_deg``): a blink gathers the socket's lining onto the
dipping line where the lids meet, and near the canthi its sub-mm triangles folded (the bake's
eyeBlink shapes: MakeHuman 4 / 4, ICT 18 / 17, MediaPipe 1 / 1 folded edges). With the limit the
skin the lids move, flat at rest, bends at most that far, alternating with the orientation guard
(no triangle turned over either); both bend the skin around the lid margins, which stay where the
FAPs put them.

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


@pytest.mark.parametrize("name", sorted(HEADS))
def test_the_fold_limit_keeps_the_margins_where_the_faps_put_them(name):
    """The limit and the guard bend the skin around the lid margins (inverse mass 0 where the lids
    meet, :func:`faceforge.animation.lid_folds.margin_inv_mass`): the pinned vertices, the lid FDPs
    among them, end bit for bit where the lid field alone puts them; only near the corners do the
    margins ease free."""
    from faceforge.animation.eyelids import move_lids
    from faceforge.animation.lid_folds import lid_margins

    v, f, lm, _ = _load(HEADS[name])
    irisd = np.mean([e.gap for e in find_eyes(lm)]) / 1024.0
    blink = faps([{19: 900, 21: 124, 20: 900, 22: 124}])
    lids = Eyelids(v, f, lm, irisd, fold_deg=80.0)
    held = lids.apply(v[None], blink)
    field_only = move_lids(v[None], lids.fields, blink, irisd, v)
    pinned = lids.inv_mass == 0.0
    fdps = [int(np.argmin(np.linalg.norm(v - lm[k], axis=1))) for k in ("3.1", "3.2", "3.3", "3.4")]
    assert pinned[fdps].all()
    margins = np.concatenate([lid_margins(e, v, f) for e in find_eyes(lm)])
    assert np.isin(fdps, margins).all()                   # the margins found run through the lid FDPs
    assert pinned.sum() >= 8 and np.isin(np.flatnonzero(pinned), margins).all()
    np.testing.assert_array_equal(held[0, pinned], field_only[0, pinned])
    assert not np.array_equal(held, field_only)           # the limit did move the skin around them


def test_lid_margins_are_the_rows_on_the_margin_curves():
    """On a strip of skin rows, the margins are the rows nearest each margin curve (heights
    ``top s(u)`` and ``bottom s(u)``), within the corners and in front; the rows between, above and
    below, and the skin behind, are not."""
    from faceforge.animation.eyelids import Eye
    from faceforge.animation.lid_folds import lid_margins

    eye = Eye(np.zeros(3), np.eye(3), 1.0, 0.5, -0.5, 0.0, 0.0, 0.0, 19, 21)
    us, vs = np.linspace(-0.9, 0.9, 19), np.array([-1.0, -0.52, -0.2, 0.2, 0.47, 1.0])
    grid = np.array([[u, vv * eye.taper(u), 0.0] for vv in vs for u in us])
    back = grid + [0.0, 0.0, -5.0]            # the same rows far behind: a socket's lining
    rest = np.concatenate([grid, back])
    n = len(us)
    faces = []
    for off in (0, len(grid)):
        for r in range(len(vs) - 1):
            for c in range(n - 1):
                a, b = off + r * n + c, off + (r + 1) * n + c
                faces += [[a, a + 1, b], [a + 1, b + 1, b]]
    got = lid_margins(eye, rest, np.array(faces))
    rows = np.unique(got // n)
    assert rows.tolist() == [1, 4]            # v -0.52 (lower) and 0.47 (upper)
    assert len(got) == 2 * n
