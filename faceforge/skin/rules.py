"""Binding rules beyond the paper (§8): the inner lip band, the muscles inserting through
others (``bind.insertions``), the modiolus at the mouth corners (``bind.modiolus_radius``), the
commissure, the vermilion and the nose (``bind.nose_on_bone``); :mod:`faceforge.skin.binding`
and :func:`faceforge.skin.head.bind_head` explain each."""

from __future__ import annotations

import numpy as np

from faceforge.constants import FLOAT, INT
from faceforge.geometry.triangles import vertex_normals


#: soft tissue depth at the mouth corners, mm (Rhine 1983 ``ecm2_sup``, the deepest of the
#: mouth region in :data:`faceforge.anatomy.tissue.DEPTH_MM`): the width of the lip band
LIP_BAND_MM = 18.0


def lip_band_width(landmarks: dict) -> float | None:
    """:data:`LIP_BAND_MM` in skin units (scaled by the eye separation, ``ES0 / 63 mm``);
    None when the eye FDPs that give ES0 are missing."""
    from faceforge.anatomy.tissue import units_per_mm

    try:
        return LIP_BAND_MM * units_per_mm(landmarks)
    except KeyError:
        return None


#: inner lip skin faces more than 60 degrees away from the front (cosine below this)
INNER_LIP_COS = 0.5


def lip_band(cut, width: float | None, forward=(0.0, 0.0, 1.0)) -> np.ndarray:
    """(n,) bool: the inner lip skin -- working vertices within ``width`` (skin units,
    shortest edge path over the skin) of the inner-lip contours, corners included, whose
    normal turns more than 60 degrees away from ``forward`` (the face's front): where the
    lips touch each other and roll into the mouth. None, or no contours: no vertex."""
    from scipy.sparse.csgraph import dijkstra

    from faceforge.geometry.triangles import edge_graph

    n = len(cut.vertices)
    if width is None or len(cut.upper) < 2 or len(cut.lower) < 2:
        return np.zeros(n, bool)
    v, f = np.asarray(cut.vertices, FLOAT), np.asarray(cut.faces, INT)
    seeds = np.unique(np.r_[cut.upper, cut.lower]).astype(INT)
    d = dijkstra(edge_graph(v, f), indices=seeds, min_only=True, limit=float(width) * (1.0 + 1e-9))
    fwd = np.asarray(forward, FLOAT) / np.linalg.norm(forward)
    return (d <= width) & (vertex_normals(v, f) @ fwd < INNER_LIP_COS)


def match_insertions(insertions, names) -> tuple[list[int], list[str]]:
    """Which of ``names`` (muscle names; None for a body that is no muscle) ``insertions``
    (``bind.insertions``: a muscle's name, or a left/right pair's name without ``_L`` / ``_R``)
    selects: ``(indices into names, the insertion names that match none)``."""
    wanted = set(insertions)
    hits, used = [], set()
    for i, n in enumerate(names):
        if n is None:
            continue
        key = n if n in wanted else (n[:-2] if n[-2:] in ("_L", "_R") and n[:-2] in wanted else None)
        if key is not None:
            hits.append(i)
            used.add(key)
    return hits, [n for n in insertions if n not in used]


#: FDPs of the mouth corners: outer lip contour (8.3 left, 8.4 right), inner (2.4, 2.5)
CORNER_FDPS = ("8.3", "8.4", "2.4", "2.5")

#: ``bind.modiolus_radius``: the skin within this fraction of MW0 (the mouth width, FDP 8.3 to
#: 8.4) of a mouth corner binds to the orbicularis oris (module docstring, the modiolus)
MODIOLUS_RADIUS = 0.12


#: FDPs of the inner lip corners, where the two lips meet (the commissure)
COMMISSURE_FDPS = ("2.4", "2.5")

#: ``bind.commissure_radius``: the lip skin within this fraction of MW0 of an inner lip corner
#: binds to the whole ring, not its own lip's arc (:func:`faceforge.skin.bind_passes.commissure_anchors`)
COMMISSURE_RADIUS = 0.05


def commissure_mask(vertices, landmarks: dict, radius: float = COMMISSURE_RADIUS) -> np.ndarray:
    """(n,) bool: the vertices within ``radius`` x MW0 (|FDP 8.3 - FDP 8.4|) of an inner lip
    corner (:data:`COMMISSURE_FDPS`, those given). No vertex without 8.3 and 8.4 or with
    ``radius`` 0."""
    return _near_fdps(vertices, landmarks, radius, COMMISSURE_FDPS)


def modiolus_mask(vertices, landmarks: dict, radius: float = MODIOLUS_RADIUS) -> np.ndarray:
    """(n,) bool: the vertices within ``radius`` x MW0 of one of the mouth corners'
    FDPs (:data:`CORNER_FDPS`, those given); MW0 = |FDP 8.3 - FDP 8.4|. No vertex
    without 8.3 and 8.4 or with ``radius`` 0."""
    return _near_fdps(vertices, landmarks, radius, CORNER_FDPS)


def _near_fdps(vertices, landmarks: dict, radius: float, fdps) -> np.ndarray:
    """(n,) bool: the vertices within ``radius`` x MW0 of one of ``fdps`` (those given)."""
    v = np.asarray(vertices, FLOAT)
    corners = [landmarks[k] for k in fdps if k in landmarks]
    if radius <= 0.0 or "8.3" not in landmarks or "8.4" not in landmarks or not corners:
        return np.zeros(len(v), bool)
    reach = radius * float(np.linalg.norm(np.subtract(landmarks["8.3"], landmarks["8.4"])))
    return (np.linalg.norm(v[:, None, :] - np.asarray(corners, FLOAT)[None], axis=2) <= reach).any(axis=1)


