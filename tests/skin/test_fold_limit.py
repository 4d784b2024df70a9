"""The skin's fold limit (``skin.fold_deg``): the quads flat at rest are picked with their limits
(skin.fold_limit), and the guards' alternation keeps them within it (animation.guards.alternate)."""

import numpy as np

from faceforge.animation.guards.alternate import GuardedSkinStep
from faceforge.animation.guards.orientation import OrientationGuard
from faceforge.pbd import SolverSettings
from faceforge.pbd.constraints.bending import dihedral_angle
from faceforge.skin.binding import Body, bind_skin
from faceforge.skin.fold_limit import fold_limits
from faceforge.skin.layer import SkinSimulation, SkinStiffness, skin_topology
from tests.skin.synthetic import grid


def creased_sheet():
    """A 4 x 4 grid folded 70 deg along its middle column line (x = 0.5): the quads on that line
    are bent at rest, the rest flat."""
    v, f = grid(4, 4)
    v = v.copy()
    right = v[:, 0] > 0.5 + 1e-9
    t = np.radians(70)
    d = v[right, 0] - 0.5
    v[right, 0], v[right, 2] = 0.5 + d * np.cos(t), d * np.sin(t)
    return v, f


def test_fold_limits_hold_the_flat_quads_and_the_corners_tighter():
    v, f = creased_sheet()
    quads = skin_topology(f).bending_quads
    bent = np.degrees(np.abs(dihedral_angle(v, quads)))
    assert (bent > 60).any() and (bent < 1e-6).any()
    q, lim = fold_limits(v, f, 80.0)
    flat = quads[bent < 60]
    np.testing.assert_array_equal(q, flat)
    np.testing.assert_allclose(lim, np.radians(80.0))
    # a commissure quad gets the tighter limit, bent at rest or not, and appears once
    corner = quads[[int(np.argmax(bent)), int(np.argmin(bent))]]
    q2, lim2 = fold_limits(v, f, 80.0, corner, 75.0)
    assert len(q2) == len(flat) + 1
    for c in corner:
        row = np.flatnonzero((q2 == c).all(axis=1))
        assert len(row) == 1 and lim2[row[0]] == np.radians(75.0)
    # the corners alone (skin.fold_deg 0), and nothing with both off
    q3, lim3 = fold_limits(v, f, 0.0, corner, 75.0)
    assert len(q3) == 2 and np.all(lim3 == np.radians(75.0))
    assert fold_limits(v, f, 0.0, corner, 0.0) is None
    assert fold_limits(v, f, 0.0) is None


def sheet(fold_deg):
    """A 4 x 4 sheet's skin layer on a body just under it, with or without the fold limit."""
    v, f = grid(4, 4)
    b = bind_skin(v, f, [Body("muscle", "muscle", v + [0.0, 0.0, -0.05], f)], max_distance=0.5)
    return v, f, SkinSimulation(v, f, b, SkinStiffness(), SolverSettings(iterations=10),
                                fold_limit=fold_limits(v, f, fold_deg))


class PushingGuard:
    """A skull guard that, on its full pass, pushes vertex 12 over its lower-left neighbour (as the
    guard's push along a bone's normal can fold an edge); on later passes it finds nothing."""

    def __init__(self, n):
        self.vertex = np.arange(n)

    def apply_stacked(self, x, bones, pushed, only):
        if only is not None:
            return 0
        x[12] += [-0.45, -0.45, 0.05]
        pushed[0] = 12
        return 1


class NoBones:
    def world_view(self):
        return np.zeros((0, 3))


def guarded(fold_deg, orientation):
    """The sheet's skin after the guards' alternation with :class:`PushingGuard`."""
    v, f, sim = sheet(fold_deg)
    step = GuardedSkinStep.__new__(GuardedSkinStep)
    step.system, step.skin, step.guard, step.rounds, step.bone_rows = NoBones(), sim, PushingGuard(len(v)), 4, 0
    step.orientation = OrientationGuard(v, f) if orientation else None
    step.pushed = np.empty(len(v), dtype=np.int64)
    x = sim.layer.skin_positions(sim.state.positions)
    step._skull_and_orientation(x)
    return v, f, sim.simulated()


