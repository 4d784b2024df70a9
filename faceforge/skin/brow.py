"""The brow's insertion (``bind.brow_band_mm``, beyond §8): the skin of the brow binds to the
brow muscles, not to the bone through the orbit.

The frontalis, the corrugator, the depressor supercilii and the orbital orbicularis oculi all
insert into the dermis of the brow. By its ray (§8) the brow skin binds to whatever the ray
meets first, and over the supraorbital ridge the inward ray passes below the frontalis' lower
edge into the orbit and meets the cranium at the back of it: on the MakeHuman sample a band
about 1 cm high along the brow (the brow itself, between the frontalis-bound forehead and the
lids) was tied to the orbit's floor 2-3.6 cm away. The frontalis then raised the forehead
above a brow held to the bone, and every brow unit of MakeHuman (a raise or a lowering peaked
at the brow, fading out 2-3 cm above it) was reproduced at a cosine of 0.36-0.62 whatever the
contractions (``benchmarks/bench_units.py``).

Here the skin within :data:`BROW_BAND_MM` of the brow line (FDPs 4.1-4.3-4.5, 4.2-4.4-4.6) and
above the upper lids (:data:`LID_CLEARANCE_MM` over FDP 3.1 / 3.2) that its rays bound to the
bone binds instead to the closest point of the brow muscles (``bind.brow_muscles``) within the
longest ray. The lids stay on the bone (the lid field moves them, :mod:`faceforge.animation.eyelids`).
"""

from __future__ import annotations

import numpy as np

from faceforge.constants import FLOAT

#: ``bind.brow_band_mm``: the skin within this many mm (an average adult's, scaled by ES0) of
#: the brow line is the brow's (0: none, the paper's rays)
BROW_BAND_MM = 10.0

#: the brow band keeps this many mm above the upper lid's FDP (3.1, 3.2) height: the lids stay
LID_CLEARANCE_MM = 3.0

#: the brow lines, each from the inner end over the top to the outer end
BROW_LINES = (("4.1", "4.3", "4.5"), ("4.2", "4.4", "4.6"))

#: the upper lid FDP of each brow line's eye
UPPER_LIDS = ("3.1", "3.2")


