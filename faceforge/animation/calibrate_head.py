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
    """FAP number -> requested FAPU values (half and full typical magnitude, both signs where the
    mapping can produce them)."""
    mags = dict(config.get("animate.calibrate.magnitude"))
    jaw_mag = float(config.get("animate.calibrate.jaw_magnitude"))
    out = {}
    for e in mapping.entries:
        if not (e.positive or e.negative or e.jaw is not None):
            continue                      # nothing to drive (e.g. a pure jaw-coupling entry)
        top = jaw_mag if (e.jaw is not None and e.jaw[0] == "pitch") else float(mags[e.fapu])
        values = [0.5 * top, top]
        two_sided = bool(e.negative) or (e.jaw is not None and e.jaw[0] == "yaw")
        if two_sided:
            values = [-top, -0.5 * top] + values
        out[e.faps[0]] = values
    return out


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


def calibrate_head(head, template, config, log=lambda m: None, progress=None) -> CalibrationResult:
    """Fit ``template``'s response curves on ``head`` (``animate.fps``,
    ``animate.calibrate.*`` of ``config``); ``progress`` wraps an iterable (optional)."""
    from faceforge.animation.calibrate import calibrate_mapping, measure_coupling, summarize
    from faceforge.animation.controls import controls
    from faceforge.animation.playback import static_poses

    fps = float(config.get("animate.fps"))
    settle = int(config.get("animate.calibrate.settle_frames"))

    def simulate(mapping, faps):
        c, jaw = controls(mapping, faps, head)
        return static_poses(head.rig, c, jaw, fps, settle=settle)

    probes = calibration_probes(template, head)
    requested = requested_values(template, config)
    log(f"calibrating {len(template.entries)} entries ({len(probes)} FAPs observable), "
        f"{settle} settle frames per pose")
    calibrated, rows = calibrate_mapping(
        template, simulate, head.rest, probes, requested, refine=int(config.get("animate.calibrate.refine")),
        progress=None if progress is None else (lambda it: progress(it, total=len(template.entries), desc="FAPs")))
    jaw_magnitude = float(config.get("animate.calibrate.jaw_magnitude"))
    if 3 in probes:
        calibrated = measure_coupling(calibrated, simulate, head.rest, probes, value=jaw_magnitude)
    lips = lip_opening(calibrated, simulate, head, jaw_magnitude)
    return CalibrationResult(calibrated, rows, summarize(rows), lips, probes)
