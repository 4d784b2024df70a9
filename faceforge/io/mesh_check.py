"""Validation and repair of a user's head mesh before simulation.

:func:`check_mesh` takes the user's ``(vertices, faces)`` and returns the internal
simulation mesh with a map back to the user's vertex order, and a report:

=====================  ==========================================================
problem                what happens
=====================  ==========================================================
no faces, NaN / inf,   rejected (:class:`~faceforge.exceptions.MeshError`)
index out of range,
zero extent
duplicate vertices     merged internally (``user_to_internal`` keeps the map back)
degenerate triangles   dropped internally (repeated index or zero area)
duplicate triangles    dropped internally (same three vertices)
non-manifold edges     rejected: an edge shared by more than two triangles
inconsistent winding   triangles turned to agree with their neighbours (per piece)
holes                  reported as boundary loops (open heads are normal)
several components     kept and reported (e.g. iris points, eyeballs); with ``one_head``
                       (landmarks to find) rejected when a piece as large as half the skin
                       lies wholly beside it (two heads: which one to find?)
unused vertices        kept and reported
=====================  ==========================================================

Tolerances are relative to the bounding-box diagonal (``faceforge.constants.TOL``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from faceforge.constants import TOL
from faceforge.exceptions import MeshError

#: vertices closer than this fraction of the diagonal are duplicates
MERGE_DISTANCE = 1e-9

#: a separate piece whose box diagonal is at least this share of the largest piece's, and whose
#: box does not meet that piece's box, is a second head (eyeballs, teeth, lashes, hair lie in or on it)
SECOND_HEAD_SHARE = 0.5


@dataclass
class MeshReport:
    """What :func:`check_mesh` found and repaired (JSON-friendly)."""

    n_vertices: int
    n_faces: int
    merged_vertices: int = 0
    degenerate_faces: int = 0
    duplicate_faces: int = 0
    unused_vertices: int = 0
    boundary_loops: list = field(default_factory=list)   # edge count of each hole, largest first
    components: list = field(default_factory=list)       # face count of each component, largest first
    warnings: list = field(default_factory=list)

    def as_dict(self) -> dict:
        return dict(self.__dict__)


@dataclass
class CheckedMesh:
    """The internal simulation mesh and its relation to the user's mesh.

    vertices : (k, 3) float64, merged vertices (mesh units)
    faces : (m, 3) int64, non-degenerate triangles indexing ``vertices``
    user_to_internal : (n,) int64, internal vertex of each user vertex
    internal_to_user : (k,) int64, first user vertex of each internal vertex
    """

    vertices: np.ndarray
    faces: np.ndarray
    user_to_internal: np.ndarray
    internal_to_user: np.ndarray
    report: MeshReport

    def to_user(self, internal_positions: np.ndarray) -> np.ndarray:
        """Per-internal-vertex data (k, ...) -> per-user-vertex data (n, ...)."""
        return np.asarray(internal_positions)[self.user_to_internal]


def merge_duplicate_vertices(vertices: np.ndarray, distance: float):
    """Group vertices closer than ``distance`` (transitively).

    Returns ``(user_to_internal (n,) int64, internal_to_user (k,) int64)``; internal
    vertices keep the order of their first user vertex.
    """
    n = len(vertices)
    pairs = cKDTree(vertices).query_pairs(distance, output_type="ndarray") if n else np.empty((0, 2), int)
    if len(pairs) == 0:
        ident = np.arange(n, dtype=np.int64)
        return ident, ident.copy()
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    first = np.full(label.max() + 1, n, dtype=np.int64)
    np.minimum.at(first, label, np.arange(n))
    order = np.argsort(first, kind="stable")          # components by first appearance
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    return rank[label].astype(np.int64), first[order]


def edge_face_counts(faces: np.ndarray):
    """Unique undirected edges ``(e, 2) int64`` (sorted pairs) and how many faces use each."""
    edges = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    unique, counts = np.unique(edges, axis=0, return_counts=True)
    return unique, counts


def boundary_loops(faces: np.ndarray) -> list:
    """Holes as closed vertex loops: list of int64 arrays, largest first.

    Boundary edges are used by exactly one face. A vertex where two holes touch is
    visited once per loop.
    """
    unique, counts = edge_face_counts(faces)
    bnd = unique[counts == 1]
    if len(bnd) == 0:
        return []
    neighbours: dict = {}
    for a, b in bnd:
        neighbours.setdefault(int(a), []).append(int(b))
        neighbours.setdefault(int(b), []).append(int(a))
    unused = {tuple(e) for e in bnd.tolist()}
    loops = []
    while unused:
        a, b = unused.pop()
        loop = [a, b]
        while True:
            cur = loop[-1]
            nxt = next((c for c in neighbours[cur] if (min(cur, c), max(cur, c)) in unused), None)
            if nxt is None:
                break
            unused.discard((min(cur, nxt), max(cur, nxt)))
            if nxt == loop[0]:
                break
            loop.append(nxt)
        loops.append(np.asarray(loop, dtype=np.int64))
    return sorted(loops, key=len, reverse=True)


def face_components(faces: np.ndarray, n_vertices: int) -> np.ndarray:
    """Connected component label (m,) int64 of each face (faces sharing a vertex connect)."""
    m = len(faces)
    rows = np.repeat(np.arange(m), 3)
    graph = coo_matrix((np.ones(3 * m), (rows, faces.ravel() + m)), shape=(m + n_vertices, m + n_vertices))
    _, label = connected_components(graph, directed=False)
    return label[:m].astype(np.int64)


def check_mesh(vertices: np.ndarray, faces: np.ndarray, path: str = "<mesh>", one_head: bool = False) -> CheckedMesh:
    """Validate and repair a head mesh.

    Parameters
    ----------
    vertices : (n, 3) float, user's vertices (any units)
    faces : (m, 3) int, triangles (quads must be split by the loader)
    path : file name used in error messages
    one_head : reject a second head-sized piece beside the skin (:func:`_reject_second_head`): the
        landmarks are to be found, and the detector would pick one head

    Returns
    -------
    CheckedMesh; raises :class:`MeshError` when the mesh cannot be used.
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces)
    if vertices.ndim != 2 or vertices.shape[1] != 3 or len(vertices) < 3:
        raise MeshError(f"needs at least 3 vertices with x, y, z, got array of shape {vertices.shape}", path)
    if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
        raise MeshError(f"needs triangles (m, 3), got array of shape {faces.shape}", path)
    if not np.all(np.isfinite(vertices)):
        bad = np.flatnonzero(~np.all(np.isfinite(vertices), axis=1))
        raise MeshError(f"{len(bad)} vertices have NaN or infinite coordinates (first: vertex {bad[0]})", path)
    faces = faces.astype(np.int64)
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise MeshError(f"face index out of range (mesh has {len(vertices)} vertices, "
                        f"faces use {faces.min()}..{faces.max()})", path)
    report = MeshReport(len(vertices), len(faces))
    used = np.zeros(len(vertices), bool)
    used[faces.ravel()] = True
    diag = float(np.linalg.norm(np.ptp(vertices[used], axis=0)))
    if diag <= 0:
        raise MeshError("all vertices coincide (zero extent)", path)

    user_to_internal, internal_to_user = merge_duplicate_vertices(vertices, MERGE_DISTANCE * diag)
    report.merged_vertices = len(vertices) - len(internal_to_user)
    if report.merged_vertices:
        report.warnings.append(f"merged {report.merged_vertices} duplicate vertices (the output keeps your vertex order)")
    iv = vertices[internal_to_user]
    f = user_to_internal[faces]

    tol = TOL.scaled(diag)
    repeated = (f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 2] == f[:, 0])
    area2 = np.linalg.norm(np.cross(iv[f[:, 1]] - iv[f[:, 0]], iv[f[:, 2]] - iv[f[:, 0]]), axis=1)
    degenerate = repeated | (area2 <= 2 * tol.degenerate * diag)
    report.degenerate_faces = int(degenerate.sum())
    if report.degenerate_faces:
        report.warnings.append(f"dropped {report.degenerate_faces} degenerate triangles (zero area)")
    f = f[~degenerate]
    if len(f) == 0:
        raise MeshError("every triangle is degenerate (zero area)", path)
    _, first = np.unique(np.sort(f, axis=1), axis=0, return_index=True)
    keep = np.sort(first)
    report.duplicate_faces = len(f) - len(keep)
    if report.duplicate_faces:
        report.warnings.append(f"dropped {report.duplicate_faces} duplicate triangles")
    f = f[keep]

    unique, counts = edge_face_counts(f)
    nm = unique[counts > 2]
    if len(nm):
        a, b = internal_to_user[nm[0]]
        raise MeshError(f"{len(nm)} non-manifold edges (shared by more than two triangles), "
                        f"e.g. between vertices {a} and {b}; fix the mesh in a modeller", path)
    flipped = _fix_winding(f)
    if flipped:
        report.warnings.append(f"turned {flipped} triangles to agree with their neighbours' winding")
    loops = boundary_loops(f)
    report.boundary_loops = [int(len(x)) for x in loops]
    labels = face_components(f, len(iv))
    report.components = sorted(np.bincount(np.unique(labels, return_inverse=True)[1]).tolist(), reverse=True)
    if len(report.components) > 1:
        if one_head:
            _reject_second_head(iv, f, labels, path)
        report.warnings.append(f"{len(report.components)} separate pieces (face counts {report.components[:5]}); "
                               "all are kept, the largest is the skin")
    used = np.zeros(len(iv), bool)
    used[f.ravel()] = True
    report.unused_vertices = int((~used).sum())
    return CheckedMesh(iv, f, user_to_internal, internal_to_user, report)


