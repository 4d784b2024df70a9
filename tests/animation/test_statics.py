"""Held poses are solved until they stop changing (issue 25, item 6)."""

import numpy as np
import pytest

from faceforge.animation.playback import Rig
from faceforge.animation.statics import SettleSettings, SettleStats, settle


def relaxing_rig(rate=0.3, n=5):
    """A stand-in rig whose skin relaxes towards ``rest + c`` (x-offset) by ``rate`` of the gap
    a frame: a fixed point at the target, reached geometrically like a held PBD pose."""
    rest = np.zeros((n, 3))
    rest[:, 1] = np.arange(n, dtype=float)
    state = {"x": rest.copy()}

    def skin(bones, muscles, dt):
        target = rest + np.array([muscles, 0.0, 0.0])
        state["x"] = state["x"] + rate * (target - state["x"])
        return state["x"]

    def reset():
        state["x"] = rest.copy()

    return Rig(skull=lambda j: None, muscles=lambda c, b, dt: float(c[0]), skin=skin, rest=rest, reset=reset)


def test_a_held_pose_is_solved_to_its_tolerance_and_says_so():
    rig = relaxing_rig()
    diag = float(np.linalg.norm(np.ptp(rig.rest, axis=0)))
    stats = SettleStats()
    tight, loose = SettleSettings(tolerance=1e-8), SettleSettings(tolerance=1e-3)
    a = settle(rig, [[1.0]], np.zeros((1, 3)), 25.0, tight, stats=stats)[0]
    settle(rig, [[1.0]], np.zeros((1, 3)), 25.0, loose, stats=stats)
    assert np.allclose(a[:, 0], 1.0, atol=1e-7)              # at the fixed point, not 10 frames short of it
    assert stats.converged == [True, True]
    assert stats.residual[0] <= 1e-8 and stats.residual[1] <= 1e-3
    assert stats.frames[0] > stats.frames[1] > 10            # it holds until converged, more for less tolerance
    assert stats.residual[0] * diag == pytest.approx(abs(1.0 - a[0, 0]) * 0.3 / 0.7, rel=0.2)


def test_a_warm_pose_continues_from_the_last_and_settles_in_fewer_frames():
    rig = relaxing_rig()
    s = SettleSettings(tolerance=1e-6)
    cold, warm = SettleStats(), SettleStats()
    settle(rig, [[1.0], [1.05]], np.zeros((2, 3)), 25.0, s, stats=cold)
    b = settle(rig, [[1.0], [1.05]], np.zeros((2, 3)), 25.0, s, warm=True, stats=warm)
    assert np.allclose(b[1][:, 0], 1.05, atol=1e-5)
    assert warm.frames[1] < cold.frames[1]


def test_an_unconverged_pose_is_reported():
    stats = SettleStats()
    settle(relaxing_rig(rate=0.01), [[1.0]], np.zeros((1, 3)), 25.0,
           SettleSettings(tolerance=1e-9, max_frames=30), stats=stats)
    assert stats.converged == [False] and stats.frames == [30]
    assert stats.as_dict()["unconverged"] == 1


def test_offline_playback_converges_every_frame_where_real_time_lags():
    from faceforge.animation.playback import play
    from faceforge.animation.statics import play_converged

    c = np.linspace(0.0, 1.0, 6)[:, None]
    got = {}
    play_converged(relaxing_rig(), c, np.zeros((6, 3)), 25.0, lambda s, f: got.update({s: f.copy()}),
                   SettleSettings(tolerance=1e-9), chunk=4)
    frames = np.concatenate([got[0], got[4]])
    assert np.allclose(frames[:, 0, 0], c[:, 0], atol=1e-8)           # each frame at its converged pose
    lagging = play(relaxing_rig(), c, np.zeros((6, 3)), 25.0)
    assert np.abs(lagging[:, 0, 0] - c[:, 0]).max() > 0.1              # one step a frame lags behind


def flipping_rig(n=5, amplitude=0.01, rate=0.3):
    """A stand-in rig that settles like :func:`relaxing_rig` but one vertex flips between two
    states every frame (a held PBD pose whose residual stops falling)."""
    rig = relaxing_rig(rate=rate, n=n)
    inner, count = rig.skin, {"n": 0}

    def skin(bones, muscles, dt):
        count["n"] += 1
        x = inner(bones, muscles, dt).copy()
        x[0, 2] += amplitude * (count["n"] % 2)
        return x

    return Rig(skull=rig.skull, muscles=rig.muscles, skin=skin, rest=rig.rest, reset=rig.reset)


def test_a_pose_whose_residual_stops_falling_is_stopped_and_reported_unconverged():
    held, stalled = SettleStats(), SettleStats()
    settle(flipping_rig(), [[1.0]], np.zeros((1, 3)), 25.0, SettleSettings(tolerance=1e-6, max_frames=150),
           stats=held)
    settle(flipping_rig(), [[1.0]], np.zeros((1, 3)), 25.0, SettleSettings(tolerance=1e-6, max_frames=150,
                                                                           stall=20), stats=stalled)
    assert held.frames == [150] and held.converged == [False]
    assert stalled.converged == [False] and 20 < stalled.frames[0] < 60     # stopped once it stopped changing
    slow = SettleStats()       # a residual still falling (1 % a frame) is not a stall: held to the end
    settle(relaxing_rig(rate=0.01), [[1.0]], np.zeros((1, 3)), 25.0,
           SettleSettings(tolerance=1e-9, max_frames=80, stall=20), stats=slow)
    assert slow.frames == [80]


