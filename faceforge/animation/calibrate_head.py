"""Calibration on a bound head (paper §9, beyond it): probes, requested values, the run.

:func:`calibrate_head` measures each mapped FAP's response on the head
(:class:`faceforge.animation.rig.BoundHead`) in static poses and fits the mapping's response
curves (:func:`faceforge.animation.calibrate.calibrate_mapping`), the jaw couplings
(:func:`faceforge.animation.calibrate.measure_coupling`) and the lip opening of ``open_jaw``.
"""

from __future__ import annotations

from dataclasses import dataclass


def calibration_probes(mapping, head):
    """FAP number -> Probe for every mapped FAP whose FDP(s) the skin has."""
    import numpy as np

    from faceforge.animation.calibrate import Probe
    from faceforge.mpeg4 import DIRECTION_VECTORS, fap_record

    probes = {}
    for entry in mapping.entries:
        for fap in entry.faps:
            rec = fap_record(fap)
            if not rec.is_translation:
                continue
            m = entry.measure.get(fap)
            fdp, rel = (m.fdp, m.relative_to) if m is not None else (rec.fdp, None)
            if fdp not in head.fdp_vertex or (rel is not None and rel not in head.fdp_vertex):
                continue
            probes[fap] = Probe(fap, head.fdp_vertex[fdp], -1 if rel is None else head.fdp_vertex[rel],
                                np.asarray(DIRECTION_VECTORS[rec.direction], dtype=float),
                                head.fapu.unit(rec.unit))
    return probes


def requested_values(mapping, config) -> dict:
    """FAP number -> requested FAPU values: for each sign the entry can drive, the fractions
    ``animate.calibrate.fractions`` of the magnitude users play (the largest value of that sign
    in the Xface files, ``animate.calibrate.magnitudes``, over the entry's FAPs), at least the
    typical magnitude of its unit (``animate.calibrate.magnitude``; open_jaw:
    ``animate.calibrate.jaw_magnitude``), which also serves a sign the files never use."""
    mags = dict(config.get("animate.calibrate.magnitude"))
    jaw_mag = float(config.get("animate.calibrate.jaw_magnitude"))
    fractions = sorted(float(f) for f in config.get("animate.calibrate.fractions"))
    played = played_magnitudes(config.get("animate.calibrate.magnitudes"))
    out = {}
    for e in mapping.entries:
        if not (e.positive or e.negative or e.jaw is not None):
            continue                      # nothing to drive (e.g. a pure jaw-coupling entry)
        typical = jaw_mag if (e.jaw is not None and e.jaw[0] == "pitch") else float(mags[e.fapu])
        neg = max([typical] + [-played.get(f, (0.0, 0.0))[0] for f in e.faps])
        pos = max([typical] + [played.get(f, (0.0, 0.0))[1] for f in e.faps])
        values = [f * pos for f in fractions]
        if bool(e.negative) or (e.jaw is not None and e.jaw[0] == "yaw"):
            values = [-f * neg for f in reversed(fractions)] + values
        out[e.faps[0]] = values
    return out


def played_magnitudes(path) -> dict:
    """FAP -> (most negative, most positive) value users play (``templates/fap_magnitudes.yaml``,
    written by ``tools/fap_magnitudes.py``); {} for no file. A malformed file is a one-line
    :class:`~faceforge.exceptions.TemplateError`."""
    from pathlib import Path

    from faceforge.exceptions import TemplateError
    from faceforge.io.safe_yaml import load_user_yaml

    if not path:
        return {}
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise TemplateError(f"cannot read it ({exc.__class__.__name__})", path) from None
    data = load_user_yaml(text, str(path), error=TemplateError)
    try:
        return {int(k): (float(v[0]), float(v[1])) for k, v in (data or {}).items()}
    except (TypeError, ValueError, IndexError, AttributeError):
        raise TemplateError("expected lines 'FAP: [most negative, most positive]'", path) from None