def _reject_second_head(vertices: np.ndarray, faces: np.ndarray, labels: np.ndarray, path: str) -> None:
    """Raise :class:`MeshError` when a piece of the mesh is another head: its bounding box is at
    least :data:`SECOND_HEAD_SHARE` of the largest piece's (by diagonal) and the two boxes do not
    meet. ``vertices (k, 3)``, ``faces (m, 3)``, ``labels (m,)`` the faces' pieces."""
    pieces = np.unique(labels)
    boxes = []
    for piece in pieces:
        pv = vertices[np.unique(faces[labels == piece])]
        boxes.append((pv.min(axis=0), pv.max(axis=0)))
    size = np.array([np.linalg.norm(hi - lo) for lo, hi in boxes])
    big = int(np.argmax(np.bincount(labels)[pieces]))           # the piece with the most faces: the skin
    lo0, hi0 = boxes[big]
    apart = [k for k, (lo, hi) in enumerate(boxes)
             if k != big and size[k] >= SECOND_HEAD_SHARE * size[big] and (np.any(lo > hi0) or np.any(hi < lo0))]
    if apart:
        raise MeshError(f"{len(apart) + 1} separate head-sized pieces side by side (the largest is "
                        f"{np.bincount(labels)[pieces][big]} triangles); faceforge animates one head a file: "
                        "save each head on its own", path)


