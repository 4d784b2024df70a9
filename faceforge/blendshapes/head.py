"""The bake of one bound head (issue 27): the ARKit shapes of a mapping solved on it
(:func:`faceforge.blendshapes.bake.bake_shapes`), the FAP mapping's visemes and expressions
settled as presets, each checked at full weight, and the left/right mirror agreement.

``head`` is a :class:`faceforge.animation.rig.BoundHead` (its rig, rest skin, faces, controls,
landmarks, user frame); everything returned is in the user's vertex order and frame except
``frames`` (working mesh, head frame, for pictures).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from faceforge.animation.calibrate_head import calibration_probes
from faceforge.animation.checks import check_animation, folded_edges
from faceforge.animation.controls import controls
from faceforge.blendshapes.arkit import ARKIT_NAMES, mirror_name
from faceforge.blendshapes.bake import bake_shapes, mirror_agreement
from faceforge.animation.eyeballs import eye_pieces
from faceforge.blendshapes.rigsolve import probe_observer, settler
from faceforge.blendshapes.solve import control_space


@dataclass
class HeadBake:
    """arrays : what ``shapes.npz`` holds (``names``, ``made``, ``neutral``, ``shapes``,
    ``contractions``, ``controls``, ``jaw``, ``lids``, ``gaze``); report : ``report.json``'s body
    (per shape, timings, mirror agreement); frames : (k, n, 3) settled working skin per shape."""

    arrays: dict
    report: dict
    frames: np.ndarray


def bake_head(head, mapping, specs: dict, kinds, fps: float, settle, lids=None, symmetric: bool = False,
              muscle_probe: float = 1.0, mirror=None, log=lambda m: None) -> HeadBake:
    """Bake ``kinds`` (``arkit``, ``visemes``, ``expressions``) on ``head``: ``specs`` the ARKit
    mapping (:func:`faceforge.blendshapes.arkit.load_arkit_mapping`), ``mapping`` the FAP mapping
    (muscles, jaw limits, presets, FAP probes), each pose settled ``settle`` frames at ``fps`` (an int)
    or to convergence (a :class:`faceforge.animation.statics.SettleSettings`, each pose continuing
    from the one before); ``lids`` the head's :class:`faceforge.animation.eyelids.Eyelids` with at
    least one eye, or None; ``symmetric``: the rig is symmetric by construction (fit.npz has a
    mirror plane): each right shape is settled at its left partner's mirrored pose, not solved
    (:mod:`faceforge.blendshapes.symmetric`); ``muscle_probe``: the contraction each muscle's
    Jacobian column is settled at (1: full, the pose a shape that saturates the muscle reuses);
    ``mirror``: the head's :class:`faceforge.geometry.mirror.Mirror` (working frame) to make each
    right shape the mirror image of its left partner's settled skin instead of settling it (only
    with ``symmetric`` and a skin with an exact mirror partner per vertex, ``head.symmetric``).
    A pose settled once is not settled again (the frame is kept)."""
    from faceforge.blendshapes.symmetric import mirror_columns

    t_start = time.perf_counter()
    settled = settler(head.rig, fps, settle)
    simulate, poses = _remembering(settled)

    simulate(np.zeros((1, len(head.controls))), np.zeros((1, 3)))   # compile outside the timing
    t0, cpu0 = time.perf_counter(), time.process_time()
    names, frames, c, jaw, lid_faps, gaze, made, report = [], [], [], [], [], [], [], {}
    out = {"settle_frames": settle if isinstance(settle, int) else "to convergence (animate.statics; refinements warm)",
           "symmetric_rig": bool(symmetric),
           "shapes": report}
    mirror_frame = _shape_mirror(head, mirror) if symmetric else None
    out["right_shapes"] = (_MIRRORED_NOTE if mirror_frame is not None else
                           "settled at the left partner's mirrored pose" if symmetric else "solved")
    if "arkit" in kinds:
        space = control_space(head.controls, set(mapping.muscles), mapping.jaw_limits, head.levers.pitch,
                              mapping.max_contraction, muscle_probe=muscle_probe)
        eyes = eye_pieces(head.rest, head.faces, head.landmarks)
        if eyes:
            log(f"eyeball pieces: {', '.join(f'{s} ({len(v[0])} vertices)' for s, v in eyes.items())}")
        baked = bake_shapes(specs, space, calibration_probes(mapping, head), simulate,
                            lambda probes: probe_observer(head.rest, probes), head.rest, lids, eyes,
                            twins=mirror_columns(head.controls) if symmetric else None,
                            mirror_frame=mirror_frame, log=log,
                            folds=lambda f: int(folded_edges(head.rest, f[None], head.faces).sum()))
        index = {n: i for i, n in enumerate(baked.names)}
        for name in ARKIT_NAMES:
            i = index.get(name)
            names.append(name)
            made.append(i is not None)
            frames.append(baked.frames[i] if i is not None else head.rest)
            c.append(baked.contractions[i] if i is not None else np.zeros(len(head.controls)))
            jaw.append(baked.jaw[i] if i is not None else np.zeros(3))
            lid_faps.append(baked.faps[i] if i is not None else np.zeros(68))
            gaze.append(baked.gaze[i] if i is not None else np.zeros(4))
        report.update(baked.report)
        out.update(jacobian_seconds=round(baked.jacobian_seconds, 2), solve_seconds=round(baked.solve_seconds, 2))
    for kind in ("visemes", "expressions"):
        if kind in kinds:
            _presets(head, mapping, kind, simulate, lids, names, frames, c, jaw, lid_faps, made, report, log)
            gaze += [np.zeros(4)] * (len(names) - len(gaze))
    out["bake_seconds"] = round(time.perf_counter() - t0, 2)
    out["bake_cpu_seconds"] = round(time.process_time() - cpu0, 2)   # all threads: honest on a busy machine
    out["poses_settled"] = poses[0] - 1                                # the first compiles, outside the timing
    out["frames_simulated"] = out["poses_settled"] * settle if isinstance(settle, int) else \
        int(sum(settled.stats.frames[1:]))
    if settled.stats is not None:
        out["statics"] = settled.stats.as_dict()
    frames = np.stack(frames)
    _check_shapes(head, frames, np.stack(jaw), names, made, report)
    user = head.to_user(np.concatenate([head.rest[None], frames])).astype(np.float32)
    out["mirror_rel_diff"] = _mirror(head, user, names, made)
    out["made"] = int(sum(made))
    out["not_made"] = [n for n, m in zip(names, made) if not m]
    out["total_seconds"] = round(time.perf_counter() - t_start, 2)
    log(f"{out['made']} of {len(names)} shapes made in {out['bake_seconds']:.1f} s "
        f"({out['bake_cpu_seconds']:.1f} s CPU; {out['poses_settled']} poses settled, "
        f"{1e3 * out['bake_seconds'] / max(out['frames_simulated'], 1):.1f} ms a frame)"
        + (f"; not made: {', '.join(out['not_made'])}" if out["not_made"] else ""))
    arrays = dict(names=np.asarray(names), made=np.asarray(made), neutral=user[0], shapes=user[1:],
                  contractions=np.stack(c), controls=np.asarray(head.controls, dtype=str), jaw=np.stack(jaw),
                  lids=np.stack(lid_faps), gaze=np.stack(gaze))
    return HeadBake(arrays, out, frames)


#: what report.json says of the right shapes when they are mirror images
_MIRRORED_NOTE = ("the left partner's settled skin mirrored through the mesh's exact vertex partners (a rig "
                  "symmetric by construction: the same muscles mirrored, mirror-coloured solver); not settled, "
                  "so the left/right mirror agreement is exact by construction (bake.mirror_shapes)")


def _shape_mirror(head, mirror):
    """(n, 3) -> (n, 3): a settled working skin reflected through ``mirror`` onto the vertices' exact
    partners; None without a mirror or when the skin is not its own mirror image."""
    if mirror is None or not getattr(head, "symmetric", False):
        return None
    partner = mirror.exact_partners(head.rest)
    if partner is None:
        return None
    return lambda frame: mirror(np.asarray(frame, dtype=float)[partner])


def _remembering(settled):
    """``settled`` (:func:`faceforge.blendshapes.rigsolve.settler`) wrapped so that a pose
    (contractions and jaw, exactly) settled from rest once is not settled again, and counted.
    Returns (simulate, [poses settled]); ``simulate.warm`` counts its poses too (never kept:
    a warm pose depends on the one before)."""
    poses, memo = [0], {}

    def simulate(c, j):
        keys = [np.concatenate([ci, ji]).tobytes() for ci, ji in zip(c, j)]
        new = [i for i, k in enumerate(keys) if k not in memo]
        if new:
            poses[0] += len(new)
            for i, f in zip(new, settled(np.asarray(c)[new], np.asarray(j)[new])):
                memo[keys[i]] = f
        return np.stack([memo[k] for k in keys]) if keys else settled(c, j)

    def warm(c, j):
        poses[0] += len(c)
        return settled.warm(c, j)

    simulate.warm = None if settled.warm is None else warm
    return simulate, poses


def _mirror(head, user, names, made) -> dict:
    """|L - mirror(R)| / |L| per left/right pair, in the head's frame (x the subject's left)."""
    R = np.asarray(head.user_rotation, dtype=float)
    rest = user[0] @ R.T
    deltas = {n: (user[i + 1] - user[0]) @ R.T for i, n in enumerate(names) if made[i]}
    pairs = [(n, mirror_name(n)) for n in names if mirror_name(n) != n and n.endswith(("Left", "_L"))]
    return mirror_agreement(rest, deltas, pairs)


def _presets(head, mapping, kind, simulate, lids, names, frames, c, jaw, lid_faps, made, report, log):
    """Settle the FAP mapping's ``visemes`` or ``expressions`` presets (as the sheet stages do) and
    append them to the shape lists."""
    table = mapping.visemes if kind == "visemes" else mapping.expressions
    if not table:
        log(f"the mapping has no {kind}: none baked")
        return
    faps = np.stack(list(table.values()))
    cc, jj = controls(mapping, faps, head)
    poses = simulate(cc, jj)
    if lids is not None:
        poses = lids.apply(poses, faps, jj)
    for i, name in enumerate(table):
        names.append(name)
        made.append(True)
        frames.append(poses[i])
        c.append(cc[i])
        jaw.append(jj[i])
        lid_faps.append(np.where(np.isin(np.arange(1, 69), (19, 20, 21, 22)), faps[i], 0.0))
        report[name] = {"made": True, "kind": kind[:-1],
                        "controls": {n: round(float(v), 4) for n, v in zip(head.controls, cc[i]) if v > 1e-4},
                        "jaw": jj[i].tolist()}


def _check_shapes(head, frames, jaw, names, made, report) -> None:
    """Per made shape: peak displacement (skin units) and the physical checks at full weight."""
    base = head.inside_at_rest()   # once, not once per shape; the rigid pieces are not skin
    for i, name in enumerate(names):
        if not made[i]:
            continue
        checks = check_animation(head.rest, frames[i:i + 1], head.faces, inside_at_rest=base,
                                 skull=lambda k, j=jaw[i]: head.skull_at(j if k >= 0 else np.zeros(3)))
        report[name]["peak_displacement"] = float(np.linalg.norm(frames[i] - head.rest, axis=1).max())
        report[name]["checks"] = checks.as_dict()