def lip_opening(mapping, simulate, head, value):
    """open_jaw alone at ``value`` MNS: how far the inner lips part (2.3 - 2.2), in MNS units."""
    import numpy as np

    if "2.2" not in head.fdp_vertex or "2.3" not in head.fdp_vertex:
        return None
    faps = np.zeros((1, 68))
    faps[0, 2] = value
    skin = simulate(mapping, faps)[0]
    a, b = head.fdp_vertex["2.2"], head.fdp_vertex["2.3"]
    gap0 = head.rest[a, 1] - head.rest[b, 1]
    gap = skin[a, 1] - skin[b, 1]
    opened = (gap - gap0) / head.fapu.unit("MNS")
    return {"requested": value, "achieved": float(opened), "relative_error": float(abs(opened - value) / value)}


class OneOffPoses:
    """The calibration's poses outside the sweep's chains (the coupling's open_jaw, the jaw-assisted
    lips of :func:`~faceforge.animation.calibrate_jaw.fit_muscle_reach`, the lip opening), as a
    ``simulate(mapping, faps (k, 68)) -> settled skins (k, n, 3)`` callable.

    rig : Rig (with ``reset``); to_controls : (mapping, faps) -> (contractions (k, m), jaw (k, 3));
    settings : SettleSettings; stats : SettleStats appended to
    warm : the first pose starts from rest, each later one continues from the pose before
        (``animate.calibrate.warm_jaw_poses``: they all have the jaw open, and a pose from rest
        spends most of its frames opening it); False: every pose from rest
    A pose is deterministic in its controls and the pose it starts from: the same controls are
    settled once (the coupling's open_jaw pose and the lip opening's, whose lip entries are not
    driven, are one simulation).
    """

    def __init__(self, rig, to_controls, fps: float, settings, stats, warm: bool = False):
        self.rig, self.to_controls, self.fps, self.settings, self.stats = rig, to_controls, fps, settings, stats
        self.warm = warm
        self.done = {}
        self.holding = None                      # (c (m,), jaw (3,)) the rig holds after the last pose

    def __call__(self, mapping, faps):
        from faceforge.animation.statics import settle

        c, jaw = self.to_controls(mapping, faps)
        key = (c.tobytes(), jaw.tobytes())
        if key not in self.done:
            before = self.holding if self.warm else None
            self.done[key] = settle(self.rig, c, jaw, self.fps, self.settings, stats=self.stats,
                                    warm=before is not None, previous=before)
            self.holding = (c[-1], jaw[-1])
        return self.done[key]


def probe_vertices(head, probes: dict) -> tuple:
    """The skin vertices calibration reads: each probe's FDP vertex and reference
    (:func:`calibration_probes`, FAP -> Probe) and the lip opening's FDPs 2.2 / 2.3, sorted, as a
    tuple of ints."""
    seen = {int(p.vertex) for p in probes.values()} | {int(p.relative_to) for p in probes.values()
                                                         if int(p.relative_to) >= 0}
    return tuple(sorted(seen | {int(head.fdp_vertex[f]) for f in ("2.2", "2.3") if f in head.fdp_vertex}))


@dataclass
class CalibrationResult:
    """What :func:`calibrate_head` measured: the calibrated mapping, the rows
    (:class:`faceforge.animation.calibrate.Row`), their summary, the lip opening of open_jaw
    (or None) and the probes (FAP number -> Probe)."""

    mapping: object
    rows: list
    summary: dict
    lips: dict | None
    probes: dict
    statics: dict | None = None
    mirrored: dict | None = None     # right entry name -> the left twin whose response it plays


