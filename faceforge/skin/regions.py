"""Regions of the skin and the bind report (§8): the face front (in front of the ears, below
the hairline, above the chin) and the fractions of each region bound to muscle, bone or
nothing."""

from __future__ import annotations

import numpy as np

from faceforge.constants import FLOAT
from faceforge.skin.binding import CRANIUM, KIND_NAMES, MANDIBLE, MUSCLE, UNBOUND, Binding


#: ear attachment FDPs (otobasion superius / inferius) and the whole ear group
_EAR_FDPS = ("10.7", "10.8", "10.9", "10.10", "10.1", "10.2", "10.3", "10.4", "10.5", "10.6")
#: hairline FDPs from subject-right to subject-left (11.2, 11.1, 11.3)
_HAIRLINE_FDPS = ("11.2", "11.1", "11.3")


def face_front_mask(vertices, landmarks: dict, margin: float = 0.1) -> tuple[np.ndarray, dict]:
    """The face front: in front of the ears, below the hairline, above the chin.

    * In front of the ears: ``z`` above the most anterior ear FDP (10.x), else
      (no ear FDPs) above the landmarks' bounding box minus ``margin`` of its depth.
    * Below the hairline: ``y`` below the hairline through 11.2, 11.1, 11.3
      (piecewise linear in ``x``, constant beyond its ends), else below the
      landmarks' bounding box plus ``margin`` of its height.
    * Above the chin: ``y`` at or above FDP 2.1 (menton), else the box bottom.

    Parameters
    ----------
    vertices : (n, 3) float
    landmarks : dict
        FDP id -> (3,) position (skin units, +Y up, face along +Z).

    Returns
    -------
    mask : (n,) bool
    rule : dict
        Which rule each limit used and its value (JSON-ready).
    """
    v = np.asarray(vertices, FLOAT)
    pts = {k: np.asarray(p, FLOAT) for k, p in landmarks.items()}
    allp = np.array(list(pts.values())) if pts else v
    lo, hi = allp.min(axis=0), allp.max(axis=0)
    size = hi - lo
    rule = {}
    ears = [pts[k][2] for k in _EAR_FDPS if k in pts]
    if ears:
        z0 = float(max(ears))
        rule["ears"] = {"rule": "z > max z of the ear FDPs 10.x", "z": z0}
    else:
        z0 = float(lo[2] - margin * size[2])
        rule["ears"] = {"rule": f"z > landmark box front minus {margin} of its depth (no 10.x)", "z": z0}
    hair = [pts[k] for k in _HAIRLINE_FDPS if k in pts]
    if hair:
        h = np.array(sorted(hair, key=lambda p: p[0]))
        y_top = np.interp(v[:, 0], h[:, 0], h[:, 1])
        rule["hairline"] = {"rule": "y < hairline through 11.2, 11.1, 11.3 (linear in x)",
                            "points": h.tolist()}
    else:
        y_top = np.full(len(v), hi[1] + margin * size[1])
        rule["hairline"] = {"rule": f"y < landmark box top plus {margin} of its height (no 11.x)",
                            "y": float(y_top[0]) if len(v) else None}
    y0 = float(pts["2.1"][1]) if "2.1" in pts else float(lo[1])
    rule["chin"] = {"rule": "y >= FDP 2.1" if "2.1" in pts else "y >= landmark box bottom", "y": y0}
    mask = (v[:, 2] > z0) & (v[:, 1] < y_top) & (v[:, 1] >= y0)
    return mask, rule


def bind_report(binding: Binding, regions: dict, n_user: int | None = None) -> dict:
    """Fractions of skin vertices bound to muscle / cranium / mandible / nothing.

    Parameters
    ----------
    binding : Binding
    regions : dict
        Region name -> ``(n,) bool`` mask over the skin vertices.
    n_user : int, optional
        Count only the first ``n_user`` vertices (the user's).

    Returns
    -------
    dict (JSON-ready): per region the vertex count and fractions;
    ``missed_rays`` = vertices whose outward and inward rays both found nothing,
    ``closest_point_anchors`` = those of them bound to the closest skull point,
    ``unbound`` = the rest.
    """
    status = binding.status if n_user is None else binding.status[:n_user]
    out = {"vertices": int(len(status)), "regions": {}}
    for name, mask in {"all": np.ones(len(status), bool), **regions}.items():
        m = np.asarray(mask, bool)[: len(status)]
        count = int(m.sum())
        frac = {KIND_NAMES[c]: (float((status[m] == c).sum()) / count if count else 0.0)
                for c in (MUSCLE, CRANIUM, MANDIBLE, UNBOUND)}
        frac["bound"] = 1.0 - frac["none"]
        out["regions"][name] = {"vertices": count, "fraction": frac,
                                "unbound_vertices": int((status[m] == UNBOUND).sum())}
    closest = np.zeros(len(binding.status), bool)
    closest[binding.vertex_ids[binding.closest]] = True
    closest = closest[: len(status)]
    out["missed_rays"] = int((status == UNBOUND).sum() + closest.sum())
    out["closest_point_anchors"] = int(closest.sum())
    out["unbound"] = int((status == UNBOUND).sum())
    out["outward_anchors"] = int(binding.outward.sum())
    out["second_anchors"] = int(len(binding.vertex_ids) - len(np.unique(binding.vertex_ids)))
    per_body = np.bincount(binding.body, minlength=len(binding.body_names))
    out["anchors_per_body"] = {n: int(c) for n, c in zip(binding.body_names, per_body) if c}
    return out
