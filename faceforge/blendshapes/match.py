"""Match a sculpted or scanned pose of a head with its muscles: the contractions and jaw pose whose
settled skin best reproduces a displacement field over the user's vertices (issue 25 item 2;
``faceforge match`` and ``benchmarks/bench_units.py``).

A :class:`FieldMatcher` holds one bound head's activation solve (:mod:`faceforge.blendshapes.solve`):
the control space (the mapping's muscles, the jaw's three DOFs within its limits), the settle of a
held pose (``animate.statics``: until the skin stops moving) and the Jacobian, built once on first use
(one settled pose a control) and shared by every target matched after it. Fields are in the user's
frame, units and vertex order (``(n_user, 3)``: a posed copy of the user's mesh less the mesh).
The eyelids (``lids``: the head's :class:`faceforge.animation.eyelids.Eyelids`) are controls too: their
FAPs 19-22 in IRISD, laid over each settled pose as playback lays them (:func:`with_lids`), so a target
whose eyes blink, open wide or stay still while the brows move is matched by the lids as well.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from faceforge.blendshapes.rigsolve import field_observer, settler
from faceforge.blendshapes.solve import ControlSpace, control_space, field_agreement, jacobian, solve_activations

#: the agreement issue 25 asks of a matched field: cosine at least this ...
GOOD_COSINE = 0.8
#: ... and the magnitude ratio |matched| / |target| within this range
GOOD_RATIO = (0.8, 1.25)
#: a lid FAP's range and probe in a match, IRISD (upper lids 19/20: open as far as the lids' cap lets
#: them, closed; lower lids 21/22: down, up): a blink is 900 + 124
LID_RANGE = {"upper": (-350.0, 900.0, 300.0), "lower": (-150.0, 400.0, 100.0)}


@dataclass
class Match:
    """One matched target.

    x : (q,) the solve's controls (:attr:`FieldMatcher.names`: contractions in [0, max], jaw pitch
        and yaw in rad, protrusion in skin units, lid FAPs ``lid.19`` ... in IRISD); contractions : (m,)
        in the head's ``controls`` order; jaw : (3,) pitch, yaw, protrusion; lids : {FAP: IRISD} of the
        lid controls
    frame : (n, 3) the settled working skin; field : (n_user, 3) its displacement in the user's
        frame and units; cosine, ratio : agreement with the target (:func:`field_agreement`);
    residuals : relative residual |target - field| / |target| after the linear solve and each
        refinement kept; seconds : the solve's wall time (the Jacobian not included)
    """

    x: np.ndarray
    contractions: np.ndarray
    jaw: np.ndarray
    frame: np.ndarray
    field: np.ndarray
    cosine: float
    ratio: float
    residuals: list
    seconds: float
    lids: dict = field(default_factory=dict)

    @property
    def good(self) -> bool:
        """Within issue 25's agreement (:data:`GOOD_COSINE`, :data:`GOOD_RATIO`)."""
        return self.cosine >= GOOD_COSINE and GOOD_RATIO[0] <= self.ratio <= GOOD_RATIO[1]