#: FDP pairs (inner, outer) at each lip's midline: upper 2.2 / 8.1, lower 2.3 / 8.2
VERMILION_FDPS = {1: ("2.2", "8.1"), -1: ("2.3", "8.2")}


def vermilion_mask(cut, sides, landmarks: dict, scale: float = 1.0) -> np.ndarray:
    """(n,) bool: the vermilion -- each lip's vertices (``sides`` +1 upper, -1 lower; (n,) int)
    within ``scale`` x that lip's midline height (|FDP 2.2 - 8.1| upper, |2.3 - 8.2| lower, skin
    units) of its inner lip contour (``cut.upper`` / ``cut.lower``), by shortest edge path over the skin:
    the red of the lips between the inner and outer lip contours. A lip without its two FDPs
    or its contour, or ``scale`` 0: no vertex."""
    from scipy.sparse.csgraph import dijkstra

    from faceforge.geometry.triangles import edge_graph

    v, f = np.asarray(cut.vertices, FLOAT), np.asarray(cut.faces, INT)
    sides = np.asarray(sides).reshape(-1)
    out = np.zeros(len(v), bool)
    for side, seeds in ((1, cut.upper), (-1, cut.lower)):
        inner, outer = VERMILION_FDPS[side]
        if inner not in landmarks or outer not in landmarks or len(seeds) < 2 or scale <= 0.0:
            continue
        reach = scale * float(np.linalg.norm(np.subtract(landmarks[inner], landmarks[outer])))
        d = dijkstra(edge_graph(v, f), indices=np.unique(np.asarray(seeds, INT)), min_only=True,
                     limit=reach * (1.0 + 1e-9))
        out |= (sides == side) & (d <= reach)
    return out


#: the nose's FDPs (:func:`nose_mask`): its base at the midline (subnasale), its tip, the alar
#: bases (the nostrils' outer ends at the lip) and the alar creases (the nose's widest points)
NOSE_FDPS = ("9.15", "9.3", "9.4", "9.5", "9.1", "9.2")


#: how far above the nose base (FDP 9.15) the nose's skin leaves the ring, mm (scaled by ES0,
#: :func:`faceforge.anatomy.tissue.units_per_mm`; :func:`nose_mask`): the subnasale and the
#: nostrils' sills, where the orbicularis oris' upper fibres insert (with the depressor septi),
#: move with the lip; with them on the bone MediaPipe's coarse philtrum (one row of triangles
#: from 9.15 to the lip) held the upper lip up (FAP 55/56 +112 MNS: 34 % short)
NOSE_BASE_MM = 2.0


def nose_mask(vertices, landmarks: dict, up=(0.0, 1.0, 0.0), base_mm: float = NOSE_BASE_MM) -> np.ndarray:
    """(n,) bool: the external nose and its nostrils (``bind.nose_on_bone``) -- the vertices on or
    above the nose's lower outline along ``up`` (the line from the nose base, FDP 9.15, at the
    midline to the alar bases' height at their side: the skin under the nostrils' sills is the upper
    lip's; measured from 9.15, never below ``base_mm`` above it, :data:`NOSE_BASE_MM`), within the
    nose's half width of the midline
    (the alar bases' 9.4 / 9.5 at their height, widening linearly to the alar creases' 9.1 / 9.2
    at theirs and above; measured across, from 9.15) and no deeper behind 9.15 than the tip (9.3)
    is in front of it (the nostrils' insides, not the palate). No vertex without the six FDPs
    (:data:`NOSE_FDPS`)."""
    v = np.asarray(vertices, FLOAT)
    if any(k not in landmarks for k in NOSE_FDPS):
        return np.zeros(len(v), bool)
    p = {k: np.asarray(landmarks[k], FLOAT) for k in NOSE_FDPS}
    u = np.asarray(up, FLOAT) / np.linalg.norm(up)
    base = p["9.15"]
    across = p["9.1"] - p["9.2"]
    across -= (across @ u) * u
    fwd = p["9.3"] - base
    fwd -= (fwd @ u) * u
    if np.linalg.norm(across) <= 0.0 or np.linalg.norm(fwd) <= 0.0:
        return np.zeros(len(v), bool)
    across /= np.linalg.norm(across)
    depth = float(np.linalg.norm(fwd))
    fwd /= depth
    d = v - base
    h, side, ahead = d @ u, np.abs(d @ across), d @ fwd

    def at(a, b):   # (height, half width) of an FDP pair
        m = 0.5 * (p[a] + p[b]) - base
        return float(m @ u), 0.5 * abs(float((p[a] - p[b]) @ across))

    (hb, wb), (hc, wc) = at("9.4", "9.5"), at("9.1", "9.2")
    t = np.clip((h - hb) / (hc - hb), 0.0, 1.0) if hc > hb else np.ones(len(v))
    width = wb + t * (wc - wb) if hc > hb else np.full(len(v), max(wb, wc))
    floor = max(hb, 0.0) * np.clip(side / wb, 0.0, 1.0) if wb > 0.0 else np.zeros(len(v))   # base to alar base
    if base_mm > 0.0:
        from faceforge.anatomy.tissue import units_per_mm

        try:
            floor = np.maximum(floor, base_mm * units_per_mm(landmarks))
        except KeyError:   # no ES0: from the nose base itself
            pass
    return (h >= floor - 1e-9 * depth) & (side <= width) & (ahead >= -depth)