def _fix_winding(faces: np.ndarray) -> int:
    """Make the winding of each piece consistent, in place; returns how many faces were turned.

    A breadth-first walk over faces sharing an edge: a neighbour that runs the shared edge
    in the same direction is turned. The first face of each piece keeps its winding (the fit
    orients the whole skin outward afterwards). Requires a manifold mesh.
    """
    m = len(faces)
    directed = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    if len(np.unique(directed, axis=0)) == len(directed):
        return 0   # every shared edge is run once each way: already consistent
    und = np.sort(directed, axis=1)
    _, inv = np.unique(und, axis=0, return_inverse=True)
    inv = inv.ravel()
    order = np.argsort(inv, kind="stable")   # half-edges of one edge become neighbours
    same = inv[order[1:]] == inv[order[:-1]]
    a, b = order[:-1][same], order[1:][same]          # half-edge ids sharing an edge
    adj = [[] for _ in range(m)]
    for ha, hb in zip(a.tolist(), b.tolist()):
        adj[ha // 3].append((hb // 3, ha, hb))
        adj[hb // 3].append((ha // 3, hb, ha))
    turned = np.zeros(m, bool)
    seen = np.zeros(m, bool)
    count = 0
    for start in range(m):
        if seen[start]:
            continue
        seen[start] = True
        stack = [start]
        while stack:
            f = stack.pop()
            for g, hf, hg in adj[f]:
                if seen[g]:
                    continue
                # directions of the shared edge as the faces will be wound
                df = directed[hf] if not turned[f] else directed[hf][::-1]
                dg = directed[hg]
                turned[g] = bool(np.all(df == dg))
                count += int(turned[g])
                seen[g] = True
                stack.append(g)
    faces[turned] = faces[turned][:, ::-1]
    return count


def largest_component(faces: np.ndarray, n_vertices: int) -> np.ndarray:
    """Faces (k, 3) of the component with the most triangles."""
    labels = face_components(faces, n_vertices)
    return faces[labels == np.bincount(labels).argmax()]


def fill_holes(vertices: np.ndarray, faces: np.ndarray, keep_open: int = 1):
    """Close holes virtually with a fan around each loop's centroid.

    The ``keep_open`` longest loops (by length in space: the neck, the rim of a face mask)
    stay open. Fan triangles follow the winding of the faces along the hole, so the
    result is consistently oriented. Returns ``(vertices (n + h, 3), faces (m + e, 3),
    n_filled)``: the original arrays come first, unchanged.
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    loops = boundary_loops(f)
    if len(loops) <= keep_open:
        return v, f, 0
    length = [float(np.linalg.norm(v[lp] - v[np.roll(lp, -1)], axis=1).sum()) for lp in loops]
    order = np.argsort(length)[::-1]
    fill = [loops[i] for i in order[keep_open:]]
    directed = f[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    unique, counts = edge_face_counts(f)
    single = {tuple(e) for e in unique[counts == 1].tolist()}
    new_v, new_f = [v], [f]
    n = len(v)
    for k, lp in enumerate(fill):
        members = set(lp.tolist())
        mask = np.array([a in members and b in members and (min(a, b), max(a, b)) in single
                         for a, b in directed.tolist()])
        edges = directed[mask]
        c = n + k
        new_v.append(v[lp].mean(axis=0, keepdims=True))
        new_f.append(np.column_stack([edges[:, 1], edges[:, 0], np.full(len(edges), c)]))
    return np.vstack(new_v), np.vstack(new_f), len(fill)