class FieldMatcher:
    """The activation solve of one bound head against displacement fields.

    head : :class:`faceforge.animation.rig.BoundHead`; mapping : a FAP mapping (its ``muscles``,
    ``jaw_limits`` and ``max_contraction``); fps : the settle's frame rate; settle : a
    :class:`faceforge.animation.statics.SettleSettings` (held until it stops moving) or a number of
    frames; muscles : the muscle names to solve with (default: the mapping's); jaw : solve the jaw too;
    lids : the head's :class:`faceforge.animation.eyelids.Eyelids` (its lid FAPs solved too,
    :func:`with_lids`) or None.
    """

    def __init__(self, head, mapping, fps: float, settle, muscles=None, jaw: bool = True, lids=None):
        self.head = head
        self.simulate = settler(head.rig, fps, settle)
        self.observe = field_observer(head.rest, head.user_index, head.user_rotation)
        self.space = control_space(head.controls, set(mapping.muscles) if muscles is None else set(muscles),
                                   mapping.jaw_limits if jaw else {}, head.levers.pitch, mapping.max_contraction)
        self.lid_faps = tuple(lids.faps) if lids is not None else ()
        if self.lid_faps:
            self.space, self.simulate = with_lids(self.space, self.simulate, lids)
        self._J = None
        self.jacobian_seconds = 0.0

    @property
    def names(self) -> tuple:
        """(q,) the controls solved for."""
        return self.space.names

    @property
    def J(self) -> np.ndarray:
        """(3 n_user, q) the Jacobian: each control settled alone at its probe level (built once)."""
        if self._J is None:
            self.simulate(*self.space.pose(np.zeros(len(self.space.names))))   # compiles outside the timing
            t0 = time.perf_counter()
            self._J = jacobian(self.simulate, self.observe, self.space)
            self.jacobian_seconds = time.perf_counter() - t0
        return self._J

    def match(self, target: np.ndarray, passes: int = 2, local: int = 2, rescale: int = 2) -> Match:
        """The controls whose settled skin best matches ``target`` (n_user, 3) (user frame and units);
        ``passes``, ``local``, ``rescale``: :func:`faceforge.blendshapes.solve.solve_activations`."""
        target = np.asarray(target, dtype=float)
        J = self.J
        t0 = time.perf_counter()
        res = solve_activations(target.ravel(), J, self.space, self.simulate, self.observe, passes=passes,
                                rescale=rescale, local=local)
        if self.lid_faps:   # any lid FAP switches the lids' hold on (playback's rule): a pose the muscles make
            own = self.space.subset([n for n in self.space.names if not n.startswith("lid.")])   # alone is
            keep = [self.space.names.index(n) for n in own.names]                # solved without the lids too
            alone = solve_activations(target.ravel(), J[:, keep], own, self.simulate, self.observe, passes=passes,
                                      rescale=rescale, local=local)
            if alone.residuals[-1] <= res.residuals[-1]:   # and the better of the two kept
                x = np.zeros(len(self.space.names))
                x[keep] = alone.x
                res = replace(alone, x=x)
        cos, ratio = field_agreement(res.observed, target)
        m = len(res.contractions) - len(self.lid_faps)
        return Match(res.x, res.contractions[:m], res.jaw, res.frame, res.observed.reshape(-1, 3), cos, ratio,
                     list(res.residuals), time.perf_counter() - t0,
                     {f: float(v) for f, v in zip(self.lid_faps, res.contractions[m:])})

    def used(self, match: Match, least: float = 1e-3) -> dict:
        """{control: value} of the controls ``match`` uses (|value| > ``least``)."""
        return {n: float(v) for n, v in zip(self.space.names, match.x) if abs(v) > least}


def with_lids(space: ControlSpace, simulate, lids) -> tuple[ControlSpace, object]:
    """``space`` with the lid FAPs of ``lids`` (an :class:`~faceforge.animation.eyelids.Eyelids`) as
    controls ``lid.19`` ... (IRISD, :data:`LID_RANGE`), appended to its columns, and ``simulate``
    wrapped to match: the contraction columns past the head's are those FAPs, laid over each settled
    pose by ``lids.apply`` (with the pose's jaw, as playback lays them)."""
    faps = tuple(lids.faps)
    kinds = ["upper" if f in (19, 20) else "lower" for f in faps]
    names = tuple(f"lid.{f}" for f in faps)
    lo, hi, probe = (np.array([LID_RANGE[k][i] for k in kinds]) for i in range(3))
    grown = ControlSpace(space.names + names, np.concatenate([space.lower, lo]), np.concatenate([space.upper, hi]),
                         np.concatenate([space.probe, probe]), space.columns + names)
    m = len(space.columns)

    def overlay(run):
        def simulate_lidded(c, jaw):
            c = np.atleast_2d(c)
            f68 = np.zeros((len(c), 68))
            f68[:, [f - 1 for f in faps]] = c[:, m:]
            return lids.apply(run(c[:, :m], jaw), f68, np.atleast_2d(jaw))
        return simulate_lidded

    out = overlay(simulate)
    out.stats = simulate.stats
    out.warm = overlay(simulate.warm) if simulate.warm is not None else None
    return grown, out


