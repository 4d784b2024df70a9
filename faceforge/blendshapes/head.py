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
from faceforge.blendshapes.bake import bake_shapes, fap_row, mirror_agreement
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
              muscle_probe: float = 1.0, mirror=None, split=(), log=lambda m: None) -> HeadBake:
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
    with ``symmetric`` and a skin with an exact mirror partner per vertex, ``head.symmetric``);
    ``split``: ARKit pair stems (``mouthSmile``: ``mouthSmileLeft`` / ``-Right``) made from their
    bilateral pose cut across the midline (:mod:`faceforge.blendshapes.split`, ``bake.split_pairs``).
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
        probes = calibration_probes(mapping, head)
        pairs = _split_specs(specs, split)
        solve = {n: s for n, s in specs.items() if not any(n in (p[0].name, p[1].name) for p in pairs.values())}
        solve.update({stem: p[2] for stem, p in pairs.items()})
        baked = bake_shapes(solve, space, probes, simulate,
                            lambda probes: probe_observer(head.rest, probes), head.rest, lids, eyes,
                            twins=mirror_columns(head.controls) if symmetric else None,
                            mirror_frame=mirror_frame, log=log,
                            folds=lambda f: int(folded_edges(head.rest, f[None], head.faces).sum()))
        if pairs:
            out["split_pairs"] = _split(head, pairs, baked, probes, mirror_frame, log)
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
        report.update({n: r for n, r in baked.report.items() if n in ARKIT_NAMES})
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


def _split_specs(specs: dict, stems) -> dict:
    """{stem: (left spec, right spec, bilateral spec)} of the ``stems`` (``bake.split_pairs``) whose two
    sides are made and move no jaw (:func:`faceforge.blendshapes.split.bilateral_spec`); a stem that is
    not a splittable ARKit pair is a :class:`faceforge.exceptions.ConfigError`."""
    from faceforge.blendshapes.split import bilateral_spec
    from faceforge.exceptions import ConfigError
    from faceforge.io.config_rules import SPLITTABLE_PAIRS

    unknown = [str(s) for s in stems if s not in SPLITTABLE_PAIRS]
    if unknown:   # the config's rule refuses these first; a caller of the library may not have read one
        raise ConfigError(f"bake.split_pairs: {', '.join(unknown)}: not a splittable ARKit pair "
                          f"(one of {', '.join(SPLITTABLE_PAIRS)})")
    out = {}
    for stem in stems:
        left, right = specs.get(f"{stem}Left"), specs.get(f"{stem}Right")
        if left is None or right is None or not (left.made and right.made) or left.eye or right.eye \
                or any(k.startswith("jaw.") for k in left.controls + right.controls):
            continue
        out[stem] = (left, right, bilateral_spec(stem, left, right))
    return out


def _split(head, pairs: dict, baked, probes, mirror_frame, log) -> dict:
    """Each solved bilateral pose of ``pairs`` (:func:`_split_specs`) in ``baked`` cut across the midline
    into its left and right shapes (:mod:`faceforge.blendshapes.split`), appended to ``baked`` (frames,
    contractions, lids, report rows measured on the new frames); on a mirror-symmetric skin
    (``mirror_frame``) the bilateral frame is first made exactly symmetric. Returns what report.json
    says of it (the bilateral solves' rows)."""
    from faceforge.anatomy.tissue import units_per_mm
    from faceforge.blendshapes.split import BLEND_MM, midline_side, side_weights, split_controls, split_frame

    side = midline_side(head.rest, head.landmarks)
    if side is None:
        log("bake.split_pairs: no pupils (FDP 3.5 / 3.6) to place the midline: not split")
        return {"split": [], "reason": "no pupils (FDP 3.5 / 3.6)"}
    weight = side_weights(side, BLEND_MM * units_per_mm(head.landmarks))
    names_c = [str(n) for n in head.controls]
    left_cols = np.array([n.endswith("_L") for n in names_c])
    right_cols = np.array([n.endswith("_R") for n in names_c])
    index = {n: i for i, n in enumerate(baked.names)}
    rows, done, new = {}, [], {"frames": [], "contractions": [], "faps": []}
    for stem, (left, right, _) in pairs.items():
        rows[stem] = baked.report.get(stem)
        i = index.get(stem)
        if i is None:
            for spec in (left, right):
                baked.report[spec.name] = {"made": False, "reason": f"its bilateral pose {stem}: "
                                           + str((rows[stem] or {}).get("reason", "not made"))}
            continue
        frame = baked.frames[i]
        if mirror_frame is not None:
            frame = 0.5 * (frame + mirror_frame(frame))
        for spec, f, ck in zip((left, right), split_frame(head.rest, frame, weight),
                               split_controls(baked.contractions[i], left_cols, right_cols)):
            f68 = np.zeros(68)
            for fap, v in spec.lids.items():
                f68[fap - 1] = v
            baked.names.append(spec.name)
            for key, value in zip(new, (f, ck, f68)):
                new[key].append(value)
            baked.report[spec.name] = _split_row(spec, stem, head, f, ck, names_c, probes)
        done.append(stem)
    if new["frames"]:             # the split shapes after the solved ones (no jaw, no gaze)
        k = len(new["frames"])
        for key, rows_new in new.items():
            setattr(baked, key, np.concatenate([getattr(baked, key), np.stack(rows_new)]))
        baked.jaw = np.concatenate([baked.jaw, np.zeros((k, 3))])
        baked.gaze = np.concatenate([baked.gaze, np.zeros((k, 4))])
    log(f"split from their bilateral poses ({2 * BLEND_MM:g} mm blend across the midline): {', '.join(done)}")
    return {"split": done, "blend_mm": 2 * BLEND_MM, "bilateral": rows,
            "note": "each pair is its bilateral pose (both sides' muscles, solved against both sides' FAP "
                    "targets) settled once and cut across the midline: left + right = the bilateral pose"}


def _split_row(spec, stem, head, frame, contractions, control_names, probes) -> dict:
    """A split shape's report row: its controls, and its own FAP targets measured on its frame."""
    row = {"made": True, "split_from": stem, "approximation": spec.approximation or None,
           "mirror_of": spec.mirror_of or None,
           "controls": {n: round(float(v), 4) for n, v in zip(control_names, contractions) if v > 1e-4}}
    if spec.lids:
        row["lids"] = {str(f): v for f, v in spec.lids.items()}
    faps = [f for f in spec.faps if f in probes]
    if faps:
        got = np.asarray(probe_observer(head.rest, [probes[f] for f in faps])(frame[None]), dtype=float)[0]
        want = np.array([spec.faps[f] for f in faps], dtype=float)
        row.update(fap_row(faps, want, got))
    return row


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
        head.check_carried(checks, frames[i:i + 1])
        report[name]["peak_displacement"] = float(np.linalg.norm(frames[i] - head.rest, axis=1).max())
        report[name]["checks"] = checks.as_dict()
