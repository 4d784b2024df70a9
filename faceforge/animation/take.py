"""Play a whole take a block at a time into a frame writer (paper §9, issue 28's streaming).

A take's controls come as blocks (:class:`~faceforge.animation.control_stream.ControlBlocks`);
each block is simulated (:func:`~faceforge.animation.playback.play`, the paper's real-time
iterations, or :func:`~faceforge.animation.statics.play_converged` for offline quality), and its
frames pass, a chunk at a time, through the kinematic lids and eyeballs, the physical checks, the head turn
and the user's vertex order into the writer. Nothing here holds more than a block: a take's
memory does not grow with its length.
"""

from __future__ import annotations

import time

import numpy as np

from faceforge.animation.check_stream import StreamChecker
from faceforge.animation.eyeballs import apply_gaze, gaze_from_faps
from faceforge.animation.head_motion import turn_head
from faceforge.animation.playback import play, warm_up


def play_take(head, source, writer, *, weights=None, lids=None, timings=None, offline=None,
              bar=None, log=print, overlay=None, eyes=None) -> StreamChecker:
    """Simulate every block of ``source`` on ``head`` and write its frames.

    head
        the :class:`~faceforge.animation.rig.BoundHead` (rest ``(n, 3)``, rig, ``to_user``).
    source
        the take's control blocks: ``n_frames``, ``fps`` and, per block, ``start``, ``c (f, m)``,
        ``jaw (f, 3)``, ``faps (f, 68)`` and ``angles (f, 3)`` radians.
    writer
        a :class:`~faceforge.io.frame_stream.FrameNpzWriter` for ``(F, n_user, 3)`` frames; the
        contractions and jaw values are spooled to it as ``contractions`` and ``jaw``.
    weights
        ``(n,)`` neck weights of the head turn (None: the head does not turn).
    lids
        the kinematic eyelids (:meth:`BoundHead.eyelids`) or None.
    offline
        :class:`~faceforge.animation.statics.SettleSettings` to solve each frame to convergence,
        or None for real time (``solver.iterations`` a frame, timed into ``timings``).
    bar
        a progress bar (``update(1)`` per frame) or None.
    overlay
        ``overlay(frames (k, n, 3), first) -> frames``, kinematic pieces moved over the skin after
        the lids (``first``: the index of the first frame in the take), or None.
    eyes
        the mesh's eyeball pieces (:func:`faceforge.animation.eyeballs.eye_pieces`), turned by the
        block's eyeball FAPs 23-26 after the lids, or None.

    Returns the :class:`StreamChecker` that saw every frame (in the skull's frame, lids
    included, before the head turn). A diverging simulation raises ``FloatingPointError``.
    """
    checker = StreamChecker(head.rest, head.faces, source.n_frames, inside_at_rest=head.inside_at_rest())
    checker.carried = head.carried_check()   # a proxy-simulated head: its user mesh's turned triangles too

    def per_frame(frames, **_):   # one progress bar over the blocks
        for i in frames:
            yield i
            if bar is not None:
                bar.update(1)

    previous = None
    for block in source:
        def sink(start, frames, block=block):
            stop = start + len(frames)
            if lids is not None:   # kinematic, over the simulated skin; before the checks, which see them
                frames = lids.apply(frames, block.faps[start:stop], block.jaw[start:stop])
            if eyes:
                gaze = gaze_from_faps(block.faps[start:stop])
                if gaze.any():
                    frames = apply_gaze(frames, gaze, eyes)
            if overlay is not None:
                frames = overlay(frames, block.start + start)
            checker.add(frames)
            carried = None
            if checker.carried is not None:   # carried once: the check's frames are the written ones
                carried = head.carried(frames)
                checker.carried.add(carried)
            if weights is not None:   # (a head turn after the checks: those frames are carried again)
                frames, carried = turn_head(frames, block.angles[start:stop], head.skull.jaw.yaw_point, weights), None
            writer.write(head.to_user(frames) if carried is None else head.user_frame(carried))

        if not block.start:   # leaves the rig at rest
            warm_up(head.rig, block.c, block.jaw, source.fps, log, guards=(head.orientation,))
        if offline is not None:
            from faceforge.animation.statics import play_converged

            t0 = time.perf_counter()
            play_converged(head.rig, block.c, block.jaw, source.fps, sink, offline, previous=previous)
            if timings is not None:   # all layers: the held frames are not split
                timings.skin += time.perf_counter() - t0
                timings.frames += len(block.c)
            previous = (block.c[-1], block.jaw[-1])
        else:                 # real time: solver.iterations a frame
            play(head.rig, block.c, block.jaw, source.fps, progress=per_frame, timings=timings, sink=sink)
        writer.spool("contractions", block.c)
        writer.spool("jaw", block.jaw)
    return checker


def take_weights(head, summary, neck_fade: float):
    """``(n,)`` neck weights of the take's head turn, or None when it does not turn: the head
    turns as a whole about the top of the spine (the midpoint of the jaw's condyles), the skin
    below the skull fading out over ``neck_fade`` of the bone's height; a second, detached head
    in the mesh does not turn (weight 0)."""
    if not np.any(summary.max_angles):
        return None
    from faceforge.animation.head_motion import neck_weights
    from faceforge.animation.head_parts import detached_vertices

    low, high = head.bone_heights()
    weights = neck_weights(head.rest, low, neck_fade * (high - low))
    weights[detached_vertices(head.rest, head.faces, list(head.fdp_vertex.values()))] = 0.0
    return weights
