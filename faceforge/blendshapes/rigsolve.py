"""The activation solve on a bound head: the ``simulate`` and ``observe`` callables of
:mod:`faceforge.blendshapes.solve` built from a rig (:class:`faceforge.animation.playback.Rig`),
and the two kinds of target the bake and the benchmarks use:

* a **displacement field** over the user's vertices (e.g. a MakeHuman expression unit), in the
  user's frame and units: :func:`field_observer`;
* **landmark motions in FAPU** (FAP values): each FAP's FDP displacement along the FAP's
  direction, as calibrate measures it (:class:`faceforge.animation.calibrate.Probe`):
  :func:`probe_observer`.
"""

from __future__ import annotations

import numpy as np

from faceforge.animation.calibrate import measure
from faceforge.animation.playback import static_poses


def settler(rig, fps: float, settle):
    """``simulate(contractions (k, m), jaw (k, 3)) -> (k, n, 3)``: each pose settled from rest,
    ``settle`` frames at ``fps`` (an int: :func:`faceforge.animation.playback.static_poses`) or
    until it stops moving (a :class:`faceforge.animation.statics.SettleSettings`; then
    ``simulate.stats`` is the :class:`~faceforge.animation.statics.SettleStats` of every pose, and
    ``simulate.warm`` settles poses continuing from the last one settled instead of from rest:
    a refinement of that pose settles in fewer frames; None for ``settle`` an int)."""
    if isinstance(settle, int):
        def simulate(c, jaw):
            return static_poses(rig, c, jaw, fps, settle=settle)
        simulate.stats = simulate.warm = None
        return simulate
    from faceforge.animation.statics import SettleStats, settle as settle_poses

    stats = SettleStats()
    held = {}

    def run(c, jaw, warm):
        out = settle_poses(rig, c, jaw, fps, settle, warm=warm, stats=stats, previous=held.get("now"))
        if len(c):
            held["now"] = (np.array(c[-1], dtype=float), np.array(jaw[-1], dtype=float))
        return out

    def simulate(c, jaw):
        return run(c, jaw, False)

    simulate.stats = stats
    simulate.warm = lambda c, jaw: run(c, jaw, True)
    return simulate


def field_observer(rest: np.ndarray, user_index: np.ndarray, user_rotation: np.ndarray | None = None):
    """``observe(frames (k, n, 3)) -> (k, 3 n_user)``: the displacement of each user vertex from
    rest, in the user's frame (``head = user @ R.T``, so ``user = head @ R``), flattened.

    rest : (n, 3) working skin at rest; user_index : (n_user,) working vertex of each user vertex
    """
    rest = np.asarray(rest, dtype=float)
    idx = np.asarray(user_index, dtype=np.int64)
    R = np.eye(3) if user_rotation is None else np.asarray(user_rotation, dtype=float)

    def observe(frames):
        d = np.asarray(frames, dtype=float)[:, idx] - rest[idx]
        return (d @ R).reshape(len(d), -1)

    return observe


def probe_observer(rest: np.ndarray, probes: list):
    """``observe(frames (k, n, 3)) -> (k, len(probes))``: each probe's FDP motion in FAPU
    (:func:`faceforge.animation.calibrate.measure`)."""
    rest = np.asarray(rest, dtype=float)

    def observe(frames):
        frames = np.asarray(frames, dtype=float)
        return np.stack([measure(rest, frames, p) for p in probes], axis=1).reshape(len(frames), len(probes))

    return observe
