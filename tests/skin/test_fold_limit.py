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
