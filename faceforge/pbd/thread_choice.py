"""Threads or not, decided by the clock, step by step (issue 28).

A partitioned step (:mod:`faceforge.pbd.partition`) projects its parts on numba's threads or
one after the other on the calling thread, with the same bits either way. On a quiet
machine the threads win (two parts: 0.63-0.70 of one thread's time); on a busy one (load
4-10 on 2 cores) the second thread waits for a core and two threads took 1.12-1.19 times as
long. :class:`ThreadChooser` times the steps of both ways and runs the faster: it tries
each a few times at the start, then spends :data:`EXPLORE_STEPS` of every
:data:`EXPLORE_EVERY` steps on the other way, so it follows the load as it changes. The
result cannot change (the tests compare both ways bit for bit); only the time does.
"""

from __future__ import annotations

import time
from collections import deque
from statistics import median

#: steps of each way tried at the start, alternating
FIRST_STEPS = 4
#: every this many steps, the way not in use is timed again ...
EXPLORE_EVERY = 100
#: ... for this many steps
EXPLORE_STEPS = 2
#: the recent step times kept per way (their median decides)
WINDOW = 5


class ThreadChooser:
    """Whether the next step runs on threads (:meth:`pick`), learnt from the times of the
    earlier ones (:meth:`run`). ``enabled=False``: always the calling thread."""

    def __init__(self, enabled: bool):
        self.enabled = bool(enabled)
        self.times = {True: deque(maxlen=WINDOW), False: deque(maxlen=WINDOW)}
        self.count = 0
        self.threaded_steps = 0

    def best(self) -> bool:
        """The way with the smaller median recent time (threads while one is unknown)."""
        a, b = self.times[True], self.times[False]
        if not a or not b:
            return True
        return median(a) <= median(b)

    def pick(self) -> bool:
        """True: run the next step's parts on threads."""
        if not self.enabled:
            return False
        self.count += 1
        if self.count <= 2 * FIRST_STEPS:
            return self.count % 2 == 1
        best = self.best()
        return (not best) if self.count % EXPLORE_EVERY < EXPLORE_STEPS else best

    def run(self, step, *args) -> None:
        """``step(threaded, *args)`` on the way :meth:`pick` chose, timed."""
        use = self.pick()
        if not self.enabled:
            step(False, *args)
            return
        t0 = time.perf_counter()
        step(use, *args)
        self.times[use].append(time.perf_counter() - t0)
        self.threaded_steps += use
