"""The per-frame simulation loop (paper §9): controls in, skin positions out.

One frame at the motion's frame rate does, in this order (§6: the deeper layer
drives the shallower ones and never the reverse):

1. **skull**: the mandible's rigid transform from the jaw DOFs (pitch, yaw, protrusion);
2. **muscles**, layer by layer, from their contractions and the bones under them;
3. **skin**: the anchor particles follow their surface points on the deformed muscles
   and bones, then the skin's PBD constraints are projected (``solver.substeps`` x
   ``solver.iterations``);
4. the **influence map** weights the skin displacement: ``rest + w (sim - rest)``, then the
   rig's optional ``blend`` pass (given the simulated skin too) corrects the weighted frame in
   place, its optional ``parts`` step puts the pieces that ride a bone (eyeballs, teeth) where
   it is, and its optional ``finish`` pass corrects the frame in place.

The three layer steps are callables of a :class:`Rig` so the loop is independent of
how the layers are built (and testable with stand-ins); :func:`play` times each of
them per frame for the benchmark.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable

import numpy as np


@dataclass
class Rig:
    """The layered head as three steps.

    Attributes
    ----------
    skull : callable jaw (3,) float -> bones, an opaque value (e.g. cranium and mandible
        vertices (n_b, 3) float) handed to the next two steps
    muscles : callable (contractions (m,) float in [0, 1], bones, dt s) -> muscles, opaque
        (e.g. a list of muscle vertex arrays)
    skin : callable (bones, muscles, dt s) -> (n, 3) float skin positions (working mesh)
    rest : (n, 3) float, the skin at rest (working mesh)
    influence : (n,) float in [0, 1] or None (all ones)
    reset : callable () -> None, back to the rest state (optional)
    finish : callable (n, 3) float64 -> None, applied in place to each weighted frame (optional;
        e.g. :meth:`faceforge.animation.guards.orientation.OrientationGuard.apply`: the influence map
        blends rest and simulation with weights that vary from vertex to vertex, which can
        turn over a triangle the simulation kept upright)
    blend : callable (weighted frame (n, 3) float64, simulated skin (n, 3)) -> None, applied in
        place to each weighted frame before ``parts`` and ``finish`` (optional; e.g.
        :class:`faceforge.skin.fold_limit.BlendLimit`: where the blend bends the skin past its
        fold limit, the weights are raised toward the simulation)
    parts : callable (n, 3) float64 -> None, applied in place to each weighted frame after
        ``blend``, before ``finish`` (optional; e.g. :class:`faceforge.animation.rig.RigidParts`:
        the eyeballs and teeth of the mesh put rigidly on their bone)
    """

    skull: Callable
    muscles: Callable
    skin: Callable
    rest: np.ndarray
    influence: np.ndarray | None = None
    reset: Callable | None = None
    finish: Callable | None = None
    blend: Callable | None = None
    parts: Callable | None = None


@dataclass
class Timings:
    """Wall-clock seconds spent per layer, summed over ``frames`` frames."""

    skull: float = 0.0
    muscles: float = 0.0
    skin: float = 0.0
    frames: int = 0

    def per_frame_ms(self) -> dict:
        n = max(self.frames, 1)
        out = {k: 1e3 * getattr(self, k) / n for k in ("skull", "muscles", "skin")}
        out["total"] = sum(out.values())
        return out


def play(rig: Rig, contractions: np.ndarray, jaw: np.ndarray, fps: float, progress=None,
         timings: Timings | None = None, settle: int = 0, sink=None, chunk: int = 64) -> np.ndarray | None:
    """Simulate every frame and return the weighted skin.

    Parameters
    ----------
    rig : Rig
    contractions : (F, m) float in [0, 1]
    jaw : (F, 3) float, (pitch rad, yaw rad, protrusion skin units)
    fps : float > 0; each frame advances dt = 1 / fps
    progress : optional callable wrapping an iterable (``ctx.progress``); gets ``total=`` and
        ``desc=`` keywords
    timings : optional Timings, accumulated in place
    settle : extra frames simulated at each frame's controls before it is recorded (0 for
        playback; static poses such as calibration use more)
    sink : optional ``sink(start, frames (k, n, 3) float64)``: the frames are handed over
        ``chunk`` at a time (``start``: the first one's index; the array is reused, copy what
        you keep) and not returned, so a take's memory does not grow with its length

    Returns
    -------
    (F, n, 3) float64 skin positions of the working mesh, influence-weighted (None with ``sink``).

    Raises
    ------
    FloatingPointError if a frame produced a non-finite position (names the frame).
    """
    contractions = np.atleast_2d(np.asarray(contractions, dtype=float))
    jaw = np.atleast_2d(np.asarray(jaw, dtype=float))
    if len(contractions) != len(jaw) or jaw.shape[1] != 3:
        raise ValueError(f"contractions {contractions.shape} and jaw {jaw.shape} must be (F, m) and (F, 3)")
    if not fps > 0:
        raise ValueError(f"fps must be > 0, got {fps}")
    dt = 1.0 / fps
    rest = np.asarray(rig.rest, dtype=float)
    w = np.ones(len(rest)) if rig.influence is None else np.asarray(rig.influence, dtype=float)
    if w.shape != (len(rest),):
        raise ValueError(f"influence must be ({len(rest)},), got {w.shape}")
    size = len(jaw) if sink is None else max(1, min(int(chunk), len(jaw)))
    out = np.empty((size, len(rest), 3))
    w3 = w[:, None]
    frames = range(len(jaw))
    if progress is not None:
        frames = progress(frames, total=len(jaw), desc="frames")
    t = timings if timings is not None else Timings()
    for i in frames:
        for _ in range(settle + 1):
            t0 = time.perf_counter()
            bones = rig.skull(jaw[i])
            t1 = time.perf_counter()
            muscles = rig.muscles(contractions[i], bones, dt)
            t2 = time.perf_counter()
            skin = rig.skin(bones, muscles, dt)
            t3 = time.perf_counter()
            t.skull += t1 - t0
            t.muscles += t2 - t1
            t.skin += t3 - t2
            t.frames += 1
        skin = np.asarray(skin, dtype=float)
        if not np.all(np.isfinite(skin)):
            raise FloatingPointError(f"frame {i}: the simulation produced non-finite skin positions")
        j = i % size
        frame = out[j]   # rest + w (skin - rest), in place
        np.subtract(skin, rest, out=frame)
        np.multiply(w3, frame, out=frame)
        np.add(rest, frame, out=frame)
        finish_frame(rig, out[j], skin)
        if sink is not None and (j == size - 1 or i == len(jaw) - 1):
            sink(i - j, out[:j + 1])
    return out if sink is None else None


def finish_frame(rig: Rig, frame: np.ndarray, skin: np.ndarray) -> None:
    """The rig's passes over an influence-weighted ``frame (n, 3)`` float64, in place: ``blend``
    (given the simulated ``skin (n, 3)``), ``parts``, ``finish``; each when the rig has it."""
    if rig.blend is not None:
        rig.blend(frame, skin)
    if rig.parts is not None:
        rig.parts(frame)
    if rig.finish is not None:
        rig.finish(frame)


def ease_in(settle: int = 30, ramp: int | None = None) -> np.ndarray:
    """Fraction of a static pose's controls at each of its frames, ``(max(settle, ramp),)``:
    linear up to 1 over ``ramp`` frames (default a third of ``settle``), then held."""
    ramp = max(1, settle // 3) if ramp is None else max(1, int(ramp))
    return np.minimum(np.arange(1, max(settle, ramp) + 1) / ramp, 1.0)


def static_poses(rig: Rig, contractions: np.ndarray, jaw: np.ndarray, fps: float,
                 settle: int = 30, ramp: int | None = None) -> np.ndarray:
    """Settled skin for each independent pose: reset, ease the controls in linearly over
    ``ramp`` frames (default a third of ``settle``), hold them to frame ``settle``.

    A pose is approached, not jumped to: the jaw thrown open to 0.34 rad in one frame made
    the orbicularis oris diverge on the MakeHuman head (a Gauss-Seidel sweep cannot absorb
    a one-frame step of a centimetre).
    contractions (k, m), jaw (k, 3) -> (k, n, 3) float. Needs ``rig.reset``.
    """
    if rig.reset is None:
        raise ValueError("static_poses needs a rig with reset()")
    t = ease_in(settle, ramp)[:, None]
    out = []
    for c, j in zip(np.atleast_2d(contractions), np.atleast_2d(jaw)):
        rig.reset()
        out.append(play(rig, t * c, t * j, fps)[-1])
    rig.reset()
    return np.stack(out) if out else np.zeros((0,) + np.shape(rig.rest))


def warm_up(rig, contractions, jaw, fps: float, log, guards=()) -> float:
    """Play the track's first frame once and put the rig back at rest, so that the timed
    playback does not count numba's compilation of the kernels (about 35 s on the first run
    after an install or an upgrade; cached on disk afterwards). Logs the compilation when the
    frame took more than a second; returns its seconds. The rig is left at rest, also for an
    empty track. ``guards``: objects with a ``warm_up()`` (the orientation guard), whose kernels
    frame 0 does not reach (its rescans compiled at frame 9 of a first animate, issue 28)."""
    rig.reset()
    if not len(jaw):
        return 0.0
    t0 = time.perf_counter()
    play(rig, contractions[:1], jaw[:1], fps)
    for guard in guards:
        if guard is not None:
            guard.warm_up()
    seconds = time.perf_counter() - t0
    rig.reset()
    if seconds > 1.0:
        log(f"compiled the simulation kernels in {seconds:.0f} s (once: numba caches them)")
    return seconds
