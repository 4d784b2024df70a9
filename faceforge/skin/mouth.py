"""The lip line: find it from the FDPs and cut it so the lips can part (§8).

Input heads join their lips in three ways, detected from the topology alone:

``"open"``
    The inner upper and inner lower lip contours are different vertex paths and
    no triangle joins them between the corners (ICT: a mouth boundary behind
    touching lips; MakeHuman: a slit folding into a closed mouth cavity). Nothing
    is changed.
``"bridged"``
    The contours are different paths but triangles span the gap between them
    (MediaPipe). Those triangles are deleted; the vertex array is unchanged.
``"shared_ring"``
    The upper and lower lips share one edge ring (a lower-lip FDP lies on the
    upper contour). The ring's interior vertices (corners excluded) are
    duplicated: the copies are appended after the user's vertices and the
    triangles on the lower-lip side are rewired to them, which opens a slit
    whose two borders run along the lip line.

The contours are the shortest edge paths (Dijkstra, edge length) through the
inner-lip FDPs ``2.4 -> 2.6 -> 2.2 -> 2.7 -> 2.5`` (upper) and
``2.4 -> 2.8 -> 2.3 -> 2.9 -> 2.5`` (lower); the lower path avoids the upper
one's interior vertices so that the two are disjoint unless they share FDPs.

Mapping back: the working mesh's first ``n_user`` vertices are the user's, in
the user's order; appended vertex ``n_user + i`` is a copy of user vertex
``MouthCut.source[i]``. :meth:`MouthCut.to_user` keeps the first ``n_user``
rows (the upper-lip copy of each cut vertex).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from faceforge.constants import FLOAT, INT
from faceforge.geometry.triangles import edge_graph, edge_path

__all__ = ["MouthCut", "LIP_FDPS", "lip_contours", "cut_mouth", "lip_side", "side_of_points",
           "muscle_lip_side", "ring_face_sides", "AROUND_MOUTH"]

#: FDPs of the inner lip contour, corner to corner
UPPER_FDPS = ("2.4", "2.6", "2.2", "2.7", "2.5")
LOWER_FDPS = ("2.4", "2.8", "2.3", "2.9", "2.5")
LIP_FDPS = tuple(sorted(set(UPPER_FDPS + LOWER_FDPS)))


@dataclass(frozen=True)
class MouthCut:
    """The working skin mesh after the lip cut.

    Attributes
    ----------
    case : str
        ``"open"``, ``"bridged"``, ``"shared_ring"`` or ``"no_landmarks"``.
    vertices : (n_user + c, 3) float64
        User vertices, then the ``c`` duplicated lip vertices.
    faces : (m', 3) int64
        Working triangles (bridging triangles removed, lower-lip side rewired).
    n_user : int
        Number of user vertices.
    source : (c,) int64
        User vertex that appended vertex ``n_user + i`` duplicates.
    removed_faces : (r,) int64
        Indices into the input ``faces`` of the deleted bridging triangles.
    upper : (u,) int64
        Upper inner-lip contour, corner to corner (working vertex ids).
    lower : (l,) int64
        Lower inner-lip contour, corner to corner (after the cut: the copies).
    """

    case: str
    vertices: np.ndarray
    faces: np.ndarray
    n_user: int
    source: np.ndarray
    removed_faces: np.ndarray
    upper: np.ndarray
    lower: np.ndarray

    def to_user(self, positions) -> np.ndarray:
        """Positions of the user's vertices ``(n_user, 3)`` from working ones ``(n, 3)``."""
        return np.asarray(positions)[: self.n_user]

    def report(self) -> dict:
        """A JSON-ready summary for the bind report."""
        what = {
            "open": "lips already separate: nothing changed",
            "bridged": f"deleted {len(self.removed_faces)} triangles bridging the lips",
            "shared_ring": f"cut the shared lip ring: duplicated {len(self.source)} vertices "
                           "(appended after the user's; the lower lip uses the copies)",
            "no_landmarks": "inner-lip FDPs 2.2-2.5 missing: mouth not examined",
        }[self.case]
        return {
            "case": self.case,
            "action": what,
            "n_user_vertices": int(self.n_user),
            "duplicated_vertices": int(len(self.source)),
            "removed_triangles": int(len(self.removed_faces)),
            "upper_contour_vertices": int(len(self.upper)),
            "lower_contour_vertices": int(len(self.lower)),
        }


def _chain(graph, ids: list[int], banned=()) -> list[int]:
    out = [ids[0]]
    for a, b in zip(ids[:-1], ids[1:]):
        p = edge_path(graph, a, b, banned)
        if not p:
            return []
        out += p[1:]
    return out


def lip_contours(vertices, faces, lip_vertices: dict) -> tuple[np.ndarray, np.ndarray]:
    """Upper and lower inner-lip contours as vertex paths from corner 2.4 to 2.5.

    Parameters
    ----------
    vertices : (n, 3) float
    faces : (m, 3) int
    lip_vertices : dict
        FDP id -> vertex id; needs 2.2-2.5, uses 2.6-2.9 where present.

    Returns
    -------
    upper, lower : (u,) int64, (l,) int64
        Both start at 2.4 and end at 2.5. The lower path avoids the upper
        path's interior unless a lower FDP lies on it (shared ring).
    """
    v = np.asarray(vertices, FLOAT)
    f = np.asarray(faces, INT)
    g = edge_graph(v, f)
    up = [int(lip_vertices[k]) for k in UPPER_FDPS if k in lip_vertices]
    lo = [int(lip_vertices[k]) for k in LOWER_FDPS if k in lip_vertices]
    upper = _chain(g, up)
    if not upper:
        raise ValueError("no edge path joins the upper inner-lip FDPs")
    inner = set(upper[1:-1])
    if any(x in inner for x in lo[1:-1]):
        lower = _chain(g, lo)
    else:
        lower = _chain(g, lo, banned=sorted(inner)) or _chain(g, lo)
    if not lower:
        raise ValueError("no edge path joins the lower inner-lip FDPs")
    return np.asarray(upper, INT), np.asarray(lower, INT)


def _fans(center: int, star: np.ndarray, faces: np.ndarray, cut_edges: set) -> list[list[int]]:
    """Split the faces ``star`` around ``center`` into fans across non-cut edges."""
    parent = {int(t): int(t) for t in star}

    def find(x):
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    by_edge: dict[int, list[int]] = {}
    for t in star:
        for w in faces[t]:
            if w != center and (min(w, center), max(w, center)) not in cut_edges:
                by_edge.setdefault(int(w), []).append(int(t))
    for ts in by_edge.values():
        for t in ts[1:]:
            parent[find(t)] = find(ts[0])
    groups: dict[int, list[int]] = {}
    for t in star:
        groups.setdefault(find(int(t)), []).append(int(t))
    return list(groups.values())


def cut_mouth(vertices, faces, lip_vertices: dict, up=(0.0, 1.0, 0.0)) -> MouthCut:
    """Detect how the lips are joined and cut them apart (see the module text).

    Parameters
    ----------
    vertices : (n, 3) float
    faces : (m, 3) int
    lip_vertices : dict
        FDP id -> vertex id for the inner-lip FDPs (2.2-2.9); without 2.2-2.5
        the mouth is left alone (case ``"no_landmarks"``).
    up : (3,) float
        Upward direction of the face (+Y by convention), used to tell the
        lower-lip side of a shared ring.

    Returns
    -------
    MouthCut
    """
    v = np.asarray(vertices, FLOAT)
    f = np.asarray(faces, INT)
    n = len(v)
    none = np.zeros(0, INT)
    if not all(k in lip_vertices for k in ("2.2", "2.3", "2.4", "2.5")):
        return MouthCut("no_landmarks", v.copy(), f.copy(), n, none, none, none, none)
    upper, lower = lip_contours(v, f, lip_vertices)
    ui, li = set(upper[1:-1].tolist()), set(lower[1:-1].tolist())
    if ui & li:
        return _cut_ring(v, f, upper, np.asarray(up, FLOAT))
    in_u = np.isin(f, list(ui)).any(axis=1) if ui else np.zeros(len(f), bool)
    in_l = np.isin(f, list(li)).any(axis=1) if li else np.zeros(len(f), bool)
    bridge = in_u & in_l
    if not bridge.any():
        return MouthCut("open", v.copy(), f.copy(), n, none, none, upper, lower)
    return MouthCut("bridged", v.copy(), f[~bridge], n, none,
                    np.flatnonzero(bridge).astype(INT), upper, lower)


def _cut_ring(v: np.ndarray, f: np.ndarray, ring: np.ndarray, up: np.ndarray) -> MouthCut:
    """Duplicate the interior of ``ring``; lower-side fans use the copies."""
    n = len(v)
    up = up / np.linalg.norm(up)
    cut_edges = {(min(a, b), max(a, b)) for a, b in zip(ring[:-1].tolist(), ring[1:].tolist())}
    # star of every vertex: sort face slots by vertex
    slots = np.argsort(f.ravel(), kind="stable")
    starts = np.searchsorted(f.ravel()[slots], np.arange(n + 1))
    new_f = f.copy()
    source, lower = [], [int(ring[0])]
    centroid = v[f].mean(axis=1)
    for r in ring[1:-1].tolist():
        star = np.unique(slots[starts[r]:starts[r + 1]] // 3)
        fans = _fans(r, star, f, cut_edges)
        side = [float(np.mean((centroid[fan] - v[r]) @ up)) for fan in fans]
        low = [fan for fan, s in zip(fans, side) if s < 0]
        if len(fans) < 2 or not low or len(low) == len(fans):
            lower.append(r)
            continue
        copy = n + len(source)
        source.append(r)
        lower.append(copy)
        for fan in low:
            rows = np.asarray(fan)
            new_f[rows] = np.where(f[rows] == r, copy, new_f[rows])
    lower.append(int(ring[-1]))
    src = np.asarray(source, INT)
    verts = np.concatenate([v, v[src]]) if len(src) else v.copy()
    return MouthCut("shared_ring", verts, new_f, n, src, np.zeros(0, INT), ring.astype(INT),
                    np.asarray(lower, INT))


def _lip_line(cut: MouthCut) -> np.ndarray:
    """Midpoints between each contour vertex and the nearest vertex of the other contour."""
    from scipy.spatial import cKDTree

    pu, pl = cut.vertices[cut.upper], cut.vertices[cut.lower]
    return np.concatenate([0.5 * (pu + pl[cKDTree(pl).query(pu)[1]]),
                           0.5 * (pl + pu[cKDTree(pu).query(pl)[1]])])


def side_of_points(points, cut: MouthCut, up=(0.0, 1.0, 0.0), radius: float | None = None) -> np.ndarray:
    """+1 above the lip line, -1 below, 0 farther than ``radius`` from it (or no lips).

    The lip line is the chain of midpoints between each contour vertex and the
    nearest vertex of the other contour; a point is above when it lies above
    its nearest lip-line point along ``up``. ``radius`` defaults to the mouth
    width (corner to corner).

    Parameters
    ----------
    points : (k, 3) float

    Returns
    -------
    (k,) int8
    """
    p = np.asarray(points, FLOAT).reshape(-1, 3)
    out = np.zeros(len(p), np.int8)
    if len(cut.upper) < 2 or len(cut.lower) < 2 or len(p) == 0:
        return out
    from scipy.spatial import cKDTree

    u = np.asarray(up, FLOAT) / np.linalg.norm(up)
    line = _lip_line(cut)
    width = np.linalg.norm(cut.vertices[cut.upper[0]] - cut.vertices[cut.upper[-1]])
    r = width if radius is None else float(radius)
    dist, idx = cKDTree(line).query(p)
    near = dist <= r
    above = p @ u >= line[np.minimum(idx, len(line) - 1)] @ u
    out[near & above] = 1
    out[near & ~above] = -1
    return out


#: :func:`muscle_lip_side` of a muscle around the mouth (the orbicularis oris)
AROUND_MOUTH = 2


def muscle_lip_side(vertices, cut: MouthCut, up=(0.0, 1.0, 0.0), forward=(0.0, 0.0, 1.0)) -> int:
    """Which lip a muscle acts on: +1 upper, -1 lower, :data:`AROUND_MOUTH`, 0 neither.

    Of the muscle's ``vertices (k, 3)`` only those within a mouth width of the lip line
    count (none: 0, a muscle far from the mouth). A muscle whose near vertices surround the
    mouth -- seen from the front (``forward``), every 45 degree sector around the lip
    line's centre holds one -- lies around the mouth (the sphincter, however unevenly the
    fit shares it between the lips: ICT 66 vertices above the line, 14 below). Any other
    muscle acts on the lip on whose side its near vertices lie on average (signed height
    above the nearest lip-line point along ``up``): the ends of the depressors that cross
    the line into the upper lip (ICT depressor labii inferioris: 16 of 40 vertices) do not
    make them upper-lip muscles.
    """
    p = np.asarray(vertices, FLOAT).reshape(-1, 3)
    if len(cut.upper) < 2 or len(cut.lower) < 2 or len(p) == 0:
        return 0
    from scipy.spatial import cKDTree

    u = np.asarray(up, FLOAT) / np.linalg.norm(up)
    fwd = np.asarray(forward, FLOAT) / np.linalg.norm(forward)
    side = np.cross(u, fwd)
    line = _lip_line(cut)
    width = np.linalg.norm(cut.vertices[cut.upper[0]] - cut.vertices[cut.upper[-1]])
    dist, idx = cKDTree(line).query(p)
    near = dist <= width
    if not near.any():
        return 0
    q = p[near] - line.mean(axis=0)
    sector = np.floor((np.arctan2(q @ u, q @ side) + np.pi) / (np.pi / 4)).astype(INT) % 8
    if len(np.unique(sector)) == 8:
        return AROUND_MOUTH
    h = float(np.mean((p[near] - line[idx[near]]) @ u))
    return int(np.sign(h))


def ring_face_sides(vertices, faces, cut: MouthCut, up=(0.0, 1.0, 0.0)):
    """Lip side of each face of a muscle ring around the mouth, by the ring's rows rather
    than where the face lies: ``(m,) int8``, +1 the upper lip's arc, -1 the lower's (0: a face
    touching neither arc); None when the mesh is not a closed muscle grid
    (:func:`faceforge.anatomy.muscles.hexmesh.grid_layout`) or the cut has no corners.

    The two rows whose outer samples (column ``w - 1`` of the bottom sheet: the loop around
    the lips) lie nearest the mouth corners split the ring into two arcs; the arc whose outer
    samples lie higher along ``up`` is the upper lip's. A face belongs to an arc when its
    rows are that arc's or a corner row. The fit may place a sphincter well off the lip
    line (ICT: 66 of its 80 vertices above it, its lower arc under the upper lip's outer
    contour): the side of the lip line a face lies on then gives the upper lip the arc that
    the lower lip's muscles pull.
    """
    from faceforge.anatomy.muscles.hexmesh import grid_layout

    v = np.asarray(vertices, FLOAT).reshape(-1, 3)
    f = np.asarray(faces, INT).reshape(-1, 3)
    layout = grid_layout(len(v), f, closed=True)
    if layout is None or len(cut.upper) < 2:
        return None
    h, w = layout
    outer = v[np.arange(h) * w + (w - 1)]
    corners = np.asarray(cut.vertices, FLOAT)[[cut.upper[0], cut.upper[-1]]]
    c0, c1 = (int(np.argmin(np.linalg.norm(outer - c, axis=1))) for c in corners)
    if c0 == c1:
        return None
    first = np.zeros(h, bool)     # the rows strictly between the corners going forward
    first[(c0 + 1 + np.arange((c1 - c0 - 1) % h)) % h] = True
    second = ~first
    second[[c0, c1]] = False
    u = np.asarray(up, FLOAT) / np.linalg.norm(up)
    if not first.any() or not second.any():
        return None
    upper = first if (outer[first] @ u).mean() > (outer[second] @ u).mean() else second
    lower = ~upper
    lower[[c0, c1]] = False
    corner = ~(upper | lower)
    row = (f % (h * w)) // w
    out = np.zeros(len(f), np.int8)
    out[(upper | corner)[row].all(axis=1) & upper[row].any(axis=1)] = 1
    out[(lower | corner)[row].all(axis=1) & lower[row].any(axis=1)] = -1
    return out


def _surface_side(cut: MouthCut, side: np.ndarray) -> np.ndarray:
    """``side`` (n,) int8 with the lip decided by edge paths where they are decisive
    (see :func:`lip_side`); vertices with side 0 (far from the mouth) stay 0."""
    from scipy.sparse.csgraph import dijkstra

    v = np.asarray(cut.vertices, FLOAT)
    g = edge_graph(v, np.asarray(cut.faces, INT))
    corners = np.unique([cut.upper[0], cut.upper[-1], cut.lower[0], cut.lower[-1]])
    d_up = dijkstra(g, indices=np.asarray(cut.upper[1:-1], INT), min_only=True)
    d_low = dijkstra(g, indices=np.asarray(cut.lower[1:-1], INT), min_only=True)
    d_corner = dijkstra(g, indices=corners, min_only=True)
    near = side != 0
    out = side.copy()
    out[near & (d_up < d_corner) & (d_up < d_low)] = 1
    out[near & (d_low < d_corner) & (d_low < d_up)] = -1
    return out


def lip_side(cut: MouthCut, up=(0.0, 1.0, 0.0), radius: float | None = None) -> np.ndarray:
    """Which lip each working vertex belongs to: +1 upper, -1 lower, 0 neither.

    :func:`side_of_points` of the working vertices (above / below the lip line), overruled
    by the surface itself where it is decisive: a vertex (within ``radius``) whose
    shortest edge path to one contour's interior is shorter than its path to either
    corner and to the other contour lies on that lip, whatever its height. Near the
    corners the lips roll inward and the lower lip's top surface can lie above the lip
    line (ICT); only a path around a corner joins it to the upper lip, so it is lower lip.
    Vertices that reach both contours only around a corner (the cheeks beside the mouth)
    keep the height rule. The contours' own interior vertices are upper / lower by
    definition and the two corners are 0.

    Returns
    -------
    (n,) int8 over ``cut.vertices``
    """
    out = side_of_points(cut.vertices, cut, up, radius)
    if len(cut.upper) < 2 or len(cut.lower) < 2:
        return out
    if len(cut.upper) > 2 and len(cut.lower) > 2:
        out = _surface_side(cut, out)
    out[cut.upper[1:-1]] = 1
    out[cut.lower[1:-1]] = -1
    out[[cut.upper[0], cut.upper[-1]]] = 0
    return out
