"""The threads that project the parts of a partitioned model (:mod:`faceforge.pbd.partition`).

numba runs ``prange`` loops on one of three threading layers, picked at the first launch
(TBB first):

* TBB steals work: when another process holds a core, the calling thread projects the
  part nobody took, so a step costs at worst what one thread would take. (Measured on the
  shared 2-core machine, with another process busy on one core: two 24 us halves took
  47 us a launch under TBB, but 26 us at the median and 2.2 ms on average under OpenMP,
  whose barrier waits for a thread the system has put aside.)
* OpenMP: as fast on an idle machine, slow on a loaded one (above).
* numba's own workqueue: about 80 us a launch, more than a part's work; with it the parts
  are projected one after the other on the calling thread (the same result, see
  :mod:`faceforge.pbd.partition`).

pip's ``tbb`` wheel installs ``libtbb.so.12`` in ``<prefix>/lib``, where the dynamic loader
does not look; :func:`load_tbb` loads it by path so that numba's TBB layer finds it.
"""

from __future__ import annotations

import ctypes
import functools
import importlib
import os
import sys


@functools.cache
def load_tbb() -> bool:
    """Load TBB from the environment's ``lib`` folder if it is there; True when numba's
    TBB threading layer can then be used."""
    for prefix in dict.fromkeys((sys.prefix, sys.base_prefix)):
        for name in ("libtbb.so.12", "libtbb.12.dylib"):
            path = os.path.join(prefix, "lib", name)
            if os.path.exists(path):
                try:
                    ctypes.CDLL(path, mode=ctypes.RTLD_GLOBAL)
                except OSError:
                    continue
    return _layer_available("tbb")


def _layer_available(name: str) -> bool:
    try:
        importlib.import_module(f"numba.np.ufunc.{name}pool")
    except ImportError:
        return False
    return True


@functools.cache
def threaded() -> bool:
    """True when partitioned steps run their parts on threads: more than one thread is
    allowed (``NUMBA_NUM_THREADS``; ``faceforge batch`` gives each worker its share of the
    cores) and numba's threading layer (``NUMBA_THREADING_LAYER``, default TBB then OpenMP)
    is TBB or OpenMP."""
    import numba

    if numba.config.NUMBA_NUM_THREADS < 2:
        return False
    wanted = numba.config.THREADING_LAYER
    if wanted == "workqueue":
        return False
    if wanted == "omp":
        return _layer_available("omp")
    return load_tbb() or (wanted != "safe" and _layer_available("omp"))


def threads_used(partitions: int) -> int:
    """How many threads a step with ``partitions`` parts runs on (1: the calling thread)."""
    if partitions < 2 or not threaded():
        return 1
    import numba

    return min(int(partitions), int(numba.get_num_threads()))
