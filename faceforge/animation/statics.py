"""Held poses solved until they stop changing (issue 25, item 6).

Real-time playback (:func:`faceforge.animation.playback.play`) advances every frame by the
paper's fixed ``solver.iterations`` Gauss-Seidel sweeps, which leaves the skin short of its
equilibrium. A *held* pose (a calibration probe, a sheet's expression or viseme, a baked
shape) is a static problem: the controls are eased in and then held, frame after frame (each
frame ``solver.iterations`` more sweeps, its velocities damped), until the skin no longer
moves. The frame-to-frame motion is the residual of that fixed point ``x = step(x)``: it is
what this module watches, and what it reports.

A pose may start from rest (``warm=False``: the rig is reset, the controls eased in from
zero) or continue from the previous pose (``warm=True``: eased from the previous pose's
controls), which a sequence of nearby poses (calibration's secant steps on one drive)
settles in a few frames instead of a ramp from rest.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from faceforge.animation.playback import finish_frame


@dataclass
class SettleStats:
    """What :func:`settle` did, per pose (appended in call order).

    frames : frames simulated per pose (ramp + hold)
    residual : last frame-to-frame motion of the skin per pose, as a fraction of the rest
        skin's bounding-box diagonal (the largest vertex move)
    converged : whether it fell below the tolerance before ``max_frames``
    """

    frames: list = field(default_factory=list)
    residual: list = field(default_factory=list)
    converged: list = field(default_factory=list)

    def as_dict(self) -> dict:
        f, r = np.asarray(self.frames, dtype=float), np.asarray(self.residual, dtype=float)
        return {"poses": len(self.frames), "frames": int(f.sum()) if len(f) else 0,
                "frames_per_pose_median": float(np.median(f)) if len(f) else None,
                "frames_per_pose_max": int(f.max()) if len(f) else None,
                "residual_max": float(r.max()) if len(r) else None,
                "residual_median": float(np.median(r)) if len(r) else None,
                "unconverged": int(len(self.converged) - sum(self.converged))}


@dataclass(frozen=True)
class SettleSettings:
    """How a held pose is settled.

    ramp : frames over which the controls are eased in from rest (a cold pose)
    warm_ramp : frames over which they move from the previous pose's (a warm pose)
    tolerance : stop when the skin moved less than this fraction of the rest diagonal in one
        frame (the residual of the held pose's fixed point)
    min_hold, max_frames : frames held at the least after the ramp; frames in all at the most
    stall : stop a held pose whose residual has not fallen below ``STALL_DROP`` x its lowest
        so far for this many frames (it stopped changing: a vertex flipping between two states
        settles no further; reported unconverged); 0 holds such a pose to ``max_frames``
    cycle : stop a held pose once, for this many frames in a row, every vertex came back to
        within ``tolerance`` of where it was two frames before while some vertex still moved more
        than that in the last frame: a vertex flipping between two states (a period-2 cycle of
        the fixed-point iteration), which ``stall`` waits out for its whole count of frames;
        reported unconverged, the pose returned is the cycle's midpoint. 0: off (the sheets, the
        bake); calibration's probes use ``animate.calibrate.cycle``
    watch : (k,) int skin vertex indices whose motion alone is the residual (tolerance, stall,
        cycle, blow-up), or None: every skin vertex. A caller that reads only those vertices
        (calibration reads its FDPs: ``animate.calibrate.watch_fdps``) stops a pose once they
        settled, whatever the rest of a dense mesh still does
    """

    ramp: int = 10
    warm_ramp: int = 3
    tolerance: float = 5e-5
    min_hold: int = 2
    max_frames: int = 150
    stall: int = 0
    cycle: int = 0
    watch: tuple | None = None

    @classmethod
    def from_config(cls, config) -> "SettleSettings":
        """``animate.statics.*`` of a faceforge config (defaults where absent)."""
        def get(key, default):
            try:
                value = config.get(f"animate.statics.{key}")
            except (KeyError, AttributeError):
                return default
            return default if value is None else value

        # ``cycle`` is calibration's (animate.calibrate.cycle), set by its caller
        return cls(ramp=int(get("ramp", cls.ramp)), warm_ramp=int(get("warm_ramp", cls.warm_ramp)),
                   tolerance=float(get("tolerance", cls.tolerance)), min_hold=int(get("min_hold", cls.min_hold)),
                   max_frames=int(get("max_frames", cls.max_frames)), stall=int(get("stall", cls.stall)))


def settle(rig, contractions: np.ndarray, jaw: np.ndarray, fps: float, settings: SettleSettings | None = None,
           warm: bool = False, stats: SettleStats | None = None, previous=None) -> np.ndarray:
    """Settled skin for each pose, in order, each solved until it stops moving.

    rig : faceforge.animation.playback.Rig (with ``reset``)
    contractions : (k, m) float in [0, 1]; jaw : (k, 3) float (pitch rad, yaw rad, protrusion)
    fps : frame rate (each frame advances 1 / fps s)
    warm : continue each pose from the one before (the first from ``previous``, the controls
        ``(c (m,), jaw (3,))`` the rig currently holds, or from rest when None) instead of
        resetting the rig
    stats : a :class:`SettleStats` to append to (optional)

    Returns (k, n, 3) float64, influence-weighted and finished as :func:`play` returns frames.
    The rig is left holding the last pose (call ``rig.reset()`` to go back to rest).
    """
    s = settings or SettleSettings()
    c_all = np.atleast_2d(np.asarray(contractions, dtype=float))
    j_all = np.atleast_2d(np.asarray(jaw, dtype=float))
    if len(c_all) != len(j_all):
        raise ValueError(f"contractions {c_all.shape} and jaw {j_all.shape} differ in length")
    dt = 1.0 / float(fps)
    rest = np.asarray(rig.rest, dtype=float)
    tol = s.tolerance * float(np.linalg.norm(np.ptp(rest, axis=0)))
    w = None if rig.influence is None else np.asarray(rig.influence, dtype=float)[:, None]
    out = np.empty((len(c_all),) + rest.shape)
    prev_c, prev_j = (None, None) if previous is None else (np.asarray(previous[0], float),
                                                            np.asarray(previous[1], float))
    for i, (c, j) in enumerate(zip(c_all, j_all)):
        if not warm or prev_c is None:
            if rig.reset is None:
                raise ValueError("settle needs a rig with reset()")
            rig.reset()
            prev_c, prev_j, ramp = np.zeros_like(c), np.zeros_like(j), s.ramp
        else:
            ramp = s.warm_ramp
        skin, frames, motion = _hold(rig, prev_c, prev_j, c, j, dt, max(1, ramp), s, tol)
        if not np.all(np.isfinite(skin)):
            raise FloatingPointError(f"pose {i}: the simulation produced non-finite skin positions")
        frame = rest + (skin - rest) * (1.0 if w is None else w)
        finish_frame(rig, frame, skin)
        out[i] = frame
        prev_c, prev_j = c, j
        if stats is not None:
            stats.frames.append(frames)
            stats.residual.append(motion / (tol / s.tolerance))
            stats.converged.append(bool(motion <= tol))
    return out


#: a held pose's residual must fall below this fraction of its lowest so far to count as still settling
STALL_DROP = 0.9
#: a frame that moves a vertex by more than this fraction of the diagonal has blown up: the pose
#: stops there (a jaw opened 31 mm in one frame moves 8 %; MakeHuman's diverging right risorius took 50 s)
BLOWN_UP = 0.2


def _hold(rig, c0, j0, c1, j1, dt, ramp, s: SettleSettings, tol):
    """Ease (c0, j0) -> (c1, j1) over ``ramp`` frames, then hold until a frame moves the skin
    less than ``tol``, its residual stalls (``s.stall``), it flips between two states
    (``s.cycle``, :func:`_two_cycle`) or ``s.max_frames``. Returns (raw skin (n, 3), frames, last
    motion)."""
    last, motion, n = None, np.inf, 0
    watch = None if s.watch is None else np.asarray(s.watch, dtype=np.int64)
    best, since = np.inf, 0
    before, flips = None, 0                      # the skin two frames back; frames in a row back on it
    while n < s.max_frames:
        t = min(1.0, (n + 1) / ramp)
        c, j = c0 + t * (c1 - c0), j0 + t * (j1 - j0)
        bones = rig.skull(j)
        skin = np.asarray(rig.skin(bones, rig.muscles(c, bones, dt), dt), dtype=float)
        n += 1
        if last is not None:
            motion = float(np.sqrt(((_seen(skin, watch) - _seen(last, watch)) ** 2).sum(axis=1).max()))
        if s.cycle:
            flips = flips + 1 if before is not None and motion > tol and _two_cycle(
                _seen(skin, watch), _seen(before, watch), tol) else 0
            before = last
        last = skin.copy()
        if n >= ramp + s.min_hold and motion <= tol:
            break
        if s.cycle and flips >= s.cycle and n >= ramp + s.min_hold:
            # flipping between two states: unconverged, reported; the pose is the cycle's midpoint (the
            # rig holds the last state)
            return 0.5 * (last + before), n, motion
        if n > 1 and not motion <= BLOWN_UP * tol / s.tolerance:
            break                                # blown up (or non-finite): nothing to settle
        if n > ramp:
            if motion < STALL_DROP * best:
                best, since = motion, n
            elif s.stall and n - since >= s.stall and n >= ramp + s.min_hold:
                break                            # the residual stopped changing: unconverged, reported
    return last, n, motion


def _seen(skin: np.ndarray, watch) -> np.ndarray:
    """The rows of ``skin (n, 3)`` the residual watches: ``watch (k,)`` int, or all (None)."""
    return skin if watch is None else skin[watch]


def _two_cycle(skin: np.ndarray, before: np.ndarray, tol: float) -> bool:
    """Whether no vertex of ``skin (n, 3)`` is farther than ``tol`` from where it was two frames
    before (``before (n, 3)``)."""
    return float(((skin - before) ** 2).sum(axis=1).max()) <= tol * tol


def play_converged(rig, contractions: np.ndarray, jaw: np.ndarray, fps: float, sink,
                   settings: SettleSettings | None = None, stats: SettleStats | None = None,
                   chunk: int = 64, previous: tuple | None = None) -> None:
    """Offline playback (``animate.quality: offline``): every frame of a track is held at its
    controls until the skin stops moving (warm from the frame before, no ramp), so each
    exported frame is the converged pose instead of the real-time ``solver.iterations`` sweeps'
    approximation. Frames go to ``sink(start, frames (k, n, 3))`` ``chunk`` at a time, as
    :func:`faceforge.animation.playback.play` hands them over. Costs several times real time.
    ``previous``: the controls ``(c (m,), jaw (3,))`` of the frame before ``contractions[0]`` when
    a long track is played a block at a time (the rig, holding that frame, is then not reset;
    blocks of a multiple of ``chunk`` frames give the whole track's frames).
    """
    s = settings or SettleSettings()
    s = SettleSettings(ramp=1, warm_ramp=1, tolerance=s.tolerance, min_hold=0, max_frames=s.max_frames)
    c_all = np.atleast_2d(np.asarray(contractions, dtype=float))
    j_all = np.atleast_2d(np.asarray(jaw, dtype=float))
    if previous is None:
        rig.reset()
        previous = (np.zeros(c_all.shape[1]), np.zeros(3))
    for start in range(0, len(j_all), chunk):
        stop = min(start + chunk, len(j_all))
        frames = settle(rig, c_all[start:stop], j_all[start:stop], fps, s, warm=True, stats=stats,
                        previous=previous)
        previous = (c_all[stop - 1], j_all[stop - 1])
        sink(start, frames)
