"""Measurements of issue 25 ("expressions that read") on a bound head, shared by
``bench_expressions.py``: mirror agreement of left/right FAPs, the jaw's chin path, and per
expression the muscles used and the peak displacement by region.

All poses are settled as ``faceforge expressions`` settles them
(:func:`faceforge.animation.playback.static_poses`). Distances in mm use the fit's own scale
(:func:`faceforge.anatomy.tissue.units_per_mm`); FAP-unit figures the head's FAPU.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

#: left/right FAP twins measured for mirror agreement (MPEG-4 numbers), with a value each
MIRROR_FAPS = (("raise_cornerlip", 12, 13, 150.0), ("stretch_cornerlip", 6, 7, 100.0),
               ("raise_i_eyebrow", 31, 32, 100.0), ("raise_o_eyebrow", 35, 36, 100.0),
               ("squeeze_eyebrow", 37, 38, 80.0), ("lift_cheek", 41, 42, 100.0),
               ("lower_t_lip_m", 8, 9, -150.0), ("raise_b_lip_m", 10, 11, -150.0))

#: FDPs of each region for the peak displacement (both sides where there are two)
REGIONS = {"brows": ("4.1", "4.2", "4.3", "4.4", "4.5", "4.6"),
           "lids": ("3.1", "3.2", "3.3", "3.4"),
           "cheeks": ("5.1", "5.2", "5.3", "5.4"),
           "nose": ("9.1", "9.2", "9.4", "9.5"),
           "mouth_corners": ("8.3", "8.4"),
           "lips": ("8.1", "8.2", "8.5", "8.6", "8.7", "8.8")}


def load_head(workdir: Path, sets=(), mapping_path=None):
    """(BoundHead, FapMapping, config) of a fitted and bound workdir; the mapping the
    workdir plays (its calibration when there is one, else the template) unless given."""
    from faceforge.animation.fap_mapping import load_fap_mapping
    from faceforge.animation.rig import BoundHead
    from faceforge.io.config import load_config
    from faceforge.pipeline import mapping as stage

    config = load_config(remembered=workdir / "config.yaml", sets=list(sets))
    head = BoundHead(workdir / "fit", workdir / "bind", config)
    head._bench_lids = head.eyelids(config)
    head._bench_config = config
    if mapping_path is None:
        cal = stage.calibrated_mapping_path(workdir)
        mapping_path = cal if cal.is_file() else stage.mapping_template_path(config)
    mapping = load_fap_mapping(mapping_path)
    template = load_fap_mapping(stage.mapping_template_path(config))
    from dataclasses import replace

    mapping = replace(mapping, expressions=template.expressions, visemes=template.visemes)
    return head, mapping, config


def settle(head, mapping, faps: np.ndarray, settle_frames: int | None = None, lids=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Settled skins (k, n, 3), contractions (k, m) and jaw (k, 3) for FAP rows (k, 68),
    eyelids laid over. Each pose is held until the skin stops moving (``animate.statics``, as
    ``faceforge expressions`` holds it), or for ``settle_frames`` fixed frames when given."""
    from faceforge.animation.controls import controls
    from faceforge.animation.playback import static_poses
    from faceforge.animation.statics import SettleSettings
    from faceforge.animation.statics import settle as held

    c, jaw = controls(mapping, faps, head)
    if settle_frames is None:
        skins = held(head.rig, c, jaw, 25.0, SettleSettings.from_config(head._bench_config))
        head.rig.reset()
    else:
        skins = static_poses(head.rig, c, jaw, 25.0, settle=settle_frames)
    lids = lids if lids is not None else getattr(head, "_bench_lids", None)
    if lids is not None:
        skins = lids.apply(skins, faps)
    return skins, c, jaw


def mirror_partner(rest: np.ndarray, plane) -> np.ndarray:
    """(n,) index of the vertex nearest each vertex's mirror image."""
    from scipy.spatial import cKDTree

    return cKDTree(rest).query(plane(rest))[1]


def mirror_agreement(head, mapping, plane) -> list[dict]:
    """Per left/right FAP twin: ``||mirror(d_L) - d_R|| / ||d_L||`` over the skin (the
    fraction of the motion that differs), and the two peak displacements (FAPU of the FAP)."""
    partner = mirror_partner(head.rest, plane)
    rows = []
    for name, left, right, value in MIRROR_FAPS:
        faps = np.zeros((2, 68))
        faps[0, left - 1] = value
        faps[1, right - 1] = value
        skins, _, _ = settle(head, mapping, faps)
        dl, dr = skins[0] - head.rest, skins[1] - head.rest
        ml = plane.direction(dl[partner])
        diff = float(np.linalg.norm(ml - dr) / max(np.linalg.norm(dl), 1e-30))
        pl, pr = np.linalg.norm(dl, axis=1).max(), np.linalg.norm(dr, axis=1).max()
        rows.append({"faps": f"{left}/{right}", "name": name, "value": value,
                     "differs": round(diff, 4), "peak_left": float(pl), "peak_right": float(pr),
                     "peak_ratio": round(float(min(pl, pr) / max(pl, pr, 1e-30)), 4)})
    return rows


def chin_path(head, mapping, values=(150.0, 300.0, 450.0, 2000.0)) -> list[dict]:
    """open_jaw alone: the skin chin's (FDP 2.1) path down and back, MNS units."""
    faps = np.zeros((len(values), 68))
    faps[:, 2] = values
    skins, _, jaw = settle(head, mapping, faps)
    mns = head.fapu.unit("MNS")
    v = head.fdp_vertex["2.1"]
    rows = []
    for k, val in enumerate(values):
        d = (skins[k, v] - head.rest[v]) / mns
        rows.append({"open_jaw": val, "pitch_deg": round(float(np.degrees(jaw[k, 0])), 2),
                     "down_mns": round(float(-d[1]), 1), "back_mns": round(float(-d[2]), 1),
                     "back_per_down": round(float(-d[2] / max(-d[1], 1e-9)), 3)})
    return rows


def expression_rows(head, mapping, units_per_mm: float, names=None) -> list[dict]:
    """Per expression preset at full intensity: the muscles used (contraction >= 0.05), the jaw
    opening, and the peak displacement in mm over each region's FDPs."""
    names = list(names or mapping.expressions)
    faps = np.array([mapping.expressions[n] for n in names], dtype=float).reshape(len(names), 68)
    skins, c, jaw = settle(head, mapping, faps)
    rows = []
    for k, n in enumerate(names):
        d = np.linalg.norm(skins[k] - head.rest, axis=1) / units_per_mm
        peaks = {}
        for region, fdps in REGIONS.items():
            ids = [head.fdp_vertex[f] for f in fdps if f in head.fdp_vertex]
            peaks[region] = round(float(d[ids].max()), 2) if ids else None
        used = {m: round(float(x), 3) for m, x in zip(head.controls, c[k]) if x >= 0.05}
        rows.append({"expression": n, "jaw_pitch_deg": round(float(np.degrees(jaw[k, 0])), 2),
                     "muscles": used, "peak_mm": peaks, "face_peak_mm": round(float(d.max()), 2)})
    return rows
