"""An ARKit weight track played through the muscles of the baked shapes (issue 27).

Each frame's controls are the baked shapes' controls mixed by the frame's weights: contractions
``w @ C`` clipped to ``[0, max contraction]``, jaw DOFs ``w @ J`` clipped to the mapping's
limits, eyelid FAPs ``w @ L`` (the kinematic lids) and eye turns ``w @ G`` (eyeball pieces, when
the mesh has them). The frames are simulated like any take
(:func:`faceforge.animation.take.play_take`: a block at a time, real time or converged).

The rig is not additive: shapes played together move less (or more) than their sum, and a take's
frames read back against the baked shapes (``--curves``) give other weights than were played
(MakeHuman, a joy take's curves replayed: RMS 0.045, ``mouthLowerDown`` 0.86 -> 0.57).
:func:`refine_drive` corrects the drive a round at a time (``animate.arkit_rounds``) so that the
played face reads back as the take's weights.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterator

import numpy as np

from faceforge.animation.control_stream import ControlBlock
from faceforge.animation.take import play_take

#: frames simulated per block of a weight track
BLOCK = 1024
#: the largest drive :func:`refine_drive` gives a shape: its baked pose (driven past it, the lagging start of
#: a take overshot into other shapes: ICT, noseSneer read 0.40 where none was played, at a cap of 1.5)
DRIVE_MAX = 1.0


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


def refine_drive(play_back, target: np.ndarray, rounds: int, upper: float = DRIVE_MAX,
                 log=print) -> tuple[np.ndarray, list]:
    """The drive whose played take reads back as ``target``: a fixed-point correction in weight
    space, ``drive <- clip(drive - (back - target), 0, upper)`` per round, from ``drive = target``.

    play_back
        ``play_back(drive (F, k)) -> back (F, k)``: the take played with that drive and its
        frames' weights solved against the baked shapes (as ``--curves`` solves them).
    target
        ``(F, k)`` the take's weights in [0, 1], one column per made shape (0 where the take
        has none).
    rounds
        corrections (each one playback and one solve); 0 returns the target itself.

    Returns ``(drive (F, k), errors)``, ``errors`` a dict per round of the read-back error of the
    drive played in it: ``{"rms", "max"}`` (weights).
    """
    target = np.asarray(target, float)
    drive = target.copy()
    errors = []
    for r in range(rounds):
        err = np.asarray(play_back(drive), float) - target
        errors.append({"rms": float(np.sqrt(np.mean(err ** 2))), "max": float(np.abs(err).max(initial=0.0))})
        log(f"round {r + 1}: the played take reads back {errors[-1]['rms']:.4f} RMS, "
            f"{errors[-1]['max']:.3f} at most, off its weights")
        drive = np.clip(drive - err, 0.0, upper)
    return drive, errors


def played_readback(head, fps: float, baked, rows, mapping, scratch, *, ridge: float, smooth: float,
                    lids=None, offline=None, log=print):
    """``play_back(drive)`` for :func:`refine_drive`: plays ``drive (F, len(rows))`` through the
    baked shapes ``rows`` into the ``.npz`` at ``scratch`` (overwritten each call; the caller
    removes it) and solves the frames' weights against the same shapes
    (:func:`faceforge.blendshapes.curves.solve_weights` with ``ridge`` and ``smooth``, as
    ``--curves`` does) -> ``(F, len(rows))``."""
    from faceforge.blendshapes.curves import solve_weights
    from faceforge.io.frame_stream import FrameNpzWriter, open_frames, release

    def play_back(drive: np.ndarray) -> np.ndarray:
        with FrameNpzWriter(scratch, len(drive), len(head.user_index)) as writer:
            play_weights(head, drive, fps, baked, rows, mapping, writer, lids=lids, offline=offline,
                         log=lambda *_: None)
            writer.close()
        frames = open_frames(scratch)
        try:
            return solve_weights(frames, baked["neutral"], baked["shapes"][rows], ridge=ridge, smooth=smooth)
        finally:
            release(frames)
            del frames
    return play_back
