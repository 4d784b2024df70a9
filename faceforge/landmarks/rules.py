"""Geometric rules that place FDPs where the mesh itself defines them better than a face
detector trained on photos (which sees neither bone nor a grey mesh's chin shadow).

All work in the face's frame (left, up, forward unit (3,)) from the detection:

* chin, on the midline profile (the mesh cut by the mid-sagittal plane):
  2.10 pogonion = the most anterior profile point between the labiomental fold (the most
  posterior forward-facing point between the lower lip 8.2 and the chin) and the detected
  menton;
  2.1 menton = below the pogonion, the first profile point whose surface normal points
  :data:`MENTON_NORMAL_DEG` below the forward direction (the convention of the sample heads'
  hand files).
* jaw angles 2.13/2.14: :func:`jaw_angles`.
* subnasale 9.15, on the midline profile: going down from the nose tip 9.3, past the columella
  (whose normal faces down, the steepest profile point), the first place where the normal has
  turned back to :data:`SUBNASALE_NORMAL_DEG` below forward: where the columella meets the upper
  lip. The detector puts it 0.3-1.1 % of the diagonal too high, on the columella, which makes
  the FAP units MNS (9.15 - 2.2) 7-23 % too large and ENS 3-9 % too small.
  Below it, 8.1: where the philtrum's normal, tilted up, turns back through
  :data:`LABRALE_NORMAL_DEG` (the vermilion border; the detector's is 0.2-0.4 % low).
* cheeks (the MPEG-4 standard gives no construction; the rule of the sample heads' files):
  5.1/5.2 below the outer eye corner, at the height midway between the subnasale 9.15 and
  the outer lip corner; 5.3/5.4 below the outer eye corner, 45 % of the way down to the alare
  9.1/9.2; each put on the skin by a ray along -forward.
* eyes whose opening is a recess in the frontal render (a closed socket behind the lids):
  :func:`eye_openings`;
* eyes that are holes in the mesh (an open boundary loop around the detected eye): the
  corners 3.7/3.11 (3.12/3.8) are the loop's extremes along the left axis, the lid centres
  3.1/3.3 (3.2/3.4) its top and bottom vertices nearest the pupil's vertical, the pupil
  3.5 (3.6) the loop's centre at the depth of those lids.

Each rule returns new positions only where its construction succeeds; the caller keeps
the detected point otherwise and records which rule moved which point.
"""

from __future__ import annotations

import numpy as np

MENTON_NORMAL_DEG = 50.0
#: the subnasale 9.15: where, below the columella, the profile normal has turned up to this angle
#: below forward (the hand files' convention: MakeHuman ~20, ICT 23, the young female ~20 degrees)
SUBNASALE_NORMAL_DEG = 22.0
#: ... only where the profile resolves that corner: the two profile points around the crossing lie
#: within this fraction of the diagonal (MakeHuman 0.57 %, ICT 0.15 %). The 478-vertex MediaPipe mask's
#: 0.88 %: there the rule's point (1.0 % from the hand point, the detector's 2.2 %) made the mask's
#: fit fail its checks (brow muscles poking 1.5 % out at the glabella), so the detector's is kept
PROFILE_RESOLUTION = 0.0075
#: the upper lip's midpoint 8.1 (labrale superius): below the subnasale the philtrum's normal tilts
#: up; where it turns back through this angle (15 degrees above forward) the lip turns forward at
#: its vermilion border (MakeHuman's and ICT's hand points: -15 and -18 degrees)
LABRALE_NORMAL_DEG = -15.0
#: the jaw angles 2.13/2.14: how far behind the detector's jaw contour point (MediaPipe 397/172), in
#: pupil distances (ES0); set from the MakeHuman and ICT hand files (0.33, 0.39), whose gonions are
#: themselves a construction ("approx"); the young female MakeHuman's is 0.24
GONION_BACK_ES = 0.36
#: an eye boundary loop must lie this close to the detected pupil (fraction of the eye width)
EYE_LOOP_REACH = 0.6


