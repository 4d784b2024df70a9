"""``animate.eyelid_relative`` (faceforge.animation.eyelids.Eyelids._refer): the lids' fold limit and guard are
held to the simulated frame the lids are laid over, so the lids straighten only what they bend. On the
levelled risorius's rig the simulation left MakeHuman's outer canthi bent past the lids' limit in
pride.fap's jaw frames; the limit and the guard, undoing each other over their rounds, crept the corner
0.05-0.2 units in one frame.

Real data: the MakeHuman sample head and its FDPs (samples/), as tests/animation/test_eyelids.py loads them.
"""

import numpy as np
import pytest

from faceforge.animation.eyelids import Eyelids, find_eyes
from faceforge.animation.lid_folds import referred_floors, referred_limits
from faceforge.pbd.constraints.bending import dihedral_angle

from tests.animation.test_eyelids import HEADS, _load, faps

OPEN = np.array([[0.4, 0.0, 0.0]])    # the jaw open (radians of pitch), no lid FAP: the jaw hold's take-back


def test_referred_limits_and_floors_keep_what_the_frame_already_has():
    """A quad bent past its limit in the frame keeps its bend as its limit (below pi); a triangle below
    its floor keeps its area as its floor, one turned over is left alone (-inf)."""
    quad = np.array([[0, 1, 2, 3]])
    flat = np.array([[0.0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, -1, 0]])
    bent = flat.copy()
    bent[3] = [0.5, 0.1, 0.98]            # folded past 90 deg towards the other wing
    lim = np.radians([80.0])
    assert np.allclose(referred_limits(flat, quad, lim), lim)
    assert np.isclose(referred_limits(bent, quad, lim)[0], abs(dihedral_angle(bent, quad)[0]))
    faces = np.array([[0, 1, 2], [0, 1, 2], [0, 1, 2]])
    n0 = np.array([[0.0, 0, 1], [0, 0, 1], [0, 0, -1]])
    floor = np.array([0.1, 0.9, 0.1])     # the triangle's area is 0.5 along +z
    assert np.allclose(referred_floors(flat, faces, n0, floor)[:2], [0.1, 0.5])
    assert referred_floors(flat, faces, n0, floor)[2] == -np.inf


@pytest.mark.parametrize("relative", [False, True])
def test_a_fold_the_simulation_left_under_the_lid_is_not_straightened(relative):
    """A pleat below the lower lid (one vertex pushed out along its normal until quads the lids' limit holds
    are bent past it; nothing turned over), the jaw open, no lid FAP: the upper lids take the (zero) drift
    back and the lids' limit and guard run. Held to the frame, they leave the pleat exactly as it was; held to
    rest (the former behaviour) the limit flattens it, moving skin nothing asked the lids to move."""
    v, f, lm, _ = _load(HEADS["makehuman"])
    eyes = find_eyes(lm)
    irisd = np.mean([e.gap for e in eyes]) / 1024.0
    lids = Eyelids(v, f, lm, irisd, fold_deg=80.0, jaw_hold=1.0, relative=relative)
    field, eye = lids.fields[0], lids.fields[0].eye
    x = (v[field.index] - eye.centre) @ eye.axes.T
    low_margin = eye.margins[1] * eye.taper(x[:, 0])
    pick = (x[:, 1] < low_margin - 0.3 * eye.gap) & (np.abs(x[:, 0]) < 0.3 * eye.half) \
        & (field.up_hold == 0.0) & (lids.inv_mass[field.index] == 1.0)
    quads = lids._fold.quads
    p = int(field.index[pick][np.argmin(np.abs(x[pick, 1] - low_margin[pick] + 0.5 * eye.gap))])
    ring = quads[(quads == p).any(axis=1)]
    assert len(ring) >= 4
    normal = np.cross(v[f[(f == p).any(axis=1)]][:, 1] - v[f[(f == p).any(axis=1)]][:, 0],
                      v[f[(f == p).any(axis=1)]][:, 2] - v[f[(f == p).any(axis=1)]][:, 0]).sum(axis=0)
    normal /= np.linalg.norm(normal)
    edge = np.mean(np.linalg.norm(v[ring[:, 0]] - v[ring[:, 1]], axis=1))
    frame = v.copy()
    frame[p] += 3.0 * edge * normal
    assert np.degrees(np.abs(dihedral_angle(frame, ring))).max() > 85.0
    out = lids.apply(frame[None], faps([{}]), OPEN)[0]
    moved = np.linalg.norm(out - frame, axis=1)
    if relative:
        assert moved.max() == 0.0
    else:
        assert moved.max() > 0.05 * edge
