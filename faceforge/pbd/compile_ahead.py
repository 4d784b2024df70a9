"""Compile the step kernels ahead, in a background process, while a first run does other work.

On a fresh install numba compiles every kernel at its first call and caches it on disk; the
first ``calibrate`` spent ~100 s CPU compiling (measured, MediaPipe sample, cold cache, load
8-9: 131 s CPU against 32 s warm), 80 s of it the two step kernels
(:func:`~faceforge.pbd._kernels._step` and its threaded twin
:func:`~faceforge.pbd._kernels._step_parts`), which every layer of every solver runs.
Nothing before ``calibrate`` needs them, so they can compile on the other core
while ``fit`` and ``bind`` run: :func:`start` spawns ``python -m faceforge.pbd.warm`` when the
cache holds no compiled step for this source, and the first :class:`~faceforge.pbd.Solver` of
a process waits for it (:func:`wait`) instead of compiling the same code again.

``FACEFORGE_COMPILE_AHEAD=0`` turns it off. The background process holds an exclusive
``flock`` on :func:`lock_path` while it compiles; a
second :func:`start` (another workdir, a batch job) sees the lock and spawns nothing. Numba
writes its cache files through a temporary file and a rename, so a process killed mid-way
leaves no half-written cache. The results do not depend on any of this: only when the
compile happens.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

#: how long :func:`wait` waits for a background compile before compiling itself, seconds
WAIT_SECONDS = 600.0

_waited = False


def lock_path() -> Path:
    """The lock file beside the step kernels' numba cache (``__pycache__`` of
    :mod:`faceforge.pbd`, or ``NUMBA_CACHE_DIR``)."""
    from faceforge.pbd._kernels import _step

    return Path(_step._cache._cache_path) / "faceforge-warm.lock"


def cold() -> bool:
    """True when numba's cache holds no compiled step kernel for this source (a fresh
    install, or an edited kernel). numba's cache index is internal: when it cannot be read
    the answer is False (then nothing is spawned, and the kernels compile at first use as
    they always did)."""
    from faceforge.pbd._kernels import _step, _step_parts
    from faceforge.pbd.threads import threaded

    kernels = (_step, _step_parts) if threaded() else (_step,)
    try:
        return any(not k._cache._cache_file._load_index() for k in kernels)
    except Exception:   # noqa: BLE001 - numba internals changed: behave as before
        return False


def _held(path: Path) -> bool:
    """True when another process holds ``path``'s exclusive lock."""
    import fcntl

    try:
        with open(path, "a+b") as f:
            try:
                fcntl.flock(f, fcntl.LOCK_SH | fcntl.LOCK_NB)
            except BlockingIOError:
                return True
            fcntl.flock(f, fcntl.LOCK_UN)
    except OSError:
        return False
    return False


def start(log=lambda msg: None) -> subprocess.Popen | None:
    """Spawn the background compile when the cache is cold and nobody compiles yet; returns
    the process (None when nothing was spawned). Detached from the terminal's signals, its
    output discarded. It keeps the caller's CPU priority: a stage may wait for it (a lower
    priority starved it on a busy machine while the stage waited)."""
    if os.name != "posix" or os.environ.get("FACEFORGE_COMPILE_AHEAD", "1") == "0" or not cold():
        return None
    try:
        path = lock_path()
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None
    if _held(path):
        return None
    try:
        process = subprocess.Popen([sys.executable, "-m", "faceforge.pbd.warm"], stdin=subprocess.DEVNULL,
                                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                   start_new_session=True)
    except OSError:   # no process to spare: the kernels compile at first use, as without it
        return None
    log("compiling the solver's kernels in the background (first run after an install)")
    return process


def compiling_here() -> None:
    """Say that this process is the one compiling (``python -m faceforge.pbd.warm``): its own
    solver steps must not wait on the lock it holds."""
    global _waited
    _waited = True


def wait(log=lambda msg: None, timeout: float = WAIT_SECONDS) -> float:
    """Block while a background compile holds the lock (once per process); returns the
    seconds waited. After ``timeout`` it gives up and the kernels compile here as usual."""
    global _waited
    if _waited or os.name != "posix":
        return 0.0
    _waited = True
    try:
        path = lock_path()
    except Exception:   # noqa: BLE001 - as in cold()
        return 0.0
    t0 = time.perf_counter()
    if _held(path):
        log("waiting for the solver's kernels compiling in the background")
        while _held(path) and time.perf_counter() - t0 < timeout:
            time.sleep(0.2)
    return time.perf_counter() - t0
