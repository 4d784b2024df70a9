"""Automatic FDP landmarks on a head mesh: find the face, see it from several views, lift,
agree, symmetrise.

1. :func:`faceforge.landmarks.views.find_face`: 24 axis frames, best face kept (any
   orientation; a mesh with no face raises ``no face found in MESH (tried N views)``).
2. The face's own frame from the best view's lifted points; :data:`views.VIEW_ANGLES`
   cameras framed on the face, the detector run on each.
3. Each view's 478 points lifted onto the mesh (:mod:`faceforge.landmarks.lift`; rays
   through holes land on the rim); the pupils (iris centres) in the plane of their lids
   when the eye is a hole. Per point the median over the views that saw it, put on the
   surface; its spread over the views is the point's uncertainty.
4. MediaPipe point -> FDP by the table ``data/mediapipe_fdp.yaml``.
5. On a mirror-symmetric mesh (:mod:`faceforge.landmarks.symmetry`) each left/right pair is
   made an exact mirror pair (the mean of the left point and the mirrored right one, and a
   vertex and its mirror vertex), and midline FDPs go onto the mirror plane.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np

from faceforge.exceptions import LandmarkError
from faceforge.landmarks.paint import REPAINTED, eye_open

#: FDPs on the midline of the face (put on the mirror plane of a symmetric mesh)
#: FDPs whose detector point is only a rule's start (the jaw contour, 4-5 % of the diagonal in front
#: of the jaw angle): left out where the rule does not place them (the MediaPipe mask has no jaw side)
RULE_ONLY = ("2.13", "2.14")
MIDLINE_FDPS = ("2.1", "2.2", "2.3", "2.10", "8.1", "8.2", "9.3", "9.15")
#: FDPs lying in an eye opening rather than on the skin when the eye is a hole
PUPILS = {"3.5": ("3.1", "3.3"), "3.6": ("3.2", "3.4")}
#: a detected point is written with a vertex id when a vertex lies this close (fraction of the
#: diagonal), else as a surface position alone (vertex: null): moving a point to its nearest
#: vertex cost accuracy (median error on MakeHuman / ICT 0.540 / 0.496 % with 0.0025,
#: 0.524 / 0.460 % with 0.001, 0.507 / 0.460 % with none)
VERTEX_SNAP = 0.001
#: the rules' lengths (thresholds, search bands, the subnasale's resolution guard) are fractions of
#: a face scale: the larger of the bounding-box diagonal and this many detected eye spans (|3.7 -
#: 3.12|). A whole head's diagonal is 4.4-5.3 eye spans (the young female MakeHuman 4.40, MakeHuman
#: 4.49, ICT 5.33), so its rules are unchanged; a head cut to a face mask (2.75-3.0 eye spans) or the
#: MediaPipe mask (2.87) keeps a whole head's rule lengths instead of 0.6 of them
RULE_SCALE_EYE_SPANS = 4.4


@lru_cache(maxsize=1)
def fdp_table() -> dict:
    """{fdp: MediaPipe point index} from ``data/mediapipe_fdp.yaml``."""
    import yaml

    path = Path(__file__).with_name("data") / "mediapipe_fdp.yaml"
    return {str(k): int(v) for k, v in yaml.safe_load(path.read_text())["mediapipe_to_fdp"].items()}


@dataclass
class Detection:
    """Detected FDPs on a mesh (the mesh's own frame and units).

    ids : tuple of k FDP ids; positions : (k, 3) float; vertex : (k,) int64 (-1: none);
    method : k strings, how each was placed; confidence : (k,) float in [0, 1];
    views : k lists of view labels that saw the point; spread : (k,) float, median distance of
    the views' points from the agreed one (fraction of the diagonal); info : dict (frame,
    views tried, symmetry, timings).
    """

    ids: tuple
    positions: np.ndarray
    vertex: np.ndarray
    method: list
    confidence: np.ndarray
    views: list
    spread: np.ndarray
    info: dict = field(default_factory=dict)


def _lift_view(sighting, vertices, faces, diagonal, radius_px):
    """(478, 3) lifted points of one view (pupils in their lids' plane when in a hole)
    and (478,) hole flags."""
    from faceforge.landmarks.lift import lift, view_depth

    pts, hole = lift(sighting.render, vertices, faces, sighting.points, diagonal, radius_px)
    table = fdp_table()
    for pupil, lids in PUPILS.items():
        i = table[pupil]
        if hole[i]:
            depth = np.mean(view_depth(sighting.render, pts[[table[lids[0]], table[lids[1]]]]))
            pts[i] = sighting.render.view.unproject(sighting.points[i:i + 1], np.array([depth]))[0]
    return pts, hole


def _consensus(stack: np.ndarray, diagonal: float):
    """(views, 478, 3) with NaN rows -> agreed (478, 3), spread (478,) and seen (views, 478)."""
    import warnings

    seen = np.isfinite(stack[:, :, 0])
    with warnings.catch_warnings():      # a point no view saw stays NaN (then: not placeable)
        warnings.simplefilter("ignore", RuntimeWarning)
        agreed = np.nanmedian(stack, axis=0)
        dist = np.linalg.norm(stack - agreed[None], axis=2)
        spread = np.nanmedian(np.where(seen, dist, np.nan), axis=0) / diagonal
    return agreed, spread, seen


def detect_landmarks(vertices: np.ndarray, faces: np.ndarray, path: str = "<mesh>",
                     symmetrise: bool = True, paint_eyes: bool = True) -> Detection:
    """Find the FDPs of :func:`fdp_table` on ``(vertices (n, 3), faces (m, 3))``.

    ``paint_eyes``: where the eyes are no opening (the frontal render sees neither a hole nor a
    recess inside the detected eye contours, :func:`faceforge.landmarks.paint.eye_open`, and the eye
    rules find no loop or socket: eyes triangulated shut), look again at each view with the eyes
    drawn where the first look put them, and take the eyes, irises and brows from that look
    (:mod:`faceforge.landmarks.paint`; config ``landmarks.paint_eyes``).
    Raises LandmarkError ``no face found in PATH (tried N views)`` when no view shows a face.
    """
    import time

    from faceforge.geometry.surface_points import closest_points
    from faceforge.geometry.triangles import vertex_normals
    from faceforge.landmarks.detector import Detector
    from faceforge.landmarks.views import (FACE_SHARE, SEARCH_LIFT, VIEW_SIZE, consensus_views, face_frame,
                                           find_face, sight, view_labels)

    t0 = time.perf_counter()
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    lo, hi = v.min(0), v.max(0)
    centre, diagonal = (lo + hi) / 2, float(np.linalg.norm(hi - lo))
    normals = vertex_normals(v, f)
    with Detector() as det:
        best, tried = find_face(v, f, normals, det, centre, diagonal / 2)
        if best is None:
            raise LandmarkError(f"no face found in {path} (tried {tried} views)", path)
        t_search = time.perf_counter() - t0
        search_pts, _ = _lift_view(best, v, f, diagonal, SEARCH_LIFT * best.render.view.size)
        left, up, forward = face_frame(search_pts)
        local = (search_pts - np.nanmean(search_pts, axis=0)) @ np.array([left, up]).T
        width = float(np.nanmax(np.ptp(local[np.isfinite(local[:, 0])], axis=0)))
        mid = np.nanmean(search_pts, axis=0)
        labels = view_labels()
        stack, names, sights = [], [], []
        radius_px = 0.12 * FACE_SHARE * VIEW_SIZE
        for view, label in zip(consensus_views(left, up, forward, mid, width), labels):
            s = sight(v, f, normals, det, view, label)
            if s is None:
                continue
            pts, _ = _lift_view(s, v, f, diagonal, radius_px)
            stack.append(pts)
            names.append(label)
            sights.append(s)
        front_sight = next((s for s in sights if s.label == "front"), None)
        front = None if front_sight is None else front_sight.render
        painted = bool(paint_eyes and front_sight is not None
                       and not eye_open(front.depth, front_sight.points, front.view.scale)
                       and not eyes_in_mesh(_consensus(np.array(stack), diagonal)[0], v, f, front, (left, up, forward)))
        if painted:
            stack = [_second_look(s, det, v, f, diagonal, radius_px, pts) for s, pts in zip(sights, stack)]
    if not stack:
        raise LandmarkError(f"no face found in {path} (tried {tried + len(labels)} views)", path)
    agreed, spread, seen = _consensus(np.array(stack), diagonal)
    table = fdp_table()
    ids = _placeable(table, agreed, path)
    idx = np.array([table[k] for k in ids])
    pos = agreed[idx]
    on_skin = np.array([k not in PUPILS for k in ids])
    snapped, gap, _ = closest_points(pos, v, f)
    pos = np.where(on_skin[:, None], snapped, pos)
    method = ["MediaPipe point %d, median of %d views" % (table[k], int(seen[:, table[k]].sum()))
              + (", eyes drawn in" if painted and table[k] in REPAINTED else "") for k in ids]
    for i in np.flatnonzero(~on_skin & (gap > 1e-3 * diagonal)):
        method[i] += ", in the eye opening at the depth of its lids"
    det = Detection(ids, pos, np.full(len(ids), -1, np.int64), method,
                    np.clip(1.0 - spread[idx] / 0.01, 0.0, 1.0),
                    [[names[j] for j in np.flatnonzero(seen[:, table[k]])] for k in ids], spread[idx],
                    {"search": best.label, "search_score": round(best.score, 4), "views_tried": tried + len(labels),
                     "frame": {"left": left.tolist(), "up": up.tolist(), "forward": forward.tolist()},
                     "eyes_drawn": painted,
                     "timings": {"search_s": t_search}})
    plane = _mirror(det, v, diagonal)
    det.info["rule_scale"] = {"length": rule_scale(det, diagonal), "diagonal": diagonal}
    _apply_rules(det, v, f, plane, det.info["rule_scale"]["length"], front, normals)
    det = _drop(det, [k for k in RULE_ONLY if det.info["rules"].get(k) is None])
    if symmetrise and det.info["symmetry"]["symmetric"]:
        _symmetrise(det, v, f, plane)
    _choose_vertices(det, v, diagonal, plane if det.info["symmetry"]["symmetric"] else None)
    det.info["timings"]["total_s"] = time.perf_counter() - t0
    return det


def eyes_in_mesh(agreed: np.ndarray, v, f, front, frame) -> bool:
    """Whether the eye rules find all four eye corners in the mesh (boundary loops or recessed
    sockets, :func:`faceforge.landmarks.rules.eye_loops` / ``eye_openings``) from the detected
    MediaPipe points ``agreed (478, 3)`` (NaN where unseen); ``front``: the frontal render."""
    from faceforge.geometry.surface_points import closest_points
    from faceforge.landmarks import rules
    from faceforge.landmarks.brows import EYE_CORNERS

    table = fdp_table()
    keys = [k for k in ("3.5", "3.6", "3.7", "3.8", "3.11", "3.12") if np.isfinite(agreed[table[k]]).all()]
    if not keys:
        return False
    pts = agreed[[table[k] for k in keys]]
    on_skin = np.array([k not in PUPILS for k in keys])
    pts[on_skin] = closest_points(pts[on_skin], v, f)[0]
    pos = dict(zip(keys, pts))
    found = set(rules.eye_openings(front, v, f, pos)) | set(rules.eye_loops(v, f, pos, frame))
    return all(k in found for k in EYE_CORNERS)


def _second_look(s, detector, v, f, diagonal, radius_px, first):
    """(478, 3) lifted points of sighting ``s`` looked at again with the eyes drawn where it put
    them (:func:`faceforge.landmarks.paint.paint_eyes`): the points of
    :data:`~faceforge.landmarks.paint.REPAINTED` from the second look, the rest the first's
    (``first (478, 3)``, also the answer when the second look finds no face)."""
    from faceforge.landmarks.paint import paint_eyes
    from faceforge.landmarks.views import Sighting

    face = detector.detect(paint_eyes(s.render.image, s.points))
    if face is None:
        return first
    points = s.points.copy()
    points[REPAINTED] = face.points[REPAINTED]
    return _lift_view(Sighting(s.render, points, s.score, s.label), v, f, diagonal, radius_px)[0]


def _drop(det: Detection, ids) -> Detection:
    """``det`` without the FDPs ``ids``."""
    keep = [i for i, k in enumerate(det.ids) if k not in ids]
    return Detection(tuple(det.ids[i] for i in keep), det.positions[keep], det.vertex[keep],
                     [det.method[i] for i in keep], det.confidence[keep], [det.views[i] for i in keep],
                     det.spread[keep], det.info)


def _placeable(table: dict, agreed: np.ndarray, path: str) -> tuple:
    """The FDPs whose point landed on the mesh in some view; raises LandmarkError naming the
    required FDPs (:data:`faceforge.io.landmarks.REQUIRED_FDPS`) that did not."""
    from faceforge.io.landmarks import REQUIRED_FDPS

    ok = tuple(k for k in table if np.isfinite(agreed[table[k]]).all())
    lost = [k for k in REQUIRED_FDPS if k not in ok]
    if lost:
        raise LandmarkError(f"a face was found but FDP {', '.join(lost)} could not be placed on the mesh "
                            "(its point falls off the mesh in every view)", path)
    return ok


def _mirror(det: Detection, v, diagonal):
    """The mesh's mirror plane started from the detected pairs (recorded in ``det.info``)."""
    from faceforge.mpeg4.tables import LEFT_RIGHT_PAIRS
    from faceforge.landmarks.symmetry import mirror_plane, symmetric

    at = {k: i for i, k in enumerate(det.ids)}
    pairs = [(at[a], at[b]) for a, b in LEFT_RIGHT_PAIRS if a in at and b in at]
    plane = mirror_plane(v, det.positions[[a for a, _ in pairs]], det.positions[[b for _, b in pairs]], diagonal)
    det.info["symmetry"] = {"mirror_error": round(plane.error, 6), "symmetric": symmetric(plane),
                            "normal": plane.mirror.normal.tolist(),
                            "offset": float(plane.mirror.point @ plane.mirror.normal)}
    return plane


def rule_scale(det: Detection, diagonal: float) -> float:
    """The length the rules measure in (mesh units): ``max(diagonal, RULE_SCALE_EYE_SPANS x the
    detected outer eye corners' distance)``; the diagonal alone where a corner is missing."""
    at = {k: i for i, k in enumerate(det.ids)}
    if "3.7" not in at or "3.12" not in at:
        return diagonal
    span = float(np.linalg.norm(det.positions[at["3.7"]] - det.positions[at["3.12"]]))
    return max(diagonal, RULE_SCALE_EYE_SPANS * span)


def _apply_rules(det: Detection, v, f, plane, diagonal, front=None, normals=None) -> None:
    """Move the points the geometric rules of :mod:`faceforge.landmarks.rules` place
    (``front``: the frontal view's render, which serves as the cheeks' ray cast; ``normals``:
    the mesh's vertex normals (n, 3), computed if not given; ``diagonal``: the face scale of
    :func:`rule_scale` the rules' lengths are fractions of)."""
    from faceforge.geometry.rays import RayCaster
    from faceforge.landmarks import rules

    fr = det.info["frame"]
    frame = tuple(np.asarray(fr[k]) for k in ("left", "up", "forward"))
    at = {k: i for i, k in enumerate(det.ids)}

    def pos():
        return {k: det.positions[i] for k, i in at.items()}

    if det.info["symmetry"]["symmetric"]:
        origin, normal = plane.mirror.point, plane.mirror.normal
    else:
        mids = [at[k] for k in MIDLINE_FDPS if k in at]
        origin, normal = det.positions[mids].mean(axis=0), frame[0]
    loops = rules.eye_loops(v, f, pos(), frame)
    sockets = {} if front is None else rules.eye_openings(front, v, f, pos())
    caster = RayCaster(v, f) if front is None else (front, v, f)   # the cheeks' and brows' ray cast
    moved = {}

    def place(name, found):
        """Move each FDP of ``found`` (FDP -> position) there, saying which rule did."""
        for k, p in found.items():
            if k in at:
                det.positions[at[k]] = p
                det.method[at[k]] = f"rule: {name} (MediaPipe point {fdp_table()[k]} was the start)"
                moved[k] = name

    # the opening seen from the front first: a hole's boundary loop is where the lid's skin ends,
    # behind and beyond the visible lid margin the FDPs name (ICT: upper lid 3.1 0.86 % of the
    # diagonal from its hand point by the loop, 0.07 % by the recess); the loop where no recess is seen
    # the subnasale first: the cheeks' construction measures from it
    place("midline profile (subnasale, upper lip)", rules.subnasale(v, f, pos(), frame, origin, normal, diagonal, normals))
    place("jaw angle (behind the detector's jaw contour, on the side of the head; approximate)",
          rules.jaw_angles(v, f, pos(), frame, diagonal))
    for name, found in (("eye opening (recess in the frontal render)", sockets),
                        ("eye opening (boundary loop)", {k: p for k, p in loops.items() if k not in sockets}),
                        ("midline profile", rules.chin(v, f, pos(), frame, origin, normal, diagonal, normals))):
        place(name, found)
    # after the eye rules, and only where they placed all four eye corners from the mesh: the
    # brows' height is measured from those corners (featureless eyes, e.g. the MediaPipe mask's
    # triangulated-shut ones, leave the corners the detector's guess, as biased as its brows)
    from faceforge.landmarks.brows import EYE_CORNERS, brows
    if all(k in moved for k in EYE_CORNERS):
        place("eyebrow height, the outer brows' side position (MediaPipe's canonical face over the eye corners)",
              brows(caster, pos(), frame, diagonal))
        # the nose base under the same condition: its bias is in eye spans, and on the mask (featureless
        # eyes) the bias was measured on that very mesh, so the correction would only reproduce it
        from faceforge.landmarks.nose import nose_base
        place("the nose's lower edge (the detector's point less its bias on MediaPipe's canonical face)",
              nose_base(caster, pos(), frame, diagonal))
    from faceforge.geometry.triangles import vertex_normals
    from faceforge.landmarks.lips import inner_corners, inner_lips
    normals = vertex_normals(v, f) if normals is None else normals
    for name, found in (("inner lip edge (walked from the outer lip point on its own lip)",
                         inner_lips(v, f, normals, pos(), frame)),
                        ("inner lip corner (the slit's end wall)", inner_corners(v, normals, pos(), frame))):
        place(name, {k: v[i] for k, i in found.items()})
    # the outer corners from the inner ones, where those came from the mesh's slit (on the mask, whose
    # mesh is the canonical face, the offset is its own: not an independent check there)
    from faceforge.landmarks.lips import outer_corners
    if all(k in moved for k in ("2.4", "2.5")):
        place("outer lip corner (the inner corner plus MediaPipe's canonical offset)",
              outer_corners(caster, pos(), frame, diagonal))
    # the cheeks' construction measures from the subnasale, the outer lip corners and the detector's
    # alae: built from the alae rule's instead, MakeHuman's 5.3 went 0.22 -> 0.24 % and its joy after
    # calibration folded 55 skin edges at the outer eye corners instead of 24 (the calibration of
    # the cheek rows moves with 5.3/5.4; the alae themselves change nothing downstream there)
    place("cheek construction", rules.cheeks(caster, pos(), frame, diagonal))
    from faceforge.landmarks.nose import alae
    place("alare (the nose wing's lateral edge, where the skin faces sideways)",
          {k: v[i] for k, i in alae(v, f, normals, pos(), frame, diagonal).items()})
    det.info["rules"] = moved


def _symmetrise(det: Detection, v, f, plane) -> None:
    """Make pairs mirror images and midline points lie on the mirror plane (a symmetric mesh)."""
    from faceforge.geometry.surface_points import closest_points
    from faceforge.mpeg4.tables import LEFT_RIGHT_PAIRS

    at = {k: i for i, k in enumerate(det.ids)}
    pairs = [(at[a], at[b]) for a, b in LEFT_RIGHT_PAIRS if a in at and b in at]
    p = det.positions
    for a, b in pairs:
        mean_left = (p[a] + plane.mirror(p[b])) / 2
        p[a], p[b] = mean_left, plane.mirror(mean_left)
    mids = [at[k] for k in MIDLINE_FDPS if k in at]
    p[mids] = plane.mirror.onto_plane(p[mids])
    skin = np.array([k not in PUPILS for k in det.ids])
    snapped, _, _ = closest_points(p[skin], v, f)
    p[skin] = snapped
    for a, b in pairs:   # mirror the snapped left point again, so the pair stays exact
        if skin[a]:
            p[b] = plane.mirror(p[a])
    for i in list(mids) + [i for pr in pairs for i in pr]:
        det.method[i] += ", symmetrised"


def _choose_vertices(det: Detection, v, diagonal, plane=None) -> None:
    """A vertex id for each point with a vertex within :data:`VERTEX_SNAP` (mirror vertices for
    the pairs of a symmetric mesh); the position then is that vertex's."""
    from scipy.spatial import cKDTree

    from faceforge.mpeg4.tables import LEFT_RIGHT_PAIRS

    dist, nearest = cKDTree(v).query(det.positions)
    at = {k: i for i, k in enumerate(det.ids)}
    for i, k in enumerate(det.ids):
        if k in PUPILS and "eye opening" in det.method[i]:
            continue
        if dist[i] <= VERTEX_SNAP * diagonal:
            det.vertex[i] = nearest[i]
    if plane is not None:
        for a, b in LEFT_RIGHT_PAIRS:
            if a in at and b in at and det.vertex[at[a]] >= 0:
                det.vertex[at[b]] = plane.partner[det.vertex[at[a]]]
    has = det.vertex >= 0
    det.positions[has] = v[det.vertex[has]]