def _segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(k,) distance of the points p (k, 3) to the segment a-b (3,)."""
    ab = b - a
    t = np.clip(((p - a) @ ab) / max(float(ab @ ab), 1e-300), 0.0, 1.0)
    return np.linalg.norm(p - (a + t[:, None] * ab), axis=1)


def brow_mask(vertices, landmarks: dict, band_mm: float = BROW_BAND_MM, up=(0.0, 1.0, 0.0)) -> np.ndarray:
    """(n,) bool: the vertices within ``band_mm`` (scaled by ES0, :func:`faceforge.anatomy.
    tissue.units_per_mm`) of a brow line (:data:`BROW_LINES`, the FDPs given) and higher along
    ``up`` than that eye's upper lid FDP plus :data:`LID_CLEARANCE_MM`. No vertex with
    ``band_mm`` 0 or without the FDPs that give ES0."""
    from faceforge.anatomy.tissue import units_per_mm

    v = np.asarray(vertices, FLOAT)
    mask = np.zeros(len(v), bool)
    if band_mm <= 0.0:
        return mask
    try:
        mm = units_per_mm(landmarks)
    except KeyError:
        return mask
    u = np.asarray(up, FLOAT) / np.linalg.norm(up)
    for line, lid in zip(BROW_LINES, UPPER_LIDS):
        pts = [np.asarray(landmarks[k], FLOAT) for k in line if k in landmarks]
        if len(pts) < 2 or lid not in landmarks:
            continue
        d = np.min([_segment_distance(v, a, b) for a, b in zip(pts[:-1], pts[1:])], axis=0)
        above = v @ u > float(np.asarray(landmarks[lid], FLOAT) @ u) + LID_CLEARANCE_MM * mm
        mask |= (d <= band_mm * mm) & above
    return mask


def brow_anchors(v, bodies, kinds, muscles, mask, max_distance, body, face, pts, dist,
                 allowed=None) -> np.ndarray:
    """Rebind the vertices of ``mask`` (n,) bool that are on the bone (``kinds[body]`` not a
    muscle) to the closest point of the bodies ``muscles`` (indices) within ``max_distance``
    (module docstring). ``allowed`` (n, n_bodies) bool filters bodies per vertex. Updates
    ``body, face, pts, dist`` in place (a vertex with no brow muscle in reach keeps its anchor);
    returns the (n,) bool mask of the vertices rebound."""
    from faceforge.skin.casting import MUSCLE

    on_bone = (body >= 0) & (np.asarray(kinds)[np.maximum(body, 0)] != MUSCLE)
    todo = np.flatnonzero(np.asarray(mask, bool) & on_bone)
    return _rebind(v, bodies, todo, muscles, max_distance, body, face, pts, dist, allowed)


def _rebind(v, bodies, todo, candidates, max_distance, body, face, pts, dist, allowed) -> np.ndarray:
    """Anchor each vertex ``todo`` (k,) int to the closest point of the bodies ``candidates``
    (indices; ``allowed`` (n, n_bodies) bool filters them per vertex, None: all) within
    ``max_distance``; updates ``body, face, pts, dist`` in place, returns the (n,) bool mask of
    the vertices rebound (one with no candidate in reach keeps its anchor)."""
    from faceforge.geometry.surface_points import closest_points

    done = np.zeros(len(v), bool)
    best = np.full(len(todo), np.inf)
    for i in candidates if len(todo) else ():
        p, d, tri = closest_points(v[todo], bodies[i].vertices, bodies[i].faces)
        take = (d < best) & (d <= max_distance)
        if allowed is not None:
            take &= allowed[todo, i]
        best[take] = d[take]
        t = todo[take]
        body[t], face[t], pts[t], dist[t] = i, tri[take], p[take], d[take]
        done[t] = True
    return done


#: each eye: inner canthus, outer canthus, upper lid, lower lid FDPs (subject's left, right)
EYES = (("3.11", "3.7", "3.1", "3.3"), ("3.12", "3.8", "3.2", "3.4"))

#: the eye's skin reaches this many eye widths (inner to outer canthus) from the canthi's segment
EYE_REACH = 1.0


def eye_mask(vertices, landmarks: dict, up=(0.0, 1.0, 0.0)) -> np.ndarray:
    """(n,) bool: the skin of the eyes, which no brow muscle may hold: within
    :data:`EYE_REACH` eye widths of an eye's canthi (:data:`EYES`), no higher than its upper
    lid FDP plus :data:`LID_CLEARANCE_MM` (below the brow band), and either no lower than its
    lower lid FDP less that (the lids and their margins) or that far behind the canthi (the
    socket a mesh without eyeballs closes behind the lids).

    By their rays (§8) the lid margins and the socket's lining bind to whatever the ray meets
    across the opening: on the MakeHuman sample 42 such vertices per eye were tied to the
    corrugator, the depressor supercilii, the frontalis or the orbital orbicularis oculi, so
    the corrugator pulled the lids 2.6-3.6 mm toward the nose and the socket's floor held the
    brow back. No vertex without the FDPs."""
    from faceforge.anatomy.tissue import units_per_mm

    v = np.asarray(vertices, FLOAT)
    mask = np.zeros(len(v), bool)
    try:
        mm = units_per_mm(landmarks)
    except KeyError:
        return mask
    u = np.asarray(up, FLOAT) / np.linalg.norm(up)
    if not all(k in landmarks for eye in EYES for k in eye):
        return mask
    p = {k: np.asarray(landmarks[k], FLOAT) for eye in EYES for k in eye}
    forward = np.cross(p["3.7"] - p["3.8"], u)   # subject's left x up: out of the face
    forward /= max(float(np.linalg.norm(forward)), 1e-300)
    gap = LID_CLEARANCE_MM * mm
    for inner, outer, upper, lower in EYES:
        width = float(np.linalg.norm(p[outer] - p[inner]))
        near = _segment_distance(v, p[inner], p[outer]) <= EYE_REACH * width
        h = v @ u
        lids = h >= float(p[lower] @ u) - gap
        behind = (v - 0.5 * (p[inner] + p[outer])) @ forward < -gap
        mask |= near & (h <= float(p[upper] @ u) + gap) & (lids | behind)
    return mask


def eye_anchors(v, bodies, kinds, muscles, mask, max_distance, body, face, pts, dist,
                allowed=None) -> np.ndarray:
    """Rebind the vertices of ``mask`` (n,) bool that are on one of the bodies ``muscles``
    (indices) to the closest point of the bone (every body whose ``kinds`` is not a muscle)
    within ``max_distance`` (:func:`eye_mask`). Updates ``body, face, pts, dist`` in place (a
    vertex with no bone in reach keeps its anchor); returns the (n,) bool mask rebound."""
    from faceforge.skin.casting import MUSCLE

    todo = np.flatnonzero(np.asarray(mask, bool) & np.isin(body, list(muscles)))
    bone = [i for i in range(len(bodies)) if kinds[i] != MUSCLE]
    return _rebind(v, bodies, todo, bone, max_distance, body, face, pts, dist, allowed)


#: ``bind.brow_shared_mm``: brow skin on one brow muscle takes a second anchor on another
#: insertion muscle whose surface is within this many mm (scaled by ES0) of its first anchor
BROW_SHARED_MM = 10.0


def shared_anchors(v, bodies, anchors: tuple, mask, brow, muscles, reach: float) -> tuple:
    """Second anchors of the brow (beyond §8): each vertex of ``mask`` (n,) bool bound to one of
    the bodies ``brow`` (indices: the brow muscles) and to no other body yet takes a second
    anchor at the closest point of the nearest other of the bodies ``muscles`` (the brow's
    insertions, the corrugator and the depressor supercilii) when that point lies within
    ``reach`` (skin units) of its first anchor.

    The brow's dermis receives the corrugator, the depressor supercilii and the frontalis
    together; bound by its ray to one of them, each vertex followed that muscle alone (MakeHuman,
    depressor supercilii at c = 1: the muscle 7.1 mm down on average, 12.7 at its insertion, FDP
    4.1, bound to the corrugator, 1.9 mm). ``anchors``: ``(vertex ids, body, face, point,
    distance, outward, closest)`` rows (k,), sorted by vertex; new rows follow their vertex's
    first. Returns the anchors."""
    ids, a_body = anchors[:2]
    muscles = [int(i) for i in muscles]
    count = np.bincount(ids, minlength=len(v))
    cand = np.flatnonzero(np.asarray(mask, bool)[ids] & np.isin(a_body, list(brow)) & (count[ids] == 1))
    if not muscles:
        return anchors
    return _extra_anchors(v, bodies, anchors, cand, muscles, reach)


#: the outer brow's dermis receives these two together (their pair names): the frontalis' outer
#: part raises it, the lateral orbicularis oculi lowers it
OUTER_BROW = ("frontalis_outer", "orbicularis_oculi")


def outer_shared_anchors(v, bodies, anchors: tuple, mask, reach: float) -> tuple:
    """:func:`shared_anchors` between the two muscles of :data:`OUTER_BROW`: brow skin (``mask``
    (n,) bool) on one of them with no second anchor takes one on the other within ``reach``.

    By its ray the outer brow binds to whichever sheet it meets first: on the MediaPipe sample
    FDP 4.5 and its two neighbours were on the orbicularis oculi and the cranium, none on the
    frontalis, so the frontalis outer at c = 1 (its sheet 356 ENS up) raised the outer brow 21.6
    ENS of the 50 the Xface files ask, only through the skin's stretch from the forehead above,
    and calibration, probing a curve that barely rose, settled anywhere between 1 and 22.
    Returns the anchors (unchanged without both muscles)."""
    from faceforge.skin.rules import match_insertions

    ids, _ = match_insertions(OUTER_BROW, [getattr(b, "name", None) if getattr(b, "kind", "") == "muscle"
                                           else None for b in bodies])
    if len(ids) < 2:
        return anchors
    return shared_anchors(v, bodies, anchors, mask, ids, ids, reach)


def raiser_anchors(v, bodies, anchors: tuple, mask, raisers, reach: float) -> tuple:
    """One more anchor for the brow on its raiser (``bind.brow_raisers``, beyond §8): each vertex
    of ``mask`` (n,) bool with an anchor on a brow muscle other than ``raisers`` (indices: the
    frontalis parts) and none on a raiser takes one at the closest point of the nearest raiser
    when that point lies within ``reach`` (skin units) of its first anchor.

    The frontalis inserts into the brow's dermis with the corrugator and the depressor
    supercilii, but by its ray the brow binds to whichever of them it meets first: on the
    MakeHuman sample the brow's rows (FDP 4.1 to 4.3 and 1 cm above) were on the corrugator and
    the depressor only, the frontalis carried the forehead above them, and a brow raise peaked
    1-3 cm above the brow while the brow itself followed only through the skin's stretch
    (MakeHuman's eyebrows-*-up units at a cosine of 0.36, ``benchmarks/bench_units.py``). With
    ``skin.join_insertions`` the vertex goes where its most moving muscle goes. ``anchors`` as
    :func:`shared_anchors`; returns them."""
    ids, a_body = anchors[0], anchors[1]
    raisers = [int(i) for i in raisers]
    if not raisers:
        return anchors
    on_raiser = np.zeros(len(v), bool)
    on_raiser[ids[np.isin(a_body, raisers)]] = True
    first = np.r_[True, ids[1:] != ids[:-1]]   # each vertex's first row (sorted by vertex)
    cand = np.flatnonzero(first & np.asarray(mask, bool)[ids] & ~on_raiser[ids]
                          & np.array([getattr(bodies[b], "kind", "") == "muscle" for b in a_body], bool))
    return _extra_anchors(v, bodies, anchors, cand, raisers, reach)


def _extra_anchors(v, bodies, anchors: tuple, cand, muscles, reach: float) -> tuple:
    """``anchors`` with one more row for each row ``cand`` (k,) int: at the closest point of the
    nearest of ``muscles`` (body indices) other than the row's own body, within ``reach`` of
    the row's point; rows sorted by vertex, each new one after its vertex's rows."""
    from faceforge.geometry.surface_points import closest_points

    ids, a_body, _, a_pts = anchors[:4]
    if not len(cand):
        return anchors
    best = np.full(len(cand), np.inf)
    hit = [np.zeros(len(cand), np.int64), np.zeros(len(cand), np.int64), np.zeros((len(cand), 3)),
           np.zeros(len(cand))]
    for i in muscles:
        p, d, tri = closest_points(v[ids[cand]], bodies[i].vertices, bodies[i].faces)
        gap = np.linalg.norm(p - a_pts[cand], axis=1)
        take = (a_body[cand] != i) & (gap <= reach) & (gap < best)
        best[take] = gap[take]
        hit[0][take], hit[1][take], hit[2][take], hit[3][take] = i, tri[take], p[take], d[take]
    ok = np.isfinite(best)
    rows = cand[ok]
    extra = (ids[rows], hit[0][ok], hit[1][ok], hit[2][ok], hit[3][ok], np.zeros(len(rows), bool),
             np.zeros(len(rows), bool))
    order = np.argsort(np.concatenate([ids, ids[rows]]), kind="stable")   # each after its vertex's rows
    return tuple(np.concatenate([a, np.asarray(b, dtype=np.asarray(a).dtype)])[order]
                 for a, b in zip(anchors, extra))


def lid_hold(binding, vertices, landmarks: dict, stiffness: float, up=(0.0, 1.0, 0.0)):
    """``skin.lid_hold`` (beyond §8): ``(tether (k,) float, held (k,) bool)`` per anchor of
    ``binding``: the anchors on the bone (cranium, mandible) of the upper lids' skin
    (:func:`eye_mask`, higher along ``up`` than its eye's canthi) are held (the caller carries
    them: their ``q`` starts at the skin vertex and stays there, the bone being still) by a
    tether of ``stiffness``; ``(None, none held)`` with ``stiffness`` 0 or without the eyes' FDPs.

    The lids are not simulated (:mod:`faceforge.animation.eyelids` lays their motion over the
    skin), and their skin, tied to the bone by the §8 stretch of ``skin.stiffness.anchor``
    (0.2), followed the brow's skin above it: on the MakeHuman sample the frontalis_inner_L's
    raise put 27 % of its field's energy below the brow, 1-2.5 cm under the brow line (the
    upper lid and its fold), where the expression unit eyebrows-left-inner-up is 0, and 26-45
    % of every brow unit's solved field (``benchmarks/bench_units.py --brows``). The upper
    lid's skin is held by the lid's own structures (the levator's aponeurosis, the orbital
    septum), not by the brow."""
    k = len(binding.vertex_ids)
    held = np.zeros(k, bool)
    if not stiffness or float(stiffness) <= 0.0 or not all(c in landmarks for eye in EYES for c in eye[:2]):
        return None, held
    v = np.asarray(vertices, FLOAT)
    u = np.asarray(up, FLOAT) / np.linalg.norm(up)
    eye = eye_mask(v, landmarks, up=u)
    above = np.zeros(len(v), bool)
    for inner, outer, _, _ in EYES:
        mid = 0.5 * (np.asarray(landmarks[inner], FLOAT) + np.asarray(landmarks[outer], FLOAT))
        width = float(np.linalg.norm(np.asarray(landmarks[outer], FLOAT) - np.asarray(landmarks[inner], FLOAT)))
        near = _segment_distance(v, np.asarray(landmarks[inner], FLOAT), np.asarray(landmarks[outer], FLOAT))
        above |= (near <= EYE_REACH * width) & ((v - mid) @ u > 0.0)
    held = (eye & above)[np.asarray(binding.vertex_ids)] & binding.on_bone()
    return (np.where(held, float(stiffness), 0.0) if held.any() else None), held


def toward_nose(vertices, landmarks: dict) -> np.ndarray:
    """(n, 3) float: per vertex the unit direction from its nearer eye's outer canthus to its inner
    one (:data:`EYES`; the nearer canthi segment), the way the corrugator draws the brow and the
    lid's skin under it (``skin.lid_hold_sink``, :mod:`faceforge.skin.sink`); zeros without the
    canthi FDPs. MPEG-4 names the corners by the image's left and right: of ``(3.11, 3.7)`` and
    ``(3.12, 3.8)`` the inner corner of each eye is the one nearer the other eye."""
    v = np.asarray(vertices, FLOAT)
    out = np.zeros((len(v), 3), FLOAT)
    if not all(c in landmarks for eye in EYES for c in eye[:2]):
        return out
    a = [np.asarray(landmarks[c], FLOAT) for eye in EYES for c in eye[:2]]   # (3.11, 3.7, 3.12, 3.8)
    eyes = [(a[0], a[1]), (a[2], a[3])]
    best = np.full(len(v), np.inf)
    for k, (p, q) in enumerate(eyes):
        other = sum(eyes[1 - k]) / 2.0
        inner, outer = (p, q) if np.linalg.norm(p - other) < np.linalg.norm(q - other) else (q, p)
        d = _segment_distance(v, inner, outer)
        m = inner - outer
        take = d < best
        best[take] = d[take]
        out[take] = m / max(float(np.linalg.norm(m)), 1e-300)
    return out


def forehead_mask(vertices, landmarks: dict, above_mm: float, up=(0.0, 1.0, 0.0)) -> np.ndarray:
    """(n,) bool: the forehead above the brow (``bind.forehead_bone_mm``): the vertices farther
    than ``above_mm`` (scaled by ES0, :func:`faceforge.anatomy.tissue.units_per_mm`) from both
    brow lines (:data:`BROW_LINES`) and higher along ``up`` than the closest point of the nearer
    line. No vertex with ``above_mm`` <= 0 or without the brow FDPs."""
    from faceforge.anatomy.tissue import units_per_mm

    v = np.asarray(vertices, FLOAT)
    n = len(v)
    if above_mm <= 0.0:
        return np.zeros(n, bool)
    try:
        mm = units_per_mm(landmarks)
    except KeyError:
        return np.zeros(n, bool)
    u = np.asarray(up, FLOAT) / np.linalg.norm(up)
    best = np.full(n, np.inf)
    height = np.zeros(n)   # the height along up of the closest brow-line point
    for line in BROW_LINES:
        pts = [np.asarray(landmarks[k], FLOAT) for k in line if k in landmarks]
        for a, b in zip(pts[:-1], pts[1:]):
            ab = b - a
            t = np.clip(((v - a) @ ab) / max(float(ab @ ab), 1e-300), 0.0, 1.0)
            c = a + t[:, None] * ab
            d = np.linalg.norm(v - c, axis=1)
            take = d < best
            best[take], height[take] = d[take], (c @ u)[take]
    return np.isfinite(best) & (best > above_mm * mm) & (v @ u > height)


def onto_cranium(binding, vertices, bodies, only_on, mask, max_distance: float):
    """``binding`` (:class:`faceforge.skin.binding.Binding`) with the vertices of ``mask`` (n,)
    bool whose anchors are all on the bodies ``only_on`` (indices) bound instead to the closest
    point of the cranium within ``max_distance`` (skin units), one anchor each (beyond §8); a
    vertex with no cranium in reach keeps its anchors. Returns ``(binding, count rebound)``.

    Two uses (:func:`faceforge.skin.head.bind_head`): the forehead above the brow off the
    frontalis (``bind.forehead_bone_mm``, :func:`forehead_mask`) and the nose off the orbicularis
    oris (``bind.nose_on_bone``, :func:`faceforge.skin.rules.nose_mask`). The frontalis inserts
    into the dermis of the brow; above it the muscle and the galea glide under the forehead's skin
    on a loose areolar layer, and the skin, tied to the scalp's layers rather than to the muscle,
    folds into the forehead's furrows when the brow rises. By its ray (§8) that skin binds to the
    frontalis itself and rose with it: on the MakeHuman sample a brow raise moved the forehead 3.9 cm
    above the brow 0.4 of the brow's rise, where MakeHuman's eyebrows units are 0
    (docs/notes/units9.md). Tied to the bone, it moves only as far as the skin's stretch from the
    raised brow carries it. The nose's skin lies over the ring's upper rows (behind the nostrils)
    and by its rays rode the pucker (docs/notes/tent17.md)."""
    from dataclasses import replace

    from faceforge.geometry.triangles import barycentric
    from faceforge.skin.casting import CRANIUM

    ids = np.asarray(binding.vertex_ids)
    n = len(binding.status)
    cranium = [i for i, b in enumerate(bodies) if getattr(b, "kind", "") == "cranium"]
    only_on = [int(i) for i in only_on]
    if not cranium or not only_on:
        return binding, 0
    off = np.bincount(ids[~np.isin(binding.body, only_on)], minlength=n) > 0   # a row on another body
    has = np.bincount(ids, minlength=n) > 0
    todo = np.flatnonzero(np.asarray(mask, bool) & has & ~off)
    if not len(todo):
        return binding, 0
    body = np.full(n, -1, np.int64)
    face = np.full(n, -1, np.int64)
    pts = np.zeros((n, 3), FLOAT)
    dist = np.full(n, np.inf, FLOAT)
    done = _rebind(np.asarray(vertices, FLOAT), bodies, todo, cranium, max_distance, body, face, pts, dist, None)
    moved = np.flatnonzero(done)
    if not len(moved):
        return binding, 0
    keep = ~np.isin(ids, moved)
    first = np.r_[True, ids[1:] != ids[:-1]] & ~keep   # the one row each moved vertex keeps
    new = keep | first
    rows = np.flatnonzero(new)
    out = {k: np.asarray(getattr(binding, k)).copy() for k in
           ("vertex_ids", "body", "face_ids", "bary", "points", "distance", "outward", "closest")}
    r = np.flatnonzero(first)
    vid = ids[r]
    out["body"][r], out["face_ids"][r], out["points"][r], out["distance"][r] = body[vid], face[vid], pts[vid], dist[vid]
    out["outward"][r] = out["closest"][r] = False
    for b in np.unique(body[vid]):
        sel = body[vid] == b
        out["bary"][r[sel]] = barycentric(pts[vid][sel], bodies[b].vertices, bodies[b].faces, face[vid][sel])
    status = np.asarray(binding.status).copy()
    status[moved] = CRANIUM
    return replace(binding, status=status, **{k: a[rows] for k, a in out.items()}), len(moved)
