"""One guarded skin step (beyond the paper): the §8 skin step, then the guards in turn.

:class:`GuardedSkinStep` is the rig's ``skin`` step (:class:`faceforge.animation.playback.Rig`):
it steps the skin layer on the muscles and bones, then

1. alternates the skull guard (:class:`faceforge.animation.guards.skull.SkullGuard`), the
   orientation guard (:class:`faceforge.animation.guards.orientation.OrientationGuard`) and the
   skin's fold limit (``skin.fold_deg``, :mod:`faceforge.skin.fold_limit`) until neither of
   the last two has anything left to do (at most ``rounds`` rounds, then on while the fold limit
   has work, up to :data:`FOLD_ROUNDS` times as many);
2. puts skin that slid into a bone back out (:class:`faceforge.animation.guards.bone_collision.
   BoneCollision`), again alternating with the orientation guard.
"""

from __future__ import annotations

import numpy as np


#: the skin's fold limit may keep the guards' alternation going up to this many times its rounds
#: (``animate.orientation_guard.rounds``): at ICT's upper lid in the viseme a the limit and the
#: orientation guard undo part of each other for a while (4 rounds left 6 edges folded, 8 left 2,
#: 16 none); a frame the limit has nothing to do on stops where it stopped without it
FOLD_ROUNDS = 4


def goes_on(work, rounds: int) -> bool:
    """Whether the guards' alternation (``animate.orientation_guard.fold_progress``) has a round after the
    ``len(work)`` it made: ``work`` (list of int) is the fold limit's projections in each round. Within
    its own ``rounds`` it does; past them only while the last round's work is below every earlier
    round's. Where the limit and the orientation guard undo each other (a pleat at an outer canthus of
    the levelled risorius's rig: triangles held 84 deg from their rest normals at the guard's floor, their
    quads folded 160 deg), each round makes as much work as the last and slides the pleat a little
    further: MakeHuman's pride.fap crept the canthus 0.10 units over 16 rounds, and the next frame's step
    brought it back (a one-frame spike)."""
    if len(work) < rounds or len(work) < 2:
        return True
    return work[-1] < min(work[:-1])


class GuardedSkinStep:
    """The rig's skin step with its guards.

    Parameters
    ----------
    system : faceforge.anatomy.layers.MusculoskeletalSystem (its world mesh starts with the
        bones, cranium then mandible, in the guard's order: ``from_parts`` puts them there)
    skin : faceforge.skin.layer.SkinSimulation
    guard : SkullGuard over ``{"cranium", "mandible"}``
    orientation : OrientationGuard or None (off)
    collision : BoneCollision or None (off)
    rounds : int >= 0, ``animate.orientation_guard.rounds`` (0: one skull-guard pass, no
        orientation guard)
    jaw : object whose ``transform`` is the mandible's current (4, 4) transform or None
        (:class:`faceforge.animation.rig.JawDrive`)
    progress : bool, ``animate.orientation_guard.fold_progress``: past its own ``rounds`` the alternation
        goes on only while the fold limit's work shrinks (:func:`goes_on`), and a stop with work left
        ends on an orientation pass; False: up to :data:`FOLD_ROUNDS` times its rounds while the limit
        has work
    """

    #: ``animate.orientation_guard.fold_progress`` (a step built without it, as tests do, goes on as before)
    progress = False

    def __init__(self, system, skin, guard, orientation, collision, rounds: int, jaw, progress: bool = False):
        self.system, self.skin, self.guard = system, skin, guard
        self.orientation, self.collision, self.rounds, self.jaw = orientation, collision, rounds, jaw
        self.progress = bool(progress)
        self.bone_rows = system.vertex_range("mandible").stop
        self.pushed = np.empty(len(guard.vertex), dtype=np.int64)

    def __call__(self, _bones, _muscles, dt: float) -> np.ndarray:
        """Step the skin by ``dt`` s and guard it; returns the simulated skin (n, 3)."""
        self.skin.step(self.system, dt)
        x = self.skin.layer.skin_positions(self.skin.state.positions)
        self._skull_and_orientation(x)
        self._collision(x)
        return self.skin.simulated()

    def _skull_and_orientation(self, x: np.ndarray) -> None:
        """The skull guard pushes vertices one by one along the bone's normals, which can turn
        a sliver over or fold an edge; the orientation guard moves them sideways, which can sink
        one below its floor, and so can the skin's fold limit (:meth:`SkinSimulation.limit_folds
        <faceforge.skin.layer.SkinSimulation.limit_folds>`): alternate until neither the
        orientation pass nor the fold limit has anything left to do. After the first round each
        looks again only where the others moved something (and the skull guard at what it pushed
        itself, which round-off may push again): a full pass's result."""
        guard, orientation, pushed = self.guard, self.orientation, self.pushed
        bones = self.system.world_view()[:self.bone_rows]
        k = 0
        folded = turned = none = np.zeros(0, dtype=np.int64)
        rounds = max(self.rounds, 1)
        work = []
        for r in range(FOLD_ROUNDS * rounds):
            only = None if r == 0 else np.concatenate([pushed[:k], turned, folded])
            k = guard.apply_stacked(x, bones, pushed, only)
            moved = None if r == 0 else np.concatenate([pushed[:k], folded])
            turned = orientation.touched if orientation is not None and orientation.apply(x, moved) else none
            # the skin's fold limit: a push or a turn may have folded an edge
            work.append(self.skin.limit_folds())
            folded = self.skin.folded if work[-1] else none
            if not len(folded) and (not len(turned) or r + 1 >= rounds):
                break   # past its own rounds the alternation goes on only while the fold limit has work
            if self.progress and not goes_on(work, rounds):
                if orientation is not None:   # the limit and the guard undo each other: end upright
                    orientation.apply(x, folded)
                break

    def _collision(self, x: np.ndarray) -> None:
        """Skin that slid into a bone beyond the triangle the skull guard holds it above (the
        lips onto the other jaw's teeth, the cheek over the cheekbone) is put back out. A vertex
        pushed out of one jaw's bone can land in the other's, and the orientation pass that
        follows can move one sideways into a bone again: the collision looks again until it
        finds nothing (at most ``rounds`` times), after the first pass only at what the last two
        passes moved (the rest was outside and has not moved since)."""
        collision, orientation = self.collision, self.orientation
        jaw = np.eye(4) if self.jaw.transform is None else self.jaw.transform
        again = None
        for _ in range(max(self.rounds, 1) if collision is not None else 0):
            if not collision.apply(x, {"mandible": jaw}, again):
                break
            again = collision.moved
            if orientation is not None and orientation.apply(x, collision.moved):
                again = np.concatenate([again, orientation.touched])
