"""The bake (issue 27): one settled pose per named shape, solved per head.

:func:`bake_shapes` takes the shapes of a mapping (:class:`faceforge.blendshapes.arkit.ShapeSpec`),
builds one Jacobian of every control any shape may use against every FAP any shape names
(one settled pose per control, :func:`faceforge.blendshapes.solve.jacobian`), then for each shape
solves the activations of its own controls against its own FAP targets (rows and columns of
that Jacobian; one Gauss-Newton pass through the simulation), lays the eyelids over the result
and measures it: per FAP requested and achieved FAPU, the peak displacement, and the physical
checks of the settled frame. Shapes marked ``not_made`` stay out, with their reason; a shape
whose FAPs have no FDP on this head is not made either (said so).

Everything is in the working mesh and the head's frame; the stage turns it into the user's.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from faceforge.blendshapes.solve import jacobian, solve_activations


@dataclass
class BakedShapes:
    """names : (k,) str, the shapes made; frames : (k, n, 3) float, settled skin (working mesh,
    eyelids applied); contractions : (k, m) float; jaw : (k, 3); faps : (k, 68) float, the lid
    FAPs applied (the solved FAP targets are in ``report``); gaze : (k, 4) float, the eye turns
    (yaw L, pitch L, yaw R, pitch R; radians); report : {name: dict} for every
    shape of the mapping, made or not; jacobian_seconds, solve_seconds : float."""

    names: list
    frames: np.ndarray
    contractions: np.ndarray
    jaw: np.ndarray
    faps: np.ndarray
    gaze: np.ndarray
    report: dict = field(default_factory=dict)
    jacobian_seconds: float = 0.0
    solve_seconds: float = 0.0


def bake_shapes(specs: dict, space, probes: dict, simulate, observe_probes, rest: np.ndarray,
                lids=None, eyes: dict | None = None, passes: int = 3, ridge: float = 1e-3,
                twins: np.ndarray | None = None, good_enough: float = 0.02,
                mirror_frame=None, folds=None, log=lambda m: None) -> BakedShapes:
    """Settle every made shape of ``specs`` (module docstring).

    specs : {name: ShapeSpec} in output order; space : ControlSpace of the head (all controls;
        each shape uses its ``controls`` of it); probes : {FAP: Probe} of the head;
    simulate : (c (k, m), jaw (k, 3)) -> (k, n, 3) skin settled from rest (its optional ``warm``
        attribute: the same continuing from the last pose, used for a shape's refinements); observe_probes : list of Probe ->
        (frames -> (k, len) FAPU) (:func:`faceforge.blendshapes.rigsolve.probe_observer` bound to rest);
    lids : faceforge.animation.eyelids.Eyelids or None (then lid-only shapes are not made);
    eyes : {side: (vertex ids, centre)} (:func:`faceforge.animation.eyeballs.eye_pieces`) or None;
    twins : (m,) mirror-twin column of each contraction column
        (:func:`faceforge.blendshapes.symmetric.mirror_columns`) on a symmetric rig, else None: then
        a shape that mirrors another is settled at its partner's mirrored pose instead of solved,
        and a midline shape moves twin controls together;
    good_enough : no Gauss-Newton pass after a solve whose relative FAP error is at most this;
    mirror_frame : None, or (n, 3) -> (n, 3) the mirror image of a settled skin (a mesh that is its
        own mirror image, :meth:`faceforge.geometry.mirror.Mirror.exact_partners`): then a shape
        that mirrors another (with ``twins``) is its partner's settled skin mirrored, not settled
        again (its pose, the partner's mirrored, is still what it records and plays); and the
        Jacobian's probe of a control whose twin was probed before it is the twin's skin mirrored;
    folds : None, or (n, 3) -> int, the folded edges of a settled skin: a shape whose pose was
        last settled warm (continuing from the pose before) and folds is settled again from rest
        at the same pose, and that frame is the shape (:func:`_cold_if_folded`).
    """
    import time

    simulate = _finite_or_nan(simulate, len(rest))
    report, todo = {}, []
    for name, spec in specs.items():
        why = _not_made(spec, space, probes, lids, eyes or {})
        if why:
            report[name] = {"made": False, "reason": why}
        else:
            todo.append(spec)
    solved_names = {s.name for s in todo}
    mirrored = [s for s in todo if twins is not None and s.faps and s.mirror_of in solved_names]
    solved = [s for s in todo if s not in mirrored]
    faps = sorted({f for s in solved for f in s.faps})
    used = [n for n in space.names if any(n in s.controls for s in solved)]
    sub = space.subset(used)
    observe = observe_probes([probes[f] for f in faps])
    t0 = time.perf_counter()
    if not used:
        J = np.zeros((len(faps), 0))
    elif mirror_frame is not None and twins is not None:
        J = _mirrored_jacobian(simulate, observe, sub, twins, mirror_frame)
    else:
        J = jacobian(simulate, observe, sub)
    t_jac = time.perf_counter() - t0
    log(f"Jacobian: {len(used)} controls x {len(faps)} FAPs in {t_jac:.1f} s")
    m = len(space.columns)
    poses = {}
    t0 = time.perf_counter()
    for spec in solved:
        c, jaw, frame, row = np.zeros(m), np.zeros(3), np.asarray(rest, dtype=float), {}
        if spec.faps:
            c, jaw, frame, row = _solve_shape(spec, faps, used, sub, J, simulate, observe, passes, ridge,
                                              tie=twins is not None, good_enough=good_enough, folds=folds)
        poses[spec.name] = (c, jaw, frame, row)
    if mirrored:
        poses.update(_mirrored(mirrored, poses, twins, simulate, observe_probes, probes, mirror_frame))
    out = {k: [] for k in ("names", "frames", "cs", "jaws", "faps", "gaze")}
    for spec in todo:
        c, jaw, frame, row = poses[spec.name]
        why = _diverged(frame, rest)
        if why:
            report[spec.name] = {"made": False, "reason": why, "controls": row.get("controls"),
                                 "mirror_of": spec.mirror_of or None}
            log(f"{spec.name}: not made: {why}")
            continue
        frame, f68, gaze = _overlay(spec, frame, row, lids, eyes or {}, jaw)
        lids_only = "not_turned" in row.get("eye", {})
        approximation = "; ".join(filter(None, [spec.approximation, "the lids follow the gaze, no eyeball turns: "
                                                + row["eye"]["not_turned"] if lids_only else ""]))
        row.update(made=True, approximation=approximation or None, mirror_of=spec.mirror_of or None)
        report[spec.name] = row
        for k, v in zip(out, (spec.name, frame, c, jaw, f68, gaze)):
            out[k].append(v)
        log(f"{spec.name}: " + (f"FAP error {row['error']:.0%}" if "error" in row else
                                ("lids only (no eyeball piece)" if lids_only else "eye rotation") if spec.eye
                                else "lids only")
            + (" (mirrored shape)" if row.get("mirrored_shape") else
               " (mirrored pose)" if row.get("mirrored_pose") else ""))
    t_solve = time.perf_counter() - t0
    n = len(rest)

    def stack(k, shape):
        return np.stack(out[k]) if out[k] else np.zeros(shape)

    return BakedShapes(out["names"], stack("frames", (0, n, 3)), stack("cs", (0, m)), stack("jaws", (0, 3)),
                       stack("faps", (0, 68)), stack("gaze", (0, 4)),
                       {name: report[name] for name in specs}, t_jac, t_solve)


def _finite_or_nan(simulate, n: int):
    """``simulate`` (and its ``warm``) settling pose by pose, a pose whose settle raises
    ``FloatingPointError`` (its skin went non-finite) returned as NaN (1, n, 3): one diverging
    pose costs its shape, not the bake."""
    def safe(run):
        def one(c, jaw):
            try:
                return run(c, jaw)
            except FloatingPointError:
                return np.full((1, n, 3), np.nan)

        def call(c, jaw):   # pose by pose (settle goes pose by pose anyway): a failure loses no other
            return np.concatenate([one(c[i:i + 1], jaw[i:i + 1]) for i in range(len(c))]) if len(c) \
                else run(c, jaw)
        return call

    out = safe(simulate)
    warm = getattr(simulate, "warm", None)
    out.warm = None if warm is None else safe(warm)
    return out


#: a settled pose whose skin moved more than this fraction of the head's size has diverged
DIVERGED = 0.25


def _diverged(frame: np.ndarray, rest: np.ndarray) -> str:
    """Why a settled ``frame`` (n, 3) is no shape ('' when it is one): non-finite, or a vertex
    moved more than :data:`DIVERGED` x the rest diagonal (a full ARKit shape moves 1-4 %; the
    simulation blew up: MakeHuman's right risorius at 0.3-0.6 did, on a bone the fit's clearance
    left asymmetric)."""
    d = np.linalg.norm(np.asarray(frame, dtype=float) - rest, axis=1)
    diag = float(np.linalg.norm(np.ptp(rest, axis=0)))
    if not np.all(np.isfinite(d)):
        return "the simulation diverged at this pose (non-finite skin)"
    if d.max() > DIVERGED * diag:
        return (f"the simulation diverged at this pose (a vertex moved {d.max() / diag:.3g} x the head's "
                "size): the rig is unstable there")
    return ""


def _not_made(spec, space, probes, lids, eyes) -> str:
    """Why ``spec`` cannot be made on this head ('' when it can)."""
    if not spec.made:
        return spec.not_made
    unknown = [c for c in spec.controls if c not in space.names]
    missing = [f for f in spec.faps if f not in probes]
    if unknown:
        return f"the head has no control {unknown[0]}"
    if missing:
        return f"no FDP on this head for FAP {missing[0]}"
    if spec.lids and lids is None:
        return "the head has no eyelids"
    if spec.eye and spec.eye["side"] not in eyes and not spec.lids:
        return f"eye rotation: {_no_piece(spec)}"
    return ""


def _no_piece(spec) -> str:
    return f"the mesh has no eyeball piece at the {spec.eye['side']} pupil"


def _overlay(spec, frame, row, lids, eyes, jaw=None):
    """The kinematic parts laid over a settled frame: the eyelid FAPs and the eye piece's turn, and
    the lids' hold on a moving jaw's drift (``jaw (3,)`` the shape's DOFs, ``animate.eyelid_jaw_hold``).
    Returns (frame (n, 3), lid FAPs (68,), gaze (4,)); notes them in ``row``."""
    from faceforge.animation.eyeballs import rotate_eye

    f68 = np.zeros(68)
    for f, v in spec.lids.items():
        f68[f - 1] = v
    jawed = lids is not None and lids.jaw_hold > 0.0 and jaw is not None and np.any(np.asarray(jaw)[:2] != 0.0)
    if spec.lids or jawed:
        frame = lids.apply(frame[None], f68[None], None if jaw is None else np.asarray(jaw)[None])[0]
    if spec.lids:
        row["lids"] = {str(f): v for f, v in spec.lids.items()}
    gaze = np.zeros(4)
    if spec.eye:
        gaze[[0, 1] if spec.eye["side"] == "L" else [2, 3]] = spec.eye["yaw"], spec.eye["pitch"]
        row["eye"] = {"side": spec.eye["side"], "yaw_deg": round(float(np.degrees(spec.eye["yaw"])), 2),
                      "pitch_deg": round(float(np.degrees(spec.eye["pitch"])), 2), "vertices": 0}
        if spec.eye["side"] in eyes:
            ids, centre = eyes[spec.eye["side"]]
            frame = rotate_eye(frame, ids, centre, spec.eye["yaw"], spec.eye["pitch"])
            row["eye"]["vertices"] = int(len(ids))
        else:   # a gaze shape whose lids follow the eye (_not_made let it through): the lids only
            row["eye"]["not_turned"] = _no_piece(spec)
    return frame, f68, gaze


def _mirrored(specs, poses, twins, simulate, observe_probes, probes, mirror_frame=None) -> dict:
    """Each of ``specs`` settled at the mirror image of its partner's solved pose (one batch), or,
    with ``mirror_frame``, its partner's settled skin mirrored (no settle);
    {name: (c, jaw, frame, report row)}, the row measuring its own FAPs as a solve's would."""
    from faceforge.blendshapes.arkit import mirror_name
    from faceforge.blendshapes.symmetric import mirror_pose

    c, jaw = mirror_pose(np.stack([poses[s.mirror_of][0] for s in specs]),
                         np.stack([poses[s.mirror_of][1] for s in specs]), twins)
    frames = simulate(c, jaw) if mirror_frame is None else \
        np.stack([mirror_frame(poses[s.mirror_of][2]) for s in specs])
    out = {}
    for i, spec in enumerate(specs):
        target = np.array(list(spec.faps.values()), dtype=float)
        got = np.asarray(observe_probes([probes[f] for f in spec.faps])(frames[i:i + 1]), dtype=float)[0]
        src = poses[spec.mirror_of][3]
        row = {**fap_row(spec.faps, target, got), "mirrored_pose": True, "mirrored_shape": mirror_frame is not None,
               "controls": {mirror_name(k) if not k.startswith("jaw.") else k:
                            (-v if k == "jaw.yaw" else v) for k, v in src.get("controls", {}).items()}}
        out[spec.name] = (c[i], jaw[i], frames[i], row)
    return out


def _mirrored_jacobian(simulate, observe, space, twins, mirror_frame) -> np.ndarray:
    """:func:`faceforge.blendshapes.solve.jacobian` on a mirror-symmetric skin: a probe pose that is
    the mirror image of one settled before it (a right muscle alone, its left twin probed) is that
    pose's settled skin mirrored (``mirror_frame``), not settled again (``twins`` as in
    :func:`bake_shapes`). J (d, q). On MakeHuman the mirrored and the settled skins of a pose differ
    by 0-4 % (``mirror_rel_diff``); the Jacobian only steers the solve, each shape's own pose is
    still settled."""
    from faceforge.blendshapes.symmetric import mirror_pose

    probe = np.asarray(space.probe, dtype=float)
    c, jaw = space.pose(np.diag(probe))
    mc, mj = mirror_pose(c, jaw, twins)
    def key(a, b):   # + 0.0: a negated zero yaw is the same pose
        return (np.concatenate([a, b]) + 0.0).tobytes()

    first = {}
    for i, (a, b) in enumerate(zip(c, jaw)):
        first.setdefault(key(a, b), i)
    source = [first.get(key(a, b), i) for i, (a, b) in enumerate(zip(mc, mj))]
    source = [s if s < i else i for i, s in enumerate(source)]        # mirror only what came before
    own = [i for i, s in enumerate(source) if s == i]
    settled = simulate(c[own], jaw[own])
    frames = {i: f for i, f in zip(own, settled)}
    obs = np.asarray(observe(np.stack([frames[i] if s == i else mirror_frame(frames[s])
                                       for i, s in enumerate(source)])), dtype=float)
    return (obs / probe[:, None]).T


def _solve_shape(spec, faps, used, sub, J, simulate, observe, passes, ridge, tie=False, good_enough=0.0,
                 folds=None):
    """One shape's activations on the rows (its FAPs) and columns (its controls) of the shared
    Jacobian -> contractions (m,), jaw (3,), settled frame (n, 3), its report row. ``tie``: a
    midline shape (its name has no side) moves each pair of twin controls as one."""
    from faceforge.blendshapes.arkit import mirror_name
    from faceforge.blendshapes.symmetric import tie_twins

    rows = [faps.index(f) for f in spec.faps]
    space = sub.subset(spec.controls)
    calls, warm, warmed = [0], getattr(simulate, "warm", None), []

    def settle(c, jaw):   # the first pose from rest, each refinement continuing from the one before
        calls[0] += 1
        out = (simulate if calls[0] == 1 or warm is None else warm)(c, jaw)
        if calls[0] > 1 and warm is not None:
            warmed.extend(out)
        return out

    Js = J[np.ix_(rows, [used.index(n) for n in space.names])]
    tied = tie_twins(space) if tie and mirror_name(spec.name) == spec.name else None
    target = np.array([spec.faps[f] for f in spec.faps])
    res = solve_activations(target, Js if tied is None else Js @ tied.tie, space if tied is None else tied,
                            settle, lambda fr: observe(fr)[:, rows], passes=passes, ridge=ridge,
                            good_enough=good_enough)
    x = res.x if tied is None else tied.expand(res.x)
    frame, observed, cold = _cold_if_folded(res, warmed, simulate, lambda fr: observe(fr)[:, rows], folds)
    res = replace(res, frame=frame, observed=observed)
    row = {**fap_row(spec.faps, target, res.observed), "residuals": [round(r, 3) for r in res.residuals],
           "saturated": _at_limit(space.names, x, space.lower, space.upper),
           "controls": {n: round(float(v), 4) for n, v in zip(space.names, x)}}
    if tied is not None:
        row["tied"] = [n for n in tied.names if "+" in n]
    if cold:
        row["settled_from_rest"] = cold
    return res.contractions, res.jaw, res.frame, row


def _cold_if_folded(res, warmed, simulate, observe, folds):
    """The shape's frame and observation (d,): ``res``'s, or, when ``res.frame`` is one of the
    ``warmed`` frames (settled continuing from the pose before) and has folded edges (``folds``),
    its pose settled again from rest when that folds less (a held pose's skin keeps creases the path
    through the poses before left in it: ICT's mouthPucker 44 folded edges warm, 23 from rest).
    Returns (frame (n, 3), observed (d,), {"warm_folds", "folds"} or None)."""
    if folds is None or not any(res.frame is f or np.array_equal(res.frame, f) for f in warmed):
        return res.frame, res.observed, None
    before = int(folds(res.frame))
    if not before:
        return res.frame, res.observed, None
    frame = simulate(res.contractions[None], res.jaw[None])
    if not np.all(np.isfinite(frame)):
        return res.frame, res.observed, None
    after = int(folds(frame[0]))
    if after >= before:   # from rest folds no less (ICT's mouthLeft 4 -> 5): the warm frame stays
        return res.frame, res.observed, {"warm_folds": before, "folds": before, "cold_folds": after}
    return frame[0], np.asarray(observe(frame), dtype=float)[0], {"warm_folds": before, "folds": after}


def _at_limit(names, x, lower, upper) -> list:
    """The controls at a nonzero bound (a muscle fully contracted, the jaw at a limit)."""
    return [n for n, v, lo, hi in zip(names, x, lower, upper)
            if (hi != 0 and v >= hi - 1e-9) or (lo != 0 and v <= lo + 1e-9)]


def fap_row(faps, target: np.ndarray, got: np.ndarray) -> dict:
    """A shape's report entries for its FAP targets: ``faps`` the FAP numbers, ``target`` and ``got``
    (d,) requested and achieved FAPU -> ``targets`` (per FAP), ``error`` (relative) and
    :func:`fap_reach`'s ``reach``, ``form_error``, ``verdict``."""
    t, g = np.asarray(target, dtype=float), np.asarray(got, dtype=float)
    return {"targets": {str(f): {"requested": float(a), "achieved": round(float(b), 1)} for f, a, b in zip(faps, t, g)},
            "error": round(float(np.linalg.norm(g - t) / np.linalg.norm(t)), 3), **fap_reach(t, g)}


def fap_reach(target: np.ndarray, got: np.ndarray) -> dict:
    """How a shape's FAP motion ``got`` (d,) compares with its ``target`` (d,) (FAPU): ``reach``,
    the part of the target made (``got . target / |target|^2``: 1 the whole, 0.3 a third in its
    direction), and ``form_error``, the error left after the best scaling of ``got``
    (``|got - s target| / |got|`` at ``s = got . target / |target|^2``: 0 when the shape is right
    but weak, as a muscle at full contraction that cannot move the skin as far as asked)."""
    t, g = np.asarray(target, dtype=float), np.asarray(got, dtype=float)
    s = float(g @ t) / max(float(t @ t), 1e-300)
    form = float(np.linalg.norm(g - s * t)) / max(float(np.linalg.norm(g)), 1e-300)
    err = float(np.linalg.norm(g - t)) / max(float(np.linalg.norm(t)), 1e-300)
    verdict = ("on target" if err <= 0.1 else f"weak: {s:.0%} of its target, the right form" if form <= 0.15
               else f"approximation: its FAP motion differs in form ({form:.0%} off after scaling)")
    return {"reach": round(s, 3), "form_error": round(form, 3), "verdict": verdict}


def mirror_agreement(user_rest: np.ndarray, deltas: dict, pairs) -> dict:
    """For each (left, right) pair of shape names: ``|d_L - mirror(d_R)| / |d_L|``, the right
    shape's displacement mirrored in x onto the left's vertices (nearest mirrored vertex of the
    user's rest mesh, (n, 3) in a frame where x is the subject's left).
    deltas : {name: (n, 3)}. Pairs with a missing shape are left out."""
    from scipy.spatial import cKDTree

    rest = np.asarray(user_rest, dtype=float)
    mi = cKDTree(rest).query(rest * np.array([-1.0, 1.0, 1.0]))[1]
    out = {}
    for a, b in pairs:
        if a in deltas and b in deltas:
            da = np.asarray(deltas[a], dtype=float)
            db = np.asarray(deltas[b], dtype=float)[mi] * np.array([-1.0, 1.0, 1.0])
            out[a] = round(float(np.linalg.norm(da - db) / max(np.linalg.norm(da), 1e-300)), 3)
    return out
