"""A long take in constant memory (issue 28): the chunked checks equal the whole-take checks,
the streamed stage file is an ordinary npz read back through a map, the PC2/MDD writers take
a map, the thread choice follows the clock, and the orientation guard warms every kernel."""

from __future__ import annotations

import numpy as np
import pytest

from faceforge.animation.checks import check_animation
from faceforge.animation.check_stream import StreamChecker
from faceforge.io.export_cache import read_mdd, read_pc2, write_mdd, write_pc2
from faceforge.io.frame_stream import FrameNpzWriter, iter_chunks, open_frames
from faceforge.pbd import thread_choice
from faceforge.pbd.thread_choice import ThreadChooser
from tests.pbd.meshes import grid_faces


def grid(n=6):
    """A bumpy n x n grid (rest (n*n, 3), faces (2 (n-1)^2, 3))."""
    x, y = np.meshgrid(np.arange(n, dtype=float), np.arange(n, dtype=float))
    v = np.stack([x.ravel(), y.ravel(), 0.1 * np.sin(x.ravel() * 1.3) * np.cos(y.ravel())], axis=1)
    return v, grid_faces(n)


def wild_frames(rest, count=37, seed=0):
    """Frames that move, fold, turn triangles over, and one NaN."""
    rng = np.random.default_rng(seed)
    frames = rest + rng.normal(scale=0.05, size=(count,) + rest.shape) * np.linspace(0, 8, count)[:, None, None]
    frames[11, 3] = np.nan
    frames[20] = rest * [1, -1, 1]          # mirrored: everything turned over
    return frames


@pytest.mark.parametrize("chunk", [1, 5, 64])
def test_the_chunked_checks_equal_the_whole_take_checks(chunk):
    rest, faces = grid()
    frames = wild_frames(rest)
    tet = (np.array([[1.0, 1, -0.5], [4, 1, -0.5], [1, 4, -0.5], [1, 1, 0.5]]),
           np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]))   # a bone some frames sink into
    skull = lambda i: [tet]                                   # noqa: E731
    whole = check_animation(rest, frames, faces, skull=skull)
    stream = StreamChecker(rest, faces, len(frames))
    for part in iter_chunks(frames, chunk):
        stream.add(part)
    assert stream.report(skull=skull) == whole
    assert whole.non_finite == 1 and whole.inverted_triangles > 0 and whole.skin_inside_skull > 0


def test_the_streamed_npz_is_an_npz_and_maps(tmp_path):
    frames = np.random.default_rng(1).random((130, 17, 3)).astype(np.float32)
    path = tmp_path / "animation.npz"
    with FrameNpzWriter(path, 130, 17) as w:
        for part in iter_chunks(frames, 64):
            w.write(part)
        w.close(fps=np.float64(25.0), controls=np.array(["a", "bc"]))
    with np.load(path) as d:
        assert np.array_equal(d["frames"], frames) and d["fps"] == 25.0 and d["controls"].tolist() == ["a", "bc"]
    m = open_frames(path)
    assert isinstance(m, np.memmap) and np.array_equal(m, frames)
    assert float(open_frames(path, "fps")) == 25.0
    # the exporters take the map and write it chunk by chunk, the same bytes
    write_pc2(tmp_path / "a.pc2", m, None, 25.0)
    write_mdd(tmp_path / "a.mdd", m, None, 25.0)
    assert np.array_equal(read_pc2(tmp_path / "a.pc2")[0], frames)
    assert np.array_equal(read_mdd(tmp_path / "a.mdd")[0], frames)
    with pytest.raises(ValueError, match="announced"):
        with FrameNpzWriter(tmp_path / "short.npz", 3, 17) as w:
            w.write(frames[:2])
            w.close()


def test_the_thread_chooser_runs_the_faster_way_and_keeps_looking(monkeypatch):
    clock = {"t": 0.0}
    cost = {True: 2.0, False: 1.0}           # a busy machine: the threads lose
    monkeypatch.setattr(thread_choice.time, "perf_counter", lambda: clock["t"])

    def step(threaded):
        clock["t"] += cost[threaded]

    chooser = ThreadChooser(True)
    used = []
    for _ in range(200):
        use = chooser.pick()
        chooser.count -= 1                   # run() picks again
        used.append(use)
        chooser.run(step)
    assert sum(used[:8]) == 4                # both tried at the start
    late = used[8:]
    assert sum(late) <= len(late) // thread_choice.EXPLORE_EVERY * thread_choice.EXPLORE_STEPS + 2
    cost[True], cost[False] = 0.5, 1.0       # the other core came free: back to threads
    for _ in range(150):
        chooser.run(step)
    assert chooser.best() is True
    off = ThreadChooser(False)
    off.run(lambda threaded: used.append(("off", threaded)))
    assert used[-1] == ("off", False)


def test_the_orientation_guard_warms_every_kernel():
    from faceforge.animation.guards import orientation as og

    rest, faces = grid(4)
    guard = og.OrientationGuard(rest, faces)
    guard.warm_up()
    for kernel in (og._watched, og._rewatched, og._guard_rounds):
        assert kernel.signatures, kernel
    assert not guard._mark.any()
