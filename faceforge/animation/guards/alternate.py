"""One guarded skin step (beyond the paper): the §8 skin step, then the guards in turn.

:class:`GuardedSkinStep` is the rig's ``skin`` step (:class:`faceforge.animation.playback.Rig`):
it steps the skin layer on the muscles and bones, then

1. alternates the skull guard (:class:`faceforge.animation.guards.skull.SkullGuard`), the
   orientation guard (:class:`faceforge.animation.guards.orientation.OrientationGuard`) and the
   skin's fold limit (``skin.fold_deg``, :mod:`faceforge.skin.fold_limit`) until neither of
   the last two has anything left to do (at most ``rounds`` rounds);
2. puts skin that slid into a bone back out (:class:`faceforge.animation.guards.bone_collision.
   BoneCollision`), again alternating with the orientation guard.
"""

from __future__ import annotations

import numpy as np


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
    """

    def __init__(self, system, skin, guard, orientation, collision, rounds: int, jaw):
        self.system, self.skin, self.guard = system, skin, guard
        self.orientation, self.collision, self.rounds, self.jaw = orientation, collision, rounds, jaw
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
        k, bent = 0, np.zeros(len(x), dtype=bool)
        folded = turned = np.zeros(0, dtype=np.int64)
        for r in range(max(self.rounds, 1)):
            only = None if r == 0 else np.concatenate([pushed[:k], turned, folded])
            k = guard.apply_stacked(x, bones, pushed, only)
            moved = None if r == 0 else np.concatenate([pushed[:k], folded])
            turned = orientation.touched if orientation is not None and orientation.apply(x, moved) \
                else np.zeros(0, dtype=np.int64)
            bent[:] = False   # the skin's fold limit: a push or a turn may have folded an edge
            folded = np.flatnonzero(bent) if self.skin.limit_folds(bent) else np.zeros(0, dtype=np.int64)
            if not len(turned) and not len(folded):
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


#: at most this many orientation / fold-limit rounds on a finished frame: at ICT's upper lid in the
#: viseme a the two undo part of each other for a while (4 rounds left 7 edges folded, 16 left 2,
#: 32 none and nothing turned over); a frame the limit has nothing to do on costs one round
FINISH_ROUNDS = 32


class FinishedFrame:
    """The rig's ``finish`` on each weighted frame (:class:`faceforge.animation.playback.Rig`)
    with a skin fold limit: the orientation guard, then the fold limit (the influence map's blend
    of rest and simulation, ``rest + w (skin - rest)``, can bend an edge the simulation kept
    within it where ``w`` falls off), in turn until the limit has nothing left to do (at most
    ``rounds`` rounds, :data:`FINISH_ROUNDS`).

    orientation : OrientationGuard or None; folds : (quads (m, 4) skin vertex ids, limits (m,)
    radians), :attr:`faceforge.skin.layer.SkinSimulation.fold_quads`; rounds : int >= 1.
    """

    def __init__(self, orientation, folds, rounds: int = FINISH_ROUNDS):
        self.orientation, (self.quads, self.limits), self.rounds = orientation, folds, max(int(rounds), 1)

    def __call__(self, frame: np.ndarray) -> None:
        """Finish ``frame`` ((n, 3) float64, C-contiguous) in place."""
        from faceforge.pbd.dihedral_limit import limit_dihedrals
        from faceforge.skin.fold_limit import FOLD_TOL

        moved, bent = None, np.zeros(len(frame), dtype=bool)
        for _ in range(self.rounds):
            if self.orientation is not None:
                self.orientation.apply(frame, moved)
            bent[:] = False
            if not limit_dihedrals(frame, self.quads, self.limits, touched=bent, tol=FOLD_TOL):
                return
            moved = np.flatnonzero(bent)
        if self.orientation is not None:   # the limit's last turn may not leave a triangle over
            self.orientation.apply(frame, moved)