def calibrate_head(head, template, config, log=lambda m: None, progress=None) -> CalibrationResult:
    """Fit ``template``'s response curves on ``head`` (``animate.fps``, ``animate.calibrate.*``
    and ``animate.statics.*`` of ``config``) on warm chains of converged poses
    (:func:`faceforge.animation.calibrate_sweep.calibrate_sweep`); ``progress`` wraps an
    iterable (optional). The result's ``statics`` says how the poses settled. On a symmetric
    rig (``head.symmetric``) only the left entry of each left/right pair is probed, at both
    sides' requests, and the right one plays its response (:mod:`~faceforge.animation.calibrate_mirror`;
    the result's ``mirrored``); its rows are then the left entry's only."""
    from dataclasses import replace

    from faceforge.animation.calibrate import measure_coupling, summarize
    from faceforge.animation.calibrate_mirror import entry_twins, joint_requests, mirror_responses
    from faceforge.animation.calibrate_sweep import calibrate_sweep, face_lanes
    from faceforge.animation.controls import controls
    from faceforge.animation.statics import SettleSettings, SettleStats, settle

    fps = float(config.get("animate.fps"))
    # calibration's probes settle to their own tolerance (animate.calibrate.statics_tolerance):
    # a looser one than the sheets' costs 0.03 points of median error and a fifth of the frames
    sheets = SettleSettings.from_config(config)
    # and stop a probe flipping between two states (animate.calibrate.cycle) instead of waiting out the stall
    settings = replace(sheets, tolerance=float(config.get("animate.calibrate.statics_tolerance")),
                       cycle=int(config.get("animate.calibrate.cycle")))
    # animate.calibrate.watch_fdps: a pose is settled once the vertices calibration reads (the FDPs) stop moving
    watch = probe_vertices(head, calibration_probes(template, head)) \
        if bool(config.get("animate.calibrate.watch_fdps", False)) else None
    settings = replace(settings, watch=watch)
    # the jaw coupling, the jaw-assisted lips and the lip opening (OneOffPoses: the first from rest) are
    # held to the sheets' tolerance with no stall (a slowly settling lip cut short read 32 % low on the
    # synthetic head)
    final = replace(sheets, stall=0, watch=watch)
    stats = SettleStats()
    held = {}

    def pose_for(mapping, faps, warm):
        c, jaw = controls(mapping, faps[None], head)
        skin = settle(head.rig, c, jaw, fps, settings, warm=warm, stats=stats, previous=held.get("now"))[0]
        held["now"] = (c[0], jaw[0])
        return skin

    once = OneOffPoses(head.rig, lambda mapping, faps: controls(mapping, faps, head), fps, final, stats,
                       warm=bool(config.get("animate.calibrate.warm_jaw_poses")))

    def simulate(mapping, faps):
        held.pop("now", None)                    # the sweep's chains are over: the rig leaves their pose
        return once(mapping, faps)

    probes = calibration_probes(template, head)
    requested = requested_values(template, config)
    # a symmetric rig: each right entry plays its left twin's response (calibrate_mirror)
    twins = entry_twins(template) if getattr(head, "symmetric", False) else {}
    if twins:
        requested = joint_requests(template, twins, requested)
    count = len(template.entries) - len(twins)
    log(f"calibrating {count} entries ({len(probes)} FAPs observable) up to the magnitudes users play, each "
        f"pose held until it converges" + (f"; {len(twins)} right entries mirror their left twins (symmetric rig)"
                                           if twins else ""))
    calibrated, rows = calibrate_sweep(
        template, pose_for, head.rest, probes, requested, tolerance=float(config.get("animate.calibrate.tolerance")),
        max_steps=int(config.get("animate.calibrate.refine")),
        lanes=face_lanes(template) if bool(config.get("animate.calibrate.lanes")) else None, skip=set(twins),
        progress=None if progress is None else (lambda it: progress(it, total=count, desc="FAPs")))
    calibrated = mirror_responses(calibrated, twins)
    jaw_magnitude = float(config.get("animate.calibrate.jaw_magnitude"))
    if 3 in probes:
        calibrated = measure_coupling(calibrated, simulate, head.rest, probes, value=jaw_magnitude)
    from faceforge.animation.calibrate_jaw import fit_muscle_reach

    calibrated, _ = fit_muscle_reach(calibrated, simulate, head.rest, probes, requested, log=log)
    lips = lip_opening(calibrated, simulate, head, jaw_magnitude)
    head.rig.reset()
    mirrored = {template.entries[r].name: template.entries[l].name for r, l in sorted(twins.items())}
    return CalibrationResult(calibrated, rows, summarize(rows), lips, probes, stats.as_dict(), mirrored)
