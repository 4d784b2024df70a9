"""The activation solve: muscle contractions and jaw pose whose settled skin best matches a
target motion (issue 25 item 2; Sifakis et al. 2005 solve activations from markers the same way).

The simulation is a black box ``simulate(contractions (k, m), jaw (k, 3)) -> (k, n, 3)`` that
settles ``k`` independent static poses, and ``observe(frames (k, n, 3)) -> (k, d)`` turns skin
positions into what the target speaks of: a displacement field over the face (``d = 3 n_face``)
or landmark motions in FAPU (``d`` = number of FAPs). The solve

1. builds a Jacobian ``J (d, q)`` by settling each control alone at its probe level
   (:func:`jacobian`: one static pose per control, the secant from rest);
2. solves ``min |J x - y|^2 + ridge |x|^2`` with the bounds of each control (contractions in
   [0, 1], the jaw within its limits) by ``scipy.optimize.lsq_linear``;
3. refines with Gauss-Newton (chord) passes through the simulation: settle the pose, take the
   residual ``y - f(x)``, solve for a step within the bounds with the same ``J``, keep it only
   when the residual falls (:func:`solve_activations`).

Nothing here knows about heads or files: the pipeline supplies ``simulate``, ``observe`` and
the control space. Lengths are the skin's units; jaw pitch and yaw are radians, protrusion is
skin units.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: the jaw's three DOFs, in ``jaw (3,)`` order
JAW_DOFS = ("pitch", "yaw", "protrusion")


@dataclass(frozen=True)
class ControlSpace:
    """The unknowns of a solve.

    names : (q,) str, each a contraction column name of the head (``head.controls``) or
        ``"jaw.pitch"``, ``"jaw.yaw"``, ``"jaw.protrusion"``
    lower, upper : (q,) float bounds ([0, max contraction] for muscles; the jaw's limits)
    probe : (q,) float, nonzero: the level each control is settled at to build the Jacobian
    columns : (m,) str, the head's contraction columns (``head.controls``)
    """

    names: tuple
    lower: np.ndarray
    upper: np.ndarray
    probe: np.ndarray
    columns: tuple

    def __post_init__(self):
        q = len(self.names)
        for k in ("lower", "upper", "probe"):
            if np.shape(getattr(self, k)) != (q,):
                raise ValueError(f"{k} must be ({q},), got {np.shape(getattr(self, k))}")
        if np.any(np.asarray(self.lower) > np.asarray(self.upper)):
            raise ValueError("lower bounds above upper bounds")

    def pose(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(k, q) or (q,) control values -> contractions (k, m) and jaw (k, 3)."""
        x = np.atleast_2d(np.asarray(x, dtype=float))
        c = np.zeros((len(x), len(self.columns)))
        jaw = np.zeros((len(x), 3))
        for j, name in enumerate(self.names):
            if name.startswith("jaw."):
                jaw[:, JAW_DOFS.index(name[4:])] = x[:, j]
            else:
                c[:, self.columns.index(name)] = x[:, j]
        return c, jaw

    def subset(self, names) -> "ControlSpace":
        """The space restricted to ``names`` (in this space's order; unknown names ignored)."""
        keep = [j for j, n in enumerate(self.names) if n in set(names)]
        return ControlSpace(tuple(self.names[j] for j in keep), np.asarray(self.lower)[keep],
                            np.asarray(self.upper)[keep], np.asarray(self.probe)[keep], self.columns)


def control_space(columns, muscles, jaw_limits: dict, pitch_lever: float, max_contraction: float = 1.0,
                  muscle_probe: float = 0.5, jaw_probe: float = 0.5) -> ControlSpace:
    """The default space: the named ``muscles`` (those of ``columns``, e.g. the mapping's active
    muscles and ``orbicularis_oris.protrude``) in [0, ``max_contraction``], and each jaw DOF
    whose limits are not [0, 0].

    jaw_limits : {dof: (lo, hi)} as in a FAP mapping (pitch, yaw rad; protrusion a fraction of
        ``pitch_lever``, the condyles -> chin distance in skin units)
    Probes: ``muscle_probe`` x the contraction range, ``jaw_probe`` x the larger side of each
    jaw range (the side a probe settles at).
    """
    names, lo, hi, probe = [], [], [], []
    for name in columns:
        if name in set(muscles):
            names.append(name)
            lo.append(0.0)
            hi.append(float(max_contraction))
            probe.append(muscle_probe * float(max_contraction))
    for dof in JAW_DOFS:
        a, b = jaw_limits.get(dof, (0.0, 0.0))
        scale = pitch_lever if dof == "protrusion" else 1.0
        a, b = a * scale, b * scale
        if a == b == 0.0:
            continue
        names.append(f"jaw.{dof}")
        lo.append(a)
        hi.append(b)
        probe.append(jaw_probe * (b if b >= -a else a))
    return ControlSpace(tuple(names), np.asarray(lo), np.asarray(hi), np.asarray(probe), tuple(columns))


def jacobian(simulate, observe, space: ControlSpace) -> np.ndarray:
    """Secant Jacobian ``J (d, q)``: column j is ``observe(pose with control j at its probe) /
    probe_j`` (one settled static pose per control; rest observes as zero)."""
    x = np.diag(np.asarray(space.probe, dtype=float))
    c, jaw = space.pose(x)
    obs = np.asarray(observe(simulate(c, jaw)), dtype=float)
    return (obs / np.asarray(space.probe, dtype=float)[:, None]).T


@dataclass
class SolveResult:
    """x (q,) control values; contractions (m,), jaw (3,); frame (n, 3) the settled skin at x;
    observed (d,) its observation; residuals: |y - f(x)| / |y| after the linear solve and each
    accepted refinement pass (the first entry the linear solve)."""

    x: np.ndarray
    contractions: np.ndarray
    jaw: np.ndarray
    frame: np.ndarray
    observed: np.ndarray
    residuals: list = field(default_factory=list)


def bounded_lsq(J: np.ndarray, y: np.ndarray, lower, upper, ridge: float = 1e-3) -> np.ndarray:
    """argmin over lower <= x <= upper of ``|J x - y|^2 + sum_j lam_j x_j^2`` with ``lam_j = ridge``
    x the squared norm of column j (a small pull towards rest, the same for a control that moves
    the skin little, a brow muscle, as for one that moves it much, the jaw: scale-free).
    J (d, q), y (d,) -> (q,)."""
    from scipy.optimize import lsq_linear

    J = np.asarray(J, dtype=float)
    q = J.shape[1]
    if q == 0:
        return np.zeros(0)
    lam = ridge * np.sum(J * J, axis=0)
    A = np.vstack([J, np.diag(np.sqrt(lam))]) if ridge > 0 else J
    b = np.concatenate([np.asarray(y, dtype=float), np.zeros(q if ridge > 0 else 0)])
    lo, hi = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
    eq = lo == hi   # lsq_linear needs lo < hi
    res = lsq_linear(A[:, ~eq], b - A[:, eq] @ lo[eq], bounds=(lo[~eq], hi[~eq]), method="bvls")
    x = lo.copy()
    x[~eq] = res.x
    return np.clip(x, lo, hi)


def solve_activations(target: np.ndarray, J: np.ndarray, space: ControlSpace, simulate, observe,
                      passes: int = 2, ridge: float = 1e-3, good_enough: float = 0.0,
                      rescale: int = 0, local: int = 0) -> SolveResult:
    """Controls whose settled skin best matches ``target`` (d,) (module docstring).

    J : (d, q) Jacobian of ``space`` (:func:`jacobian`); passes : Gauss-Newton (chord) passes
    after the linear solve, each one more settled pose; a pass that does not lower the residual
    ends the refinement (its pose is discarded), and so does a residual at or below
    ``good_enough`` (relative; 0: refine all ``passes``).
    rescale : after the passes, up to this many magnitude steps (:func:`_rescaled`): the pose
        scaled along its own direction by the least-squares factor of its observed field, kept
        when the residual falls (the secant Jacobian of a saturating skin leaves the settled
        field short: its magnitude below its cosine). 0: none.
    local : before the magnitude steps, up to this many Gauss-Newton steps with a Jacobian taken
        at the solution (:func:`_local_step`: the controls in use, each moved by a tenth of its
        range, settled together in one batch): muscles that share skin do not add up (the brow's
        joined insertions, the modiolus), so the secants from rest mispredict their sum. 0: none.
    """
    y = np.asarray(target, dtype=float)
    J = np.asarray(J, dtype=float)
    if J.shape != (len(y), len(space.names)):
        raise ValueError(f"J must be ({len(y)}, {len(space.names)}), got {J.shape}")
    lo, hi = np.asarray(space.lower, float), np.asarray(space.upper, float)
    norm = float(np.linalg.norm(y)) or 1.0

    def evaluate(x):
        c, jaw = space.pose(x)
        frame = simulate(c, jaw)
        return frame[0], np.asarray(observe(frame), dtype=float)[0]

    x = bounded_lsq(J, y, lo, hi, ridge)
    frame, f = evaluate(x)
    best = SolveResult(x, *(a[0] for a in space.pose(x)), frame, f, [float(np.linalg.norm(y - f)) / norm])
    # Broyden: after each settled pose, J is corrected along the step just taken (rank one) so
    # that it reproduces the simulated change from rest: ``J x = f(x)``
    J = _broyden(J, x, f)
    for _ in range(passes):
        if best.residuals[-1] <= good_enough:
            break
        r = y - best.observed
        # the step dx within [lo - x, hi - x], pulled towards no step
        dx = bounded_lsq(J, r, lo - best.x, hi - best.x, ridge)
        x_new = np.clip(best.x + dx, lo, hi)
        if not np.any(x_new != best.x):
            break
        frame, f = evaluate(x_new)
        J = _broyden(J, x_new, f)
        err = float(np.linalg.norm(y - f)) / norm
        if not err < best.residuals[-1]:     # no better, or the pose diverged (NaN)
            break
        stalled = err > 0.9 * best.residuals[-1]
        best = SolveResult(x_new, *(a[0] for a in space.pose(x_new)), frame, f, best.residuals + [err])
        if stalled:   # less than a tenth off the residual: the next pass would not pay its pose
            break
    # then the local Gauss-Newton steps, then the magnitude steps: each kept while it lowers the residual
    refinements = ((local, lambda b: _local_step(b, y, space, simulate, observe, lo, hi, ridge)),
                   (rescale, lambda b: _rescaled(b.x, b.observed, y, lo, hi)))
    for count, propose in refinements:
        for _ in range(count):
            x_new = propose(best)
            if x_new is None:
                break
            frame, f = evaluate(x_new)
            err = float(np.linalg.norm(y - f)) / norm
            if not err < best.residuals[-1]:
                break
            best = SolveResult(x_new, *(a[0] for a in space.pose(x_new)), frame, f, best.residuals + [err])
    return best


def _local_step(best: SolveResult, y: np.ndarray, space: ControlSpace, simulate, observe, lo: np.ndarray,
                hi: np.ndarray, ridge: float, step: float = 0.1, used: float = 1e-3):
    """One Gauss-Newton step from ``best.x`` with forward differences at it: each control whose
    value is above ``used`` (or off its lower bound) moved by ``step`` x its range towards the
    interior, all settled as one batch; the bounded step solved on those columns alone.
    Returns the new (q,) pose, or None when no control is in use."""
    x = np.asarray(best.x, dtype=float)
    active = np.flatnonzero(np.abs(x - lo) > used)
    if active.size == 0:
        return None
    h = step * (hi - lo)[active]
    h = np.where(x[active] + h <= hi[active], h, -h)
    X = np.repeat(x[None, :], active.size, axis=0)
    X[np.arange(active.size), active] += h
    c, jaw = space.pose(X)
    F = np.asarray(observe(simulate(c, jaw)), dtype=float)
    Jl = ((F - best.observed[None, :]) / h[:, None]).T
    dx = bounded_lsq(Jl, y - best.observed, (lo - x)[active], (hi - x)[active], ridge)
    x_new = x.copy()
    x_new[active] = np.clip(x[active] + dx, lo[active], hi[active])
    return None if np.allclose(x_new, x) else x_new


def _rescaled(x: np.ndarray, f: np.ndarray, y: np.ndarray, lo: np.ndarray, hi: np.ndarray,
              least: float = 0.01):
    """The magnitude step: ``x (q,)`` scaled by ``s = <f, y> / |f|^2`` (the factor that brings the
    observed field ``f (d,)`` closest to the target ``y (d,)`` along its own direction, were the
    skin linear in ``x``), clipped to the bounds; None when ``|s - 1| < least`` or nothing moves."""
    ff = float(f @ f)
    if ff == 0.0:
        return None
    s = float(f @ y) / ff
    if abs(s - 1.0) < least or s <= 0.0:
        return None
    x_new = np.clip(s * x, lo, hi)
    return None if np.allclose(x_new, x) else x_new


def _broyden(J: np.ndarray, x: np.ndarray, f: np.ndarray) -> np.ndarray:
    """J (d, q) corrected by the rank-one update that makes ``J x = f`` (secant from rest through
    the settled pose ``x`` (q,) observed as ``f`` (d,)); J unchanged for x = 0."""
    xx = float(x @ x)
    if xx == 0.0:
        return J
    return J + np.outer(f - J @ x, x) / xx


def field_agreement(result: np.ndarray, target: np.ndarray) -> tuple[float, float]:
    """(cosine, magnitude ratio) of two displacement fields (n, 3) or flat: the cosine of the
    flattened vectors and ``|result| / |target|`` (Frobenius norms)."""
    a = np.asarray(result, dtype=float).ravel()
    b = np.asarray(target, dtype=float).ravel()
    na, nb = float(np.linalg.norm(a)), float(np.linalg.norm(b))
    if nb == 0.0:
        raise ValueError("the target field is zero")
    return (float(a @ b) / (na * nb) if na > 0 else 0.0), na / nb