def test_a_pose_that_blows_up_stops_at_once():
    # an unstable fixed point (the step overshoots 3x the gap): the motion grows each frame; the
    # pose stops once a frame moves a vertex a fifth of the diagonal, not after max_frames
    stats = SettleStats()
    out = settle(relaxing_rig(rate=3.0), [[1.0]], np.zeros((1, 3)), 25.0,
                 SettleSettings(tolerance=1e-6, max_frames=150), stats=stats)
    assert stats.frames[0] < 15 and stats.converged == [False]
    assert np.abs(out[0, :, 0]).max() > 0.2 * 4.0     # what it reached is reported as it is


def test_a_pose_flipping_between_two_states_stops_once_the_rest_has_settled():
    # cycle: the skin back within the tolerance of where it was two frames before, 3 frames in a
    # row, while one vertex still flips by 0.01 a frame: stopped there, unconverged, with every
    # other vertex settled; the stall (40 frames without a 10 % fall, calibration's) waits longer
    diag = float(np.linalg.norm(np.ptp(flipping_rig().rest, axis=0)))
    stalled, cycled = SettleStats(), SettleStats()
    s = SettleSettings(tolerance=1e-6, max_frames=150, stall=40)
    settle(flipping_rig(rate=0.6), [[1.0]], np.zeros((1, 3)), 25.0, s, stats=stalled)
    out = settle(flipping_rig(rate=0.6), [[1.0]], np.zeros((1, 3)), 25.0, SettleSettings(
        tolerance=1e-6, max_frames=150, stall=40, cycle=3), stats=cycled)
    assert cycled.converged == [False] and cycled.frames[0] + 10 < stalled.frames[0]
    settled = out[0, 1:] - (flipping_rig().rest[1:] + [1.0, 0.0, 0.0])
    assert np.abs(settled).max() < 2 * 1e-6 * diag                  # all but the flipping vertex are there
    assert abs(out[0, 0, 2] - 0.005) < 2 * 1e-6 * diag              # the flipping one: the cycle's midpoint
    # the relaxation itself (no flip) never returns to where it was two frames before within the
    # tolerance before it has converged: the cycle stop leaves it alone
    plain, plain_cycle = SettleStats(), SettleStats()
    a = settle(relaxing_rig(), [[1.0]], np.zeros((1, 3)), 25.0, SettleSettings(tolerance=1e-6), stats=plain)
    b = settle(relaxing_rig(), [[1.0]], np.zeros((1, 3)), 25.0, SettleSettings(tolerance=1e-6, cycle=3),
               stats=plain_cycle)
    assert plain_cycle.frames == plain.frames and plain_cycle.converged == [True] and np.array_equal(a, b)


def test_the_cycle_stop_is_off_by_default_and_calibration_turns_it_on():
    from faceforge.io.config import load_config

    assert SettleSettings().cycle == 0 and SettleSettings.from_config(load_config(None)).cycle == 0
    assert int(load_config(None).get("animate.calibrate.cycle")) > 0


def test_the_calibration_one_off_poses_continue_from_the_pose_before_when_warm():
    # OneOffPoses (calibrate_head): the same controls are settled once; warm, the second pose
    # continues from the first (no reset, the 3-frame warm ramp) and lands on the same fixed point
    # within the tolerance in fewer frames than from rest
    from faceforge.animation.calibrate_head import OneOffPoses

    def to_controls(mapping, faps):
        faps = np.atleast_2d(faps)
        return faps[:, :1].copy(), np.zeros((len(faps), 3))

    s = SettleSettings(tolerance=1e-6)
    diag = float(np.linalg.norm(np.ptp(relaxing_rig().rest, axis=0)))
    out = {}
    for warm in (False, True):
        rig, stats = relaxing_rig(), SettleStats()
        resets = {"n": 0}
        inner = rig.reset

        def reset(inner=inner, resets=resets):
            resets["n"] += 1
            inner()

        rig = Rig(skull=rig.skull, muscles=rig.muscles, skin=rig.skin, rest=rig.rest, reset=reset)
        poses = OneOffPoses(rig, to_controls, 25.0, s, stats, warm=warm)
        a = poses(None, np.array([[1.0]]))
        b = poses(None, np.array([[1.1]]))
        assert poses(None, np.array([[1.0]])) is a and len(stats.frames) == 2     # settled once
        out[warm] = (a, b, stats.frames, resets["n"])
    assert out[False][3] == 2 and out[True][3] == 1                             # warm: the first from rest only
    assert out[True][2][1] < out[False][2][1]                                    # fewer frames for the second
    assert np.abs(out[True][1] - out[False][1]).max() < 10 * 1e-6 * diag         # the same pose
    assert np.array_equal(out[True][0], out[False][0])


def test_a_pose_watched_on_some_vertices_settles_once_they_do():
    """``SettleSettings(watch=...)``: the residual is the watched vertices' motion alone, so a pose
    whose vertex 0 flips (a dense scan's jittering lid rim) settles once the others do; the
    skin returned is still every vertex."""
    whole, seen = SettleStats(), SettleStats()
    settle(flipping_rig(), [[1.0]], np.zeros((1, 3)), 25.0, SettleSettings(tolerance=1e-6, max_frames=150),
           stats=whole)
    out = settle(flipping_rig(), [[1.0]], np.zeros((1, 3)), 25.0,
                 SettleSettings(tolerance=1e-6, max_frames=150, watch=(1, 2, 3)), stats=seen)
    assert whole.converged == [False] and whole.frames == [150]
    assert seen.converged == [True] and seen.frames[0] < 100
    assert out.shape == (1, 5, 3)
