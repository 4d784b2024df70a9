"""An ARKit weight track played through the muscles of the baked shapes (issue 27).

Each frame's controls are the baked shapes' controls mixed by the frame's weights: contractions
``w @ C`` clipped to ``[0, max contraction]``, jaw DOFs ``w @ J`` clipped to the mapping's
limits, eyelid FAPs ``w @ L`` (the kinematic lids) and eye turns ``w @ G`` (eyeball pieces, when
the mesh has them). The frames are simulated like any take
(:func:`faceforge.animation.take.play_take`: a block at a time, real time or converged).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterator

import numpy as np

from faceforge.animation.control_stream import ControlBlock
from faceforge.animation.take import play_take

#: frames simulated per block of a weight track
BLOCK = 1024


def mixed_controls(w: np.ndarray, baked, rows, mapping, levers_pitch: float) -> tuple[np.ndarray, np.ndarray]:
    """Contractions ``(k, m)`` and jaw DOFs ``(k, 3)`` of the baked shapes ``rows`` mixed by the
    weights ``w (k, len(rows))``, clipped to their ranges (protrusion limits are in jaw-lever
    units: scaled by ``levers_pitch``, skin units per unit)."""
    c = np.clip(w @ baked["contractions"][rows], 0.0, mapping.max_contraction)
    jaw = w @ baked["jaw"][rows]
    for k, dof in enumerate(("pitch", "yaw", "protrusion")):
        lo, hi = mapping.jaw_limits.get(dof, (0.0, 0.0))
        scale = levers_pitch if dof == "protrusion" else 1.0
        jaw[:, k] = np.clip(jaw[:, k], lo * scale, hi * scale)
    return c, jaw


@dataclass
class WeightBlocks:
    """The controls of a weight track ``weights (F, k)`` over the baked shapes ``rows`` (indices
    into the bake's arrays, one per column), a block of :data:`BLOCK` frames at a time, as the
    :class:`~faceforge.animation.control_stream.ControlBlock` s that ``play_take`` plays (``faps``
    carries the lid FAPs; the head does not turn)."""

    weights: np.ndarray
    baked: dict
    rows: list
    mapping: object
    levers_pitch: float
    fps: float

    @property
    def n_frames(self) -> int:
        return len(self.weights)

    def __iter__(self) -> Iterator[ControlBlock]:
        lids = self.baked["lids"][self.rows]
        for start in range(0, self.n_frames, BLOCK):
            w = self.weights[start:start + BLOCK]
            c, jaw = mixed_controls(w, self.baked, self.rows, self.mapping, self.levers_pitch)
            yield ControlBlock(start, w @ lids, c, jaw, np.zeros((len(w), 3)), np.zeros((len(w), 4)))


def play_weights(head, weights: np.ndarray, fps: float, baked, rows, mapping, writer, *, lids=None,
                 timings=None, offline=None, bar=None, log=print):
    """Simulate the weight track ``weights (F, len(rows))`` at ``fps`` on ``head`` (a
    :class:`~faceforge.animation.rig.BoundHead`) through the baked shapes ``rows`` of ``baked``
    (``shapes.npz``'s arrays) and write its frames to ``writer``; the eyes turn when the bake
    has gaze and the mesh eyeball pieces. Returns the
    :class:`~faceforge.animation.check_stream.StreamChecker` that saw every frame."""
    source = WeightBlocks(weights, baked, rows, mapping, head.levers.pitch, fps)
    overlay = _eye_turns(head, weights, baked["gaze"][rows]) if "gaze" in baked else None
    return play_take(head, source, writer, lids=lids, timings=timings, offline=offline, bar=bar, log=log,
                     overlay=overlay)


def _eye_turns(head, weights: np.ndarray, gaze: np.ndarray):
    """The overlay that turns the eyeball pieces by ``weights @ gaze`` (``gaze (k, 4)`` radians per
    shape), or None when no shape turns the eyes."""
    if not np.any(gaze):
        return None
    from faceforge.animation.eyeballs import apply_gaze, eye_pieces

    eyes = eye_pieces(head.rest, head.faces, head.landmarks)
    return lambda frames, first: apply_gaze(frames, weights[first:first + len(frames)] @ gaze, eyes)