def test_the_guards_alternation_undoes_the_fold_a_push_makes():
    quads = skin_topology(grid(4, 4)[1]).bending_quads
    for orientation in (False, True):
        v, f, free = guarded(0.0, orientation)
        assert np.degrees(np.abs(dihedral_angle(free, quads))).max() > 90
        v, f, held = guarded(80.0, orientation)
        assert np.degrees(np.abs(dihedral_angle(held, quads))).max() < 80.5   # Gauss-Seidel: within a hair
        # the pushed vertex keeps its push: the limit turns the quads' wings about their edges
        assert np.linalg.norm(held[12] - v[12]) > 0.3


def blended_sheet(shift: float):
    """A 4 x 4 sheet moved as one, ``shift`` along (1, 0, 1) / sqrt 2 (the simulation keeps it flat),
    with an influence map of 1 but at the middle vertex (12, 0.9) and a corner (0, 0.99): the
    blend ``rest + w (skin - rest)`` leaves the middle vertex a tenth of the shift behind."""
    v, f = grid(4, 4)
    skin = v + shift * np.array([1.0, 0.0, 1.0]) / np.sqrt(2.0)
    w = np.ones(len(v))
    w[12], w[0] = 0.9, 0.99
    return v, f, skin, w


def test_the_blend_limit_raises_the_weights_where_the_blend_folds_the_skin():
    from faceforge.skin.fold_limit import BlendLimit
    from faceforge.skin.influence import apply_influence

    v, f, skin, w = blended_sheet(10.0)
    quads = skin_topology(f).bending_quads
    plain = apply_influence(v, skin, w)
    # the plain blend folds the quads round the middle vertex (it lags 0.7 behind, past its neighbour)
    assert np.degrees(np.abs(dihedral_angle(plain, quads))).max() > 90
    limit = BlendLimit(v, w, *fold_limits(v, f, 80.0))
    frame = plain.copy()
    assert limit(frame, skin) > 0
    assert np.degrees(np.abs(dihedral_angle(frame, quads))).max() <= 80.0 + np.degrees(limit.tol) + 1e-6
    # each vertex stays on its way from rest to the simulation, at a weight no lower than its own
    move = skin - v
    got = ((frame - v) * move).sum(axis=1) / (move * move).sum(axis=1)
    np.testing.assert_allclose(frame, v + got[:, None] * move, atol=1e-12)
    assert np.all(got >= w - 1e-12) and np.all(got <= 1.0 + 1e-12)
    assert 12 in limit.raised and got[12] > w[12]
    # the corner, whose quads the blend does not fold, keeps its weight bit for bit
    np.testing.assert_array_equal(frame[0], plain[0])


def test_the_blend_limit_leaves_a_frame_within_the_limit_bit_for_bit():
    from faceforge.skin.fold_limit import BlendLimit
    from faceforge.skin.influence import apply_influence

    v, f, skin, w = blended_sheet(0.5)
    plain = apply_influence(v, skin, w)
    frame = plain.copy()
    assert BlendLimit(v, w, *fold_limits(v, f, 80.0))(frame, skin) == 0
    np.testing.assert_array_equal(frame, plain)


def test_playback_and_statics_apply_the_rigs_blend_limit():
    from faceforge.animation.playback import Rig, play
    from faceforge.animation.statics import SettleSettings, settle
    from faceforge.skin.fold_limit import BlendLimit

    v, f, skin, w = blended_sheet(10.0)
    quads = skin_topology(f).bending_quads

    def rig(blend):
        return Rig(skull=lambda jaw: None, muscles=lambda c, b, dt: None, skin=lambda b, m, dt: skin.copy(),
                   rest=v, influence=w, reset=lambda: None, blend=blend)

    def most(frames):
        return np.degrees(np.abs(dihedral_angle(frames[-1], quads))).max()

    c, jaw = np.zeros((2, 1)), np.zeros((2, 3))
    limit = BlendLimit(v, w, *fold_limits(v, f, 80.0))
    assert most(play(rig(None), c, jaw, 30.0)) > 90
    assert most(play(rig(limit), c, jaw, 30.0)) < 80.1
    s = SettleSettings(ramp=1, min_hold=1, max_frames=4)
    assert most(settle(rig(None), c, jaw, 30.0, s)) > 90
    assert most(settle(rig(limit), c, jaw, 30.0, s)) < 80.1
