"""The shared step of every constraint projection: the scaled Lagrange multiplier.

Every kind linearises its constraint ``C(p)`` as in the paper's Eq. 1 and moves each
particle along its gradient, ``dp_i = s * w_i * grad_i C``. The scalar ``s`` unifies
the three stiffness modes (see :mod:`faceforge.pbd.settings`):

* PBD (``xpbd`` False): ``s = -k C / D`` with ``D = sum_i w_i |grad_i C|^2`` (Müller 2007,
  Eq. 9 scaled by k, the paper's Eq. 1);
* XPBD (``xpbd`` True, ``k == 1``, ``c = (1 - k_user) / k_user``): ``s = (-C - a lam) / (D + a)`` with
  the time-step scaled compliance ``a = c D`` (Macklin et al. 2016, Eq. 18). ``lam`` is
  the multiplier accumulated since the start of the substep.
"""

from __future__ import annotations

import numba

from faceforge.constants import NUMBA_OPTIONS

#: squared lengths (relative to the squared scale of the element) below this are
#: degenerate: the constraint gradient is undefined and the projection is skipped
DEGENERATE = 1e-24

#: numba options of the solver kernels: the project's (on-disk cache, numpy error model)
#: plus reciprocal multiplication and signed-zero freedom (no FMA contraction: it would
#: round a rest length differently from numpy, and the rest state must stay an exact fixed point).
#: These change rounding (one compiled kernel gives the same bytes run to run), never the
#: handling of NaN/inf, so the degenerate-input guards stay exact.
PBD_NUMBA = {**NUMBA_OPTIONS, "fastmath": {"arcp", "nsz"}, "boundscheck": False}


@numba.njit(inline="always", **PBD_NUMBA)
def _multiplier(value, denom, k, c, lam, xpbd):
    """Scaled multiplier ``s`` of one projection (float, units of C / |grad C|^2).

    value : C(p); denom : sum_i w_i |grad_i C|^2 (> 0); k : PBD stiffness in [0, 1];
    c : compliance ratio >= 0; lam : accumulated multiplier; xpbd : bool, False for the
    PBD modes (then c and lam are ignored: ``s = -k C / D``).
    """
    if xpbd:
        return (-k * value - c * denom * lam) / (denom * (1.0 + c))
    return -k * value / denom


#: constraints per batch of the vectorised sweeps (``_project_<kind>_batched``) and the
#: rows of their flat scratch buffer, ``(BATCH_ROWS * BATCH,) float64``
BATCH = 64
BATCH_ROWS = 40