def plane_cut(vertices, faces, origin, normal) -> tuple[np.ndarray, np.ndarray]:
    """The triangles of ``(vertices (n, 3), faces (m, 3))`` the plane (``origin (3,)``, unit
    ``normal (3,)``) cuts: ``(midpoints (k, 3) of the cut segments, triangle ids (k,))``. A
    vertex on the plane counts as on its positive side, so an edge lying in the plane belongs
    to the triangle on the negative side, and a triangle touching the plane at one vertex
    only (a segment of length 0) is left out."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    d = ((v - np.asarray(origin)) @ np.asarray(normal))[f]            # (m, 3) signed distances
    neg = d < 0
    cut = np.flatnonzero(neg.any(axis=1) & ~neg.all(axis=1))
    ends = []
    for a, b in ((0, 1), (1, 2), (2, 0)):       # a cut triangle has exactly two edges whose sides differ
        da, db = d[cut, a], d[cut, b]
        cross = neg[cut, a] != neg[cut, b]
        t = np.where(cross, da / np.where(cross, da - db, 1.0), np.nan)
        ends.append(v[f[cut, a]] + t[:, None] * (v[f[cut, b]] - v[f[cut, a]]))
    ends = np.stack(ends, axis=1)                                      # (k, 3 edges, 3), NaN: not crossed
    two = ends[np.isfinite(ends[:, :, 0])].reshape(len(cut), 2, 3)
    keep = np.linalg.norm(two[:, 0] - two[:, 1], axis=1) > 0
    return two[keep].mean(axis=1), cut[keep]


def midline_profile(vertices, faces, origin, normal, vertex_normals_=None):
    """Points and in-plane unit normals of the mesh cut by the plane (``origin``, ``normal``):
    ``(points (k, 3), normals (k, 3))``, one per cut triangle (segment midpoints; the normals
    interpolated from the vertex normals, ``vertex_normals_ (n, 3)`` if given, else computed)."""
    from faceforge.geometry.triangles import barycentric, vertex_normals

    pts, fids = plane_cut(vertices, faces, origin, normal)
    if len(pts) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3))
    bary = barycentric(pts, vertices, faces, fids)          # smooth normals: a low-poly chin still turns gradually
    vn = vertex_normals(vertices, faces) if vertex_normals_ is None else vertex_normals_
    n = np.einsum("kj,kjd->kd", bary, vn[faces[fids]])
    n = n - np.outer(n @ normal, normal)
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    return pts, n


def _crossing(pts, angle, order, level):
    """The lowest place along ``order`` (profile indices, top to bottom) where ``angle`` rises
    through ``level`` (linear between the two profile points), or None."""
    a = angle[order] - level
    ups = np.flatnonzero((a[:-1] <= 0) & (a[1:] > 0))
    if len(ups) == 0:
        return None
    j = ups[-1]
    t = -a[j] / (a[j + 1] - a[j])
    return pts[order[j]] * (1 - t) + pts[order[j + 1]] * t


def chin(vertices, faces, pos: dict, frame, plane_point, plane_normal, diagonal, normals=None) -> dict:
    """{"2.10": (3,), "2.1": (3,)} from the midline profile (module docstring); {} if it fails.

    Along the profile from the lower lip down, the surface normal tilts up most in the
    labiomental fold; below it the most anterior profile point is the pogonion, and the
    normal then turns down through :data:`MENTON_NORMAL_DEG` at the menton.
    """
    left, up, fwd = frame
    if not all(k in pos for k in ("2.1", "8.2")):
        return {}
    pts, nrm = midline_profile(vertices, faces, plane_point, plane_normal, normals)
    if len(pts) == 0:
        return {}
    u, w = pts @ up, pts @ fwd
    u_lip, u_men = pos["8.2"] @ up, pos["2.1"] @ up
    front = w > min(pos["2.1"] @ fwd, pos["8.2"] @ fwd) - 0.06 * diagonal
    band = front & (nrm @ fwd > 0.2) & (u <= u_lip) & (u >= u_men - 0.03 * diagonal)
    order = np.flatnonzero(band)
    order = order[np.argsort(-u[order])]
    if len(order) < 4:
        return {}
    angle = np.degrees(np.arctan2(-(nrm @ up), nrm @ fwd))        # degrees below forward
    upper = order[u[order] >= u_men + 0.25 * (u_lip - u_men)]
    if len(upper) == 0:
        return {}
    fold = upper[np.argmin(angle[upper])]                         # the most back-tilted tangent
    chin_pts = order[u[order] < u[fold]]
    if len(chin_pts) == 0:
        return {}
    pog = pts[chin_pts[np.argmax(w[chin_pts])]]
    out = {"2.10": pog}
    low = order[u[order] < pog @ up]
    if len(low) >= 2:
        men = _crossing(pts, angle, np.concatenate([order[u[order] >= pog @ up][-1:], low]), MENTON_NORMAL_DEG)
        if men is not None:
            out["2.1"] = men
    return out


def subnasale(vertices, faces, pos: dict, frame, plane_point, plane_normal, diagonal, normals=None) -> dict:
    """{"9.15": (3,), "8.1": (3,)} from the midline profile (module docstring); {} or only 9.15
    where the construction fails."""
    left, up, fwd = frame
    if not all(k in pos for k in ("9.3", "8.1", "2.2")):
        return {}
    pts, nrm = midline_profile(vertices, faces, plane_point, plane_normal, normals)
    if len(pts) == 0:
        return {}
    u, w = pts @ up, pts @ fwd
    # the outer surface between the nose tip and the mouth (not the nostrils' or mouth's inside)
    low = min(pos["2.2"] @ up, pos["8.1"] @ up)
    band = (u < pos["9.3"] @ up) & (u > low) & (nrm @ fwd > 0) & (w > pos["8.1"] @ fwd - 0.03 * diagonal)
    order = np.flatnonzero(band)
    order = order[np.argsort(-u[order])]
    if len(order) < 3:
        return {}
    angle = np.degrees(np.arctan2(-(nrm @ up), nrm @ fwd))[order]        # degrees below forward
    top = int(np.argmax(angle[u[order] > pos["8.1"] @ up]))             # the columella
    j = _falls_through(angle, top, SUBNASALE_NORMAL_DEG)
    if j is None:
        return {}
    if np.linalg.norm(pts[order[j]] - pts[order[j - 1]]) > PROFILE_RESOLUTION * diagonal:
        return {}                                               # too coarse to tell where the corner is
    out = {"9.15": _between(pts, order, angle, j, SUBNASALE_NORMAL_DEG)}
    tilted = _falls_through(angle, j, LABRALE_NORMAL_DEG)               # the philtrum tilting up
    if tilted is not None:
        back = np.flatnonzero(angle[tilted:] >= LABRALE_NORMAL_DEG)     # ... and the lip turning forward
        if len(back):
            out["8.1"] = _between(pts, order, angle, tilted + int(back[0]), LABRALE_NORMAL_DEG)
    return out


def _falls_through(angle, start: int, level: float) -> int | None:
    """The first index after ``start`` whose angle is below ``level`` (angle[start] above it)."""
    if angle[start] <= level:
        return None
    below = np.flatnonzero(angle[start:] < level)
    return None if len(below) == 0 else start + int(below[0])


def _between(pts, order, angle, j: int, level: float) -> np.ndarray:
    """The profile point between ``order[j - 1]`` and ``order[j]`` where the angle is ``level``."""
    t = (angle[j - 1] - level) / (angle[j - 1] - angle[j])
    return pts[order[j - 1]] * (1 - t) + pts[order[j]] * t


def jaw_angles(vertices, faces, pos: dict, frame, diagonal) -> dict:
    """{"2.13": (3,), "2.14": (3,)}: the soft-tissue gonions (module docstring); {} where it fails.

    The detector's jaw points (397/172) lie on the face's contour as a photo shows it, on the
    jaw's lower border 4-5 % of the diagonal in front of the angle; each is moved back
    :data:`GONION_BACK_ES` pupil distances and put on the side of the head by a ray from outside
    along the left axis.
    Without these two the fit's jaw angle is free and the masseter pokes out of the cheek
    (MakeHuman: 1.2 % of the diagonal, the fit's check fails).
    """
    left, up, fwd = frame
    if not all(k in pos for k in ("2.13", "2.14", "3.5", "3.6")):
        return {}
    es = float(np.linalg.norm(pos["3.5"] - pos["3.6"]))
    out = {}
    for k, side in (("2.13", 1.0), ("2.14", -1.0)):
        target = pos[k] - fwd * GONION_BACK_ES * es
        # only the triangles that come near the ray (a caster over the whole mesh costs 0.8 s on 45k vertices)
        near = np.abs((vertices - target) @ np.array([up, fwd]).T).max(axis=1) < 0.02 * diagonal
        tri = faces[near[faces].any(axis=1)]
        if len(tri) == 0:
            continue
        hit = first_hit(vertices[tri], target + side * left * 0.5 * diagonal, -side * left)
        if hit is not None:
            out[k] = hit
    return out


def first_hit(triangles: np.ndarray, origin: np.ndarray, direction: np.ndarray) -> np.ndarray | None:
    """The nearest point (3,) where the ray ``origin (3,) + t direction (3,)``, t >= 0, meets one of
    ``triangles (m, 3, 3)`` (Moller-Trumbore, both faces, edges inclusive), or None.

    For a few hundred triangles near a ray; numpy alone (the mesh-wide caster imports trimesh,
    0.6 s of a fresh process's 3 s).
    """
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    e1, e2 = b - a, c - a
    p = np.cross(direction, e2)
    det = np.einsum("ij,ij->i", e1, p)
    ok = np.abs(det) > 1e-12 * np.maximum(np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1), 1e-300)
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = origin - a
    u = np.einsum("ij,ij->i", s, p) * inv
    q = np.cross(s, e1)
    w = (q @ direction) * inv
    t = np.einsum("ij,ij->i", e2, q) * inv
    hit = ok & (u >= 0) & (w >= 0) & (u + w <= 1) & (t >= 0)
    if not hit.any():
        return None
    i = np.flatnonzero(hit)[np.argmin(t[hit])]
    return origin + t[i] * direction


def _onto_skin(caster, points, fwd, diagonal):
    """(k, 3) points moved onto the skin along -forward (from in front); NaN where missed.
    ``caster``: a :class:`faceforge.geometry.rays.RayCaster`, or the frontal render (its
    buffers are that ray cast, to a pixel)."""
    from faceforge.landmarks.raster import Render, surface_at

    if isinstance(caster, tuple) and isinstance(caster[0], Render):
        render_, vertices, faces = caster
        px = render_.view.project(points)
        n = render_.depth.shape[0]
        rows = np.clip(np.floor(px[:, 1]).astype(np.int64), 0, n - 1)
        cols = np.clip(np.floor(px[:, 0]).astype(np.int64), 0, n - 1)
        return surface_at(render_, faces, vertices, rows, cols)
    origins = points + fwd * 0.3 * diagonal
    fid, hit, _ = caster.first_hit(origins, np.repeat(-fwd[None], len(points), axis=0), 0.6 * diagonal)
    hit = np.asarray(hit, dtype=np.float64)
    hit[np.asarray(fid) < 0] = np.nan
    return hit


def cheeks(caster, pos: dict, frame, diagonal) -> dict:
    """{"5.1".."5.4": (3,)} by the sample heads' construction rules (module docstring)."""
    left, up, fwd = frame
    out = {}
    sides = (("5.1", "5.3", "3.7", "8.3", "9.1"), ("5.2", "5.4", "3.12", "8.4", "9.2"))
    for cheek, bone, eye, lip, ala in sides:
        if not all(k in pos for k in (eye, lip, ala, "9.15")):
            continue
        e = pos[eye]
        h_cheek = 0.5 * (pos["9.15"] @ up + pos[lip] @ up)
        h_bone = e @ up + 0.45 * (pos[ala] @ up - e @ up)
        targets = np.array([e + up * (h_cheek - e @ up), e + up * (h_bone - e @ up)])
        hits = _onto_skin(caster, targets, fwd, diagonal)
        for k, p in zip((cheek, bone), hits):
            if np.isfinite(p).all():
                out[k] = p
    return out


def _loops_near(vertices, faces, centres: np.ndarray, reach: float) -> list:
    """Open boundary loops (vertex-id arrays) of the mesh with every vertex within ``reach``
    of one of ``centres (k, 3)``: the boundary edges (used by one triangle, found on 1D
    integer keys: fast on big meshes) near the eyes, chained."""
    from scipy.spatial import cKDTree

    f = np.asarray(faces, dtype=np.int64)
    e = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    n = int(f.max()) + 1
    keys, counts = np.unique(e[:, 0] * n + e[:, 1], return_counts=True)
    edges = np.column_stack([keys[counts == 1] // n, keys[counts == 1] % n])
    if len(edges) == 0 or reach <= 0:
        return []
    dist, _ = cKDTree(centres).query(vertices[edges.ravel()])
    edges = edges[(dist.reshape(-1, 2) <= reach).all(axis=1)]
    nbr: dict = {}
    for a, b in edges.tolist():
        nbr.setdefault(a, []).append(b)
        nbr.setdefault(b, []).append(a)
    loops, seen = [], set()
    for start in nbr:
        if start in seen or len(nbr[start]) != 2:
            continue
        loop, prev, cur = [start], None, start
        seen.add(start)
        while True:
            nxt = [c for c in nbr[cur] if c != prev]
            if not nxt or len(nbr[cur]) != 2:
                loop = None
                break
            prev, cur = cur, nxt[0]
            if cur == start:
                break
            if cur in seen:
                loop = None
                break
            seen.add(cur)
            loop.append(cur)
        if loop is not None and len(loop) >= 6:
            loops.append(np.asarray(loop, dtype=np.int64))
    return loops


def eye_loops(vertices, faces, pos: dict, frame) -> dict:
    """Corners and lid centres from open boundary loops around the eyes (module docstring)."""
    left, up, fwd = frame
    eyes = [pos[k] for k in ("3.5", "3.6", "3.7", "3.12") if k in pos]
    if len(eyes) < 2:
        return {}
    reach = 1.5 * max(np.linalg.norm(pos["3.7"] - pos["3.11"]), np.linalg.norm(pos["3.12"] - pos["3.8"])) \
        if all(k in pos for k in ("3.7", "3.11", "3.12", "3.8")) else 0.0
    loops = _loops_near(vertices, faces, np.array(eyes), reach)
    if not loops:
        return {}
    out = {}
    for outer, inner, upper, lower, pupil in (("3.7", "3.11", "3.1", "3.3", "3.5"), ("3.12", "3.8", "3.2", "3.4", "3.6")):
        if not all(k in pos for k in (outer, inner, pupil)):
            continue
        width = np.linalg.norm(pos[outer] - pos[inner])
        centre = pos[pupil]
        best = None
        for lp in loops:
            p = vertices[lp]
            span = np.ptp(p @ left)
            d = np.linalg.norm(p.mean(axis=0) - centre)
            if d < EYE_LOOP_REACH * width and 0.6 * width < span < 1.5 * width:
                if best is None or d < best[0]:
                    best = (d, p)
        if best is None:
            continue
        p = best[1]
        x = p @ left
        sign = 1.0 if pos[outer] @ left > pos[inner] @ left else -1.0
        out[outer] = p[np.argmax(sign * x)]
        out[inner] = p[np.argmin(sign * x)]
        near = np.abs(x - centre @ left) < 0.15 * width
        if near.sum() >= 2:
            q = p[near]
            out[upper] = q[np.argmax(q @ up)]
            out[lower] = q[np.argmin(q @ up)]
            c = p.mean(axis=0)      # the opening's centre, at the depth of its lids
            out[pupil] = c + fwd * (0.5 * (out[upper] + out[lower]) @ fwd - c @ fwd)
    return out


#: a pixel recessed this much (fraction of the eye's width) behind the skin bridged over it
#: belongs to the eye opening (a socket behind the lids, or a hole)
RECESS = 0.1


def _recess(depth: np.ndarray, size: int) -> np.ndarray:
    """How far each pixel of ``depth (h, w)`` lies behind the skin bridged over it: a grey
    closing of the height (-depth) with a ``size`` square fills pits narrower than ``size``
    and leaves slopes (the nose's flank) as they are; background counts as deepest."""
    from scipy import ndimage

    finite = np.isfinite(depth)
    far = np.max(depth[finite]) if finite.any() else 0.0
    height = -np.where(finite, depth, far)
    return ndimage.grey_closing(height, size=(size, size)) - height


def _opening_ends(comp: np.ndarray, pupil_col: int, step: int, narrowest: bool) -> int | None:
    """Column where the opening ``comp (h, w) bool`` ends walking from ``pupil_col`` by
    ``step`` (+1/-1): where it stops or, with ``narrowest``, at its narrowest column once it
    widens again (toward the nose the opening runs into the hollow beside it: the inner
    canthus is the waist between the two)."""
    extent = comp.sum(axis=0)
    best, last = None, None
    for c in range(pupil_col, comp.shape[1] if step > 0 else -1, step):
        if extent[c] == 0:
            break
        last = c
        if best is None or extent[c] <= extent[best]:
            best = c
        elif narrowest and extent[c] > extent[best] + max(2, 0.3 * extent[best]):
            return best
    return last


def eye_openings(render_, vertices, faces, pos: dict) -> dict:
    """Corners, lid centres and pupil of eyes whose opening is a recess in the frontal render
    (a closed socket behind the lids): the opening is the connected region of pixels
    recessed :data:`RECESS` of the eye's width behind the skin bridged over it
    (:func:`_recess`), around the detected pupil; its ends along the picture's width are the
    corners (the inner one at the narrowest column before the nose's hollow), its top and
    bottom at the pupil's column the lid centres, each taken at the nearest pixel of skin
    (the lid margin, not the socket behind it); its centre at the lids' depth is the pupil.
    An opening that is not eye-sized is ignored."""
    from scipy import ndimage

    from faceforge.landmarks.raster import surface_at

    view = render_.view
    n = render_.depth.shape[0]
    out = {}
    for outer, inner, upper, lower, pupil in (("3.7", "3.11", "3.1", "3.3", "3.5"), ("3.12", "3.8", "3.2", "3.4", "3.6")):
        if not all(k in pos for k in (outer, inner, pupil)):
            continue
        px = view.project(np.array([pos[outer], pos[inner], pos[pupil]]))[:, :2]
        width = float(np.linalg.norm(px[0] - px[1]))
        if width < 12:
            continue
        c = px[2]
        c0, c1 = int(max(c[0] - 0.9 * width, 0)), int(min(c[0] + 0.9 * width, n))
        r0, r1 = int(max(c[1] - 0.5 * width, 0)), int(min(c[1] + 0.5 * width, n))
        win = render_.depth[r0:r1, c0:c1]
        mask = _recess(win, max(3, int(0.6 * width) | 1)) > RECESS * width / view.scale
        labels, _ = ndimage.label(mask)
        near = np.argwhere(labels > 0)
        if len(near) == 0:
            continue
        pr, pc = int(c[1]) - r0, int(c[0]) - c0
        d = np.hypot(near[:, 0] - pr, near[:, 1] - pc)
        if d.min() > 0.2 * width:
            continue
        comp = labels == labels[tuple(near[np.argmin(d)])]
        col = int(np.clip(pc, 0, comp.shape[1] - 1))
        if not comp[:, col].any():
            continue
        sign = 1 if px[0, 0] > px[1, 0] else -1          # the outer corner's side in the picture
        end_out, end_in = _opening_ends(comp, col, sign, False), _opening_ends(comp, col, -sign, True)
        if end_out is None or end_in is None or not 0.6 * width < abs(end_out - end_in) < 1.4 * width:
            continue
        rows = np.flatnonzero(comp[:, col])
        if rows.max() - rows.min() > 0.8 * width:
            continue
        picks = {outer: (np.flatnonzero(comp[:, end_out]).mean(), end_out),
                 inner: (np.flatnonzero(comp[:, end_in]).mean(), end_in),
                 upper: (rows.min(), col), lower: (rows.max(), col)}
        rim = np.argwhere(~mask & np.isfinite(win))       # the skin around: the lid margins
        if len(rim) == 0:
            continue
        rr, cc = [], []
        for r_, c_ in picks.values():     # each on the nearest skin pixel, not in the recess
            j = int(np.argmin(np.hypot(rim[:, 0] - r_, rim[:, 1] - c_)))
            rr.append(rim[j, 0] + r0)
            cc.append(rim[j, 1] + c0)
        pts = surface_at(render_, faces, vertices, np.array(rr), np.array(cc))
        found = {k: p for k, p in zip(picks, pts) if np.isfinite(p).all()}
        if len(found) < 4:
            continue
        out.update(found)
        lo, hi = sorted((end_in, end_out))
        part = comp.copy()
        part[:, :lo] = False
        part[:, hi + 1:] = False
        ys, xs = np.nonzero(part)
        lids_depth = np.mean(view.project(np.array([found[upper], found[lower]]))[:, 2])
        out[pupil] = view.unproject(np.array([[xs.mean() + c0 + 0.5, ys.mean() + r0 + 0.5]]),
                                    np.array([lids_depth]))[0]
    return out