def head_motion(motion: np.ndarray, neutral: np.ndarray) -> tuple[float, float]:
    """(turn in degrees, shift in skin units) of a target's rigid head motion ``motion (4, 4)``
    (:func:`faceforge.geometry.rigid.still_part_motion`): the rotation's angle, and how far it
    carries the centroid of ``neutral (n, 3)``."""
    R, t = np.asarray(motion, dtype=float)[:3, :3], np.asarray(motion, dtype=float)[:3, 3]
    turn = float(np.degrees(np.arccos(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0))))
    centre = np.asarray(neutral, dtype=float).mean(axis=0)
    return turn, float(np.linalg.norm(t + centre @ R.T - centre))


def match_posed(head, matcher: FieldMatcher, delta: np.ndarray, motion: np.ndarray, rigid: bool,
                log=lambda m: None) -> tuple[Match, dict]:
    """Match ``delta (n_user, 3)`` (a posed copy of ``head``'s mesh less the mesh, user frame; its
    head motion ``motion (4, 4)``, already taken out when ``rigid``) with ``matcher``; the match and
    its report: the agreement against :data:`GOOD_COSINE` / :data:`GOOD_RATIO`, the residuals, the
    head motion, the controls used (jaw in degrees and mm, lids in IRISD), the peaks in mm, the physical checks of
    the settled pose (:func:`faceforge.animation.checks.check_animation`) and the seconds."""
    from faceforge.anatomy.tissue import units_per_mm
    from faceforge.animation.checks import check_animation

    neutral = head.to_user(head.rest[None])[0]
    mm = units_per_mm(head.landmarks)
    turn, shift = head_motion(motion, neutral)
    if not rigid and (turn > 1.0 or shift / mm > 1.0):
        log(f"the target's head itself moved ({turn:.1f} deg, {shift / mm:.1f} mm): if that is not the face's "
            "motion, match --rigid takes it out first")
    log(f"{len(matcher.names)} controls ({'muscles, jaw and lids' if matcher.lid_faps else 'muscles and jaw'}), "
        "one settled pose each")
    m = matcher.match(delta)
    head.rig.reset()
    checks = check_animation(head.rest, m.frame[None], head.faces, inside_at_rest=head.inside_at_rest(),
                             skull=lambda k: head.skull_at(m.jaw if k >= 0 else np.zeros(3)))
    shown = {n: (round(float(np.degrees(v)), 2) if n in ("jaw.pitch", "jaw.yaw") else
                 round(v / mm, 2) if n == "jaw.protrusion" else round(v, 1) if n.startswith("lid.") else
                 round(v, 3)) for n, v in matcher.used(m).items()}
    report = {
        "agreement": {"cosine": round(m.cosine, 4), "ratio": round(m.ratio, 4),
                      "within": {"cosine_at_least": GOOD_COSINE, "ratio": list(GOOD_RATIO), "met": m.good}},
        "residuals": [round(r, 4) for r in m.residuals],
        "head_motion": {"turn_deg": round(turn, 3), "shift_mm": round(shift / mm, 3), "removed": bool(rigid)},
        "controls": shown, "units": {"contractions": "0-1", "jaw.pitch": "deg", "jaw.yaw": "deg",
                                     "jaw.protrusion": "mm", "lid.19-22": "IRISD (MPEG-4 eyelid FAPs)"},
        "peak_mm": {"target": round(float(np.linalg.norm(delta, axis=1).max()) / mm, 2),
                    "matched": round(float(np.linalg.norm(m.field, axis=1).max()) / mm, 2)},
        "checks": checks.as_dict(),
        "seconds": {"jacobian": round(matcher.jacobian_seconds, 2), "solve": round(m.seconds, 2)},
    }
    return m, report
