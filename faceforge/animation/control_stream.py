"""A FAP file's controls a block of frames at a time (paper §9; issue 28: a take's memory does
not grow with its length).

:class:`ControlBlocks` reads a :class:`~faceforge.mpeg4.fap_stream.FapFile` block by block and
gives, per block, what :func:`faceforge.animation.controls.track_controls` and
:func:`faceforge.animation.head_motion.head_angles` give for those frames of the whole track
(every step is frame by frame, so the blocks' controls are the whole track's, bit for bit);
:meth:`ControlBlocks.summary` is one pass gathering what the stage logs and reports before and
after playing (unmapped FAPs, the largest head turn, visemes played, ...).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Iterator

import numpy as np


@dataclass
class ControlBlock:
    """One block of frames: ``faps (k, 68)`` low-level FAPs (:func:`~faceforge.animation.controls.track_faps`),
    ``c (k, m)`` contractions in ``head.controls`` order, ``jaw (k, 3)`` (pitch rad, yaw rad,
    protrusion skin units), ``angles (k, 3)`` head turn (pitch, yaw, roll) rad (zeros when the
    head does not turn), ``viseme (k, 4)`` the FAP 1 parameters, ``start``: the index of its
    first frame in the track."""

    start: int
    faps: np.ndarray
    c: np.ndarray
    jaw: np.ndarray
    angles: np.ndarray
    viseme: np.ndarray


@dataclass
class TrackSummary:
    """What a pass over the whole track found: ``unmapped`` FAP numbers with values but no
    mapping (as :func:`~faceforge.animation.controls.track_controls` lists them), ``max_angles
    (3,)`` largest |head turn| rad per axis, ``moving (68,)`` bool FAPs with a nonzero value in
    some frame, ``visemes`` the names played (code order) and ``viseme_frames`` in how many
    frames, ``max_contraction`` (0 without muscles), ``max_jaw (3,)`` largest jaw DOFs."""

    n_frames: int = 0
    unmapped: list = field(default_factory=list)
    max_angles: np.ndarray = field(default_factory=lambda: np.zeros(3))
    moving: np.ndarray = field(default_factory=lambda: np.zeros(68, bool))
    visemes: list = field(default_factory=list)
    viseme_frames: int = 0
    max_contraction: float = 0.0
    max_jaw: np.ndarray = field(default_factory=lambda: np.full(3, -np.inf))


class ControlBlocks:
    """The controls of ``fap_file`` (a :class:`~faceforge.mpeg4.fap_stream.FapFile`) through
    ``mapping`` on ``head`` (:class:`~faceforge.animation.rig.BoundHead`), a block at a time;
    ``turn``: compute the head angles (FAPs 48-50). Iterate it (any number of times) for
    :class:`ControlBlock` s."""

    def __init__(self, fap_file, mapping, head, turn: bool):
        self.fap_file, self.mapping, self.head, self.turn = fap_file, mapping, head, bool(turn)
        self.n_frames, self.fps = fap_file.n_frames, fap_file.fps

    def __iter__(self) -> Iterator[ControlBlock]:
        for block in self._blocks(None):
            yield block

    def _blocks(self, missing: set | None) -> Iterator[ControlBlock]:
        from faceforge.animation.controls import controls, track_faps
        from faceforge.animation.head_motion import head_angles

        start = 0
        for track in self.fap_file.blocks():
            faps, lacking = track_faps(track, self.mapping)
            if missing is not None:
                missing.update(lacking)
            c, jaw = controls(self.mapping, faps, self.head)
            angles = head_angles(faps) if self.turn else np.zeros((len(faps), 3))
            yield ControlBlock(start, faps, c, jaw, angles, track.viseme)
            start += len(faps)

    def summary(self) -> TrackSummary:
        """One pass over the track (:class:`TrackSummary`)."""
        from faceforge.animation.fap_mapping import viseme_weights
        from faceforge.mpeg4.visemes import VISEME_CODES

        out, missing = TrackSummary(), set()
        played = np.zeros(len(VISEME_CODES), bool)
        for block in self._blocks(missing):
            out.n_frames += len(block.faps)
            out.moving |= np.abs(block.faps).max(axis=0) > 0
            out.max_angles = np.maximum(out.max_angles, np.abs(block.angles).max(axis=0))
            if block.c.size:
                out.max_contraction = max(out.max_contraction, float(block.c.max()))
            out.max_jaw = np.maximum(out.max_jaw, block.jaw.max(axis=0))
            w = viseme_weights(block.viseme) > 0.0   # FAP 1: the visemes selected with a weight
            played |= w.any(axis=0)
            out.viseme_frames += int(w.any(axis=1).sum())
        names = sorted(VISEME_CODES, key=VISEME_CODES.get)
        out.visemes = [name for name in names if played[VISEME_CODES[name] - 1]]
        mapped = set(self.mapping.mapped_faps().tolist())
        out.unmapped = sorted(int(k + 1) for k in np.flatnonzero(out.moving) if k + 1 not in mapped)
        if missing:
            out.unmapped = [1, *out.unmapped]
        return out
