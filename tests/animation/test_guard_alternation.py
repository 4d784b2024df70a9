"""``animate.orientation_guard.fold_progress`` (faceforge.animation.guards.alternate): past its own rounds
the guards' alternation with the skin's fold limit goes on only while the limit's work shrinks, and a stop
with work left ends on an orientation pass. Where the limit and the guard undo each other, each round made
as much work as the last and slid the skin a little further (MakeHuman's outer canthus on the levelled
risorius's rig, pride.fap: 0.10 units over 16 rounds in one frame, back the next)."""

import numpy as np
import pytest

from faceforge.animation.guards.alternate import FOLD_ROUNDS, GuardedSkinStep, goes_on


def test_goes_on_within_its_rounds_and_past_them_only_while_the_work_shrinks():
    assert goes_on([5], 4) and goes_on([5, 6, 7], 4)
    assert not goes_on([5, 5, 5, 5], 4)
    assert goes_on([9, 8, 7, 6], 4) and goes_on([9, 8, 7, 6, 5], 4)
    assert not goes_on([9, 8, 7, 6, 6], 4) and not goes_on([9, 3, 7, 6, 4], 4)


class Creep:
    """A skin whose fold limit always finds the same work and slides vertex 0 along x (a pleat the
    orientation guard folds again each round), with an orientation guard that turns it back along y."""

    def __init__(self):
        self.x = np.zeros((3, 3))
        self.calls = []
        self.folded = np.array([0])

    def limit_folds(self):
        self.calls.append("fold")
        self.x[0, 0] += 0.01
        return 5


class Turning:
    def __init__(self, skin):
        self.skin, self.touched = skin, np.array([0])

    def apply(self, x, moved=None):
        self.skin.calls.append("orient")
        x[0, 1] += 0.005
        return 1


class Still:
    vertex = np.arange(3)

    def apply_stacked(self, x, bones, pushed, only):
        return 0


class NoBones:
    def world_view(self):
        return np.zeros((0, 3))


def _alternate(progress):
    skin = Creep()
    step = GuardedSkinStep.__new__(GuardedSkinStep)
    step.system, step.skin, step.guard, step.rounds, step.bone_rows = NoBones(), skin, Still(), 4, 0
    step.orientation, step.progress = Turning(skin), progress
    step.pushed = np.empty(3, dtype=np.int64)
    step._skull_and_orientation(skin.x)
    return skin


@pytest.mark.parametrize("progress", [False, True])
def test_a_limit_and_a_guard_undoing_each_other_stop_after_the_guards_rounds(progress):
    """Without the key the pair runs all FOLD_ROUNDS x rounds and the vertex slides 16 steps; with it,
    the alternation stops once the limit's work no longer shrinks (after the guard's own 4 rounds), on an
    orientation pass, and the vertex slides 4."""
    skin = _alternate(progress)
    folds = skin.calls.count("fold")
    if progress:
        assert folds == 4 and skin.calls[-1] == "orient"
        assert skin.x[0, 0] == pytest.approx(0.04)
    else:
        assert folds == FOLD_ROUNDS * 4
        assert skin.x[0, 0] == pytest.approx(0.01 * FOLD_ROUNDS * 4)
