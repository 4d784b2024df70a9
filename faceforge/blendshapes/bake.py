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

from dataclasses import dataclass, field

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
                lids=None, eyes: dict | None = None, passes: int = 1, ridge: float = 1e-3,
                log=lambda m: None) -> BakedShapes:
    """Settle every made shape of ``specs`` (module docstring).

    specs : {name: ShapeSpec} in output order; space : ControlSpace of the head (all controls;
        each shape uses its ``controls`` of it); probes : {FAP: Probe} of the head;
    simulate : (c (k, m), jaw (k, 3)) -> (k, n, 3) settled skin; observe_probes : list of Probe ->
        (frames -> (k, len) FAPU) (:func:`faceforge.blendshapes.rigsolve.probe_observer` bound to rest);
    lids : faceforge.animation.eyelids.Eyelids or None (then lid-only shapes are not made);
    eyes : {side: (vertex ids, centre)} (:func:`faceforge.blendshapes.eyes.eye_pieces`) or None.
    """
    from faceforge.blendshapes.eyes import rotate_eye

    eyes = eyes or {}
    import time

    report, todo = {}, []
    for name, spec in specs.items():
        if not spec.made:
            report[name] = {"made": False, "reason": spec.not_made}
            continue
        unknown = [c for c in spec.controls if c not in space.names]
        missing = [f for f in spec.faps if f not in probes]
        no_eye = bool(spec.eye) and spec.eye["side"] not in eyes
        if unknown or missing or (spec.lids and lids is None) or no_eye:
            why = (f"the head has no control {unknown[0]}" if unknown else
                   f"no FDP on this head for FAP {missing[0]}" if missing else
                   f"eye rotation: the mesh has no eyeball piece at the {spec.eye['side']} pupil" if no_eye
                   else "the head has no eyelids")
            report[name] = {"made": False, "reason": why}
            continue
        todo.append(spec)
    faps = sorted({f for s in todo for f in s.faps})
    used = [n for n in space.names if any(n in s.controls for s in todo)]
    sub = space.subset(used)
    observe = observe_probes([probes[f] for f in faps])
    t0 = time.perf_counter()
    J = jacobian(simulate, observe, sub) if used else np.zeros((len(faps), 0))
    t_jac = time.perf_counter() - t0
    log(f"Jacobian: {len(used)} controls x {len(faps)} FAPs in {t_jac:.1f} s")
    m = len(space.columns)
    names, frames, cs, jaws, lid_faps, gazes = [], [], [], [], [], []
    t0 = time.perf_counter()
    for spec in todo:
        c, jaw, frame, row = np.zeros(m), np.zeros(3), np.asarray(rest, dtype=float), {}
        if spec.faps:
            c, jaw, frame, row = _solve_shape(spec, faps, used, sub, J, simulate, observe, passes, ridge)
        f68 = np.zeros(68)
        for f, v in spec.lids.items():
            f68[f - 1] = v
        if spec.lids:
            frame = lids.apply(frame[None], f68[None])[0]
            row["lids"] = {str(f): v for f, v in spec.lids.items()}
        gaze = np.zeros(4)
        if spec.eye:
            gaze[[0, 1] if spec.eye["side"] == "L" else [2, 3]] = spec.eye["yaw"], spec.eye["pitch"]
            ids, centre = eyes[spec.eye["side"]]
            frame = rotate_eye(frame, ids, centre, spec.eye["yaw"], spec.eye["pitch"])
            row["eye"] = {"side": spec.eye["side"], "yaw_deg": round(float(np.degrees(spec.eye["yaw"])), 2),
                          "pitch_deg": round(float(np.degrees(spec.eye["pitch"])), 2), "vertices": int(len(ids))}
        row.update(made=True, approximation=spec.approximation or None, mirror_of=spec.mirror_of or None)
        report[spec.name] = row
        names.append(spec.name)
        frames.append(frame)
        cs.append(c)
        jaws.append(jaw)
        lid_faps.append(f68)
        gazes.append(gaze)
        log(f"{spec.name}: " + (f"FAP error {row['error']:.0%}" if "error" in row else
                                "eye rotation" if spec.eye else "lids only"))
    t_solve = time.perf_counter() - t0
    n = len(rest)
    return BakedShapes(names, np.stack(frames) if frames else np.zeros((0, n, 3)),
                       np.stack(cs) if cs else np.zeros((0, m)), np.stack(jaws) if jaws else np.zeros((0, 3)),
                       np.stack(lid_faps) if lid_faps else np.zeros((0, 68)),
                       np.stack(gazes) if gazes else np.zeros((0, 4)),
                       {name: report[name] for name in specs}, t_jac, t_solve)


def _solve_shape(spec, faps, used, sub, J, simulate, observe, passes, ridge):
    """One shape's activations on the rows (its FAPs) and columns (its controls) of the shared
    Jacobian -> contractions (m,), jaw (3,), settled frame (n, 3), its report row."""
    rows = [faps.index(f) for f in spec.faps]
    space = sub.subset(spec.controls)
    Js = J[np.ix_(rows, [used.index(n) for n in space.names])]
    target = np.array([spec.faps[f] for f in spec.faps])
    res = solve_activations(target, Js, space, simulate, lambda fr: observe(fr)[:, rows], passes=passes,
                            ridge=ridge)
    row = {"targets": {str(f): {"requested": float(t), "achieved": round(float(a), 1)}
                       for f, t, a in zip(spec.faps, target, res.observed)},
           "error": round(float(np.linalg.norm(res.observed - target) / np.linalg.norm(target)), 3),
           "residuals": [round(r, 3) for r in res.residuals],
           "controls": {n: round(float(v), 4) for n, v in zip(space.names, res.x)}}
    return res.contractions, res.jaw, res.frame, row


def apply_gaze(frames: np.ndarray, gaze: np.ndarray, eyes: dict) -> np.ndarray:
    """Frames (F, n, 3) with each eye piece turned by ``gaze (F, 4)`` (yaw L, pitch L, yaw R,
    pitch R; radians) about its centre (:func:`faceforge.blendshapes.eyes.eye_pieces`); a copy."""
    from faceforge.blendshapes.eyes import rotate_eye

    out = np.array(frames, dtype=float, copy=True)
    for side, cols in (("L", (0, 1)), ("R", (2, 3))):
        if side not in eyes:
            continue
        ids, centre = eyes[side]
        for f in np.flatnonzero(np.any(gaze[:, cols] != 0.0, axis=1)):
            out[f] = rotate_eye(out[f], ids, centre, gaze[f, cols[0]], gaze[f, cols[1]])
    return out


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
