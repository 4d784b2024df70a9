"""Per-triangle and per-vertex quantities of a triangle mesh.

Every function takes the mesh as ``(vertices (n, 3) float64, faces (m, 3) int64)``
and returns new arrays; nothing is cached. Lengths are in the mesh's units.
"""

from __future__ import annotations

import numpy as np

from faceforge.constants import FLOAT, INT

__all__ = [
    "check_mesh",
    "face_normals",
    "face_areas",
    "vertex_normals",
    "smooth_vertex_normals",
    "smooth_field",
    "barycentric",
    "points_from_barycentric",
    "concatenate_meshes",
    "vertex_components",
]


def check_mesh(vertices, faces) -> tuple[np.ndarray, np.ndarray]:
    """Validate and convert a mesh.

    Returns ``vertices (n, 3) float64`` and ``faces (m, 3) int64``; raises
    ``ValueError`` naming the offending shape or index.
    """
    v = np.asarray(vertices, dtype=FLOAT)
    f = np.asarray(faces, dtype=INT)
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"vertices must have shape (n, 3), got {v.shape}")
    if f.ndim != 2 or f.shape[1] != 3:
        raise ValueError(f"faces must have shape (m, 3), got {f.shape}")
    if f.size and (f.min() < 0 or f.max() >= len(v)):
        raise ValueError(f"faces index vertices outside [0, {len(v)}): range [{f.min()}, {f.max()}]")
    return v, f


def _cross(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Unnormalized face normals ``(e1 x e2)``, length = twice the area. (m, 3)."""
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    return np.cross(b - a, c - a)


def face_normals(vertices, faces) -> np.ndarray:
    """Unit normals of the faces, right-hand rule over ``(f0, f1, f2)``.

    Returns ``(m, 3) float64``; degenerate (zero-area) faces get a zero vector.
    """
    v, f = check_mesh(vertices, faces)
    n = _cross(v, f)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return np.divide(n, length, out=np.zeros_like(n), where=length > 0)


def face_areas(vertices, faces) -> np.ndarray:
    """Areas of the faces, ``(m,) float64`` in squared mesh units."""
    v, f = check_mesh(vertices, faces)
    return 0.5 * np.linalg.norm(_cross(v, f), axis=1)


def vertex_normals(vertices, faces) -> np.ndarray:
    """Area-weighted average of the face normals of each vertex's star.

    Summing the unnormalized cross products weights every face by twice its area.
    Returns ``(n, 3) float64`` unit vectors; vertices referenced by no face (or
    whose star has zero area) get a zero vector.
    """
    v, f = check_mesh(vertices, faces)
    cross = _cross(v, f)
    acc = np.zeros_like(v)
    for k in range(3):
        np.add.at(acc, f[:, k], cross)
    length = np.linalg.norm(acc, axis=1, keepdims=True)
    return np.divide(acc, length, out=np.zeros_like(acc), where=length > 0)


def barycentric(points, vertices, faces, face_ids) -> np.ndarray:
    """Barycentric coordinates of ``points (k, 3)`` w.r.t. the triangles ``face_ids (k,)``.

    The point is first projected orthogonally onto the triangle's plane, so a
    point off the plane gets the coordinates of its foot. Returns ``(k, 3)
    float64`` summing to 1; degenerate triangles give ``(1, 0, 0)``.
    """
    v, f = check_mesh(vertices, faces)
    p = np.asarray(points, dtype=FLOAT).reshape(-1, 3)
    ids = np.asarray(face_ids, dtype=INT).reshape(-1)
    if len(ids) != len(p):
        raise ValueError(f"points {p.shape} and face_ids {ids.shape} differ in length")
    return barycentric_in(p, v[f[ids]])


def barycentric_in(points, tri, degenerate=(1.0, 0.0, 0.0)) -> np.ndarray:
    """Barycentric coordinates of the feet of ``points (k, 3)`` on the planes of the triangles
    ``tri (k, 3, 3)`` (corners), unbounded (a foot outside its triangle has a negative one),
    summing to 1; a degenerate triangle gives ``degenerate``. The core of :func:`barycentric`."""
    p = np.asarray(points, dtype=FLOAT).reshape(-1, 3)
    a = tri[:, 0]
    e0 = tri[:, 1] - a
    e1 = tri[:, 2] - a
    d = p - a
    d00 = np.einsum("ij,ij->i", e0, e0)
    d01 = np.einsum("ij,ij->i", e0, e1)
    d11 = np.einsum("ij,ij->i", e1, e1)
    d20 = np.einsum("ij,ij->i", d, e0)
    d21 = np.einsum("ij,ij->i", d, e1)
    den = d00 * d11 - d01 * d01
    ok = den > 1e-300
    safe = np.where(ok, den, 1.0)
    b1 = np.where(ok, (d11 * d20 - d01 * d21) / safe, degenerate[1])
    b2 = np.where(ok, (d00 * d21 - d01 * d20) / safe, degenerate[2])
    return np.stack([1.0 - b1 - b2, b1, b2], axis=1)


def points_from_barycentric(vertices, faces, face_ids, bary) -> np.ndarray:
    """Inverse of :func:`barycentric`: ``sum_k bary[:, k] * v[f[face_ids, k]]``, (k, 3)."""
    v, f = check_mesh(vertices, faces)
    ids = np.asarray(face_ids, dtype=INT).reshape(-1)
    w = np.asarray(bary, dtype=FLOAT).reshape(-1, 3)
    return np.einsum("ij,ijk->ik", w, v[f[ids]])


def concatenate_meshes(meshes) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stack several meshes into one, faces re-indexed.

    Parameters
    ----------
    meshes : sequence of (vertices (n_i, 3), faces (m_i, 3))

    Returns
    -------
    vertices (sum n_i, 3) float64, faces (sum m_i, 3) int64, vertex_offsets (len + 1,) int64
        Mesh ``i`` owns vertices ``offsets[i]:offsets[i + 1]``; its faces keep their order.
    """
    vs, fs, offsets = [], [], [0]
    for v, f in meshes:
        v, f = check_mesh(v, f)
        fs.append(f + offsets[-1])
        vs.append(v)
        offsets.append(offsets[-1] + len(v))
    if not vs:
        return np.zeros((0, 3), FLOAT), np.zeros((0, 3), INT), np.zeros(1, INT)
    return np.concatenate(vs), np.concatenate(fs), np.asarray(offsets, INT)


def vertex_components(n_vertices: int, faces) -> np.ndarray:
    """Connected-component label of each vertex ``(n,) int64`` (vertices sharing a face
    connect); vertices no face uses get -1."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    faces = np.asarray(faces, dtype=INT).reshape(-1, 3)
    i = np.concatenate([faces[:, 0], faces[:, 1], faces[:, 2]])
    j = np.concatenate([faces[:, 1], faces[:, 2], faces[:, 0]])
    graph = coo_matrix((np.ones(len(i)), (i, j)), shape=(n_vertices, n_vertices))
    _, labels = connected_components(graph, directed=False)
    used = np.zeros(n_vertices, bool)
    used[faces.ravel()] = True
    return np.where(used, labels, -1).astype(INT)


def smooth_vertex_normals(vertices, faces, rounds: int = 0) -> np.ndarray:
    """(n, 3) unit vertex normals of a surface whose vertices are noisy (a scan): the area-weighted
    vertex normals (:func:`vertex_normals`) averaged over edge neighbours ``rounds`` times
    (Jacobi sweeps ``n = (n + A n) / 2`` of :func:`neighbour_average`), renormalised; ``rounds`` 0
    is :func:`vertex_normals` itself. The vertices are not moved. 0.4 mm of noise on MakeHuman's
    4.5 mm edges tilts its vertex normals 4 deg (median), 15 deg (90th percentile); three sweeps
    average each normal over about two rings of neighbours."""
    n = vertex_normals(vertices, faces)
    if rounds <= 0:
        return n
    n = smooth_field(n, faces, int(rounds))
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return n / np.where(length > 0.0, length, 1.0)


def smooth_field(values: np.ndarray, faces, sweeps: int) -> np.ndarray:
    """``values`` ``(n,)`` or ``(n, k)`` per vertex averaged ``sweeps`` times with their edge
    neighbours' mean, half each (Jacobi sweeps ``x = (x + A x) / 2`` of :func:`neighbour_average`):
    a step across one edge becomes a ramp a few edges wide. ``faces`` (m, 3) int. A new array."""
    out = np.asarray(values, dtype=float)
    if sweeps <= 0 or len(faces) == 0:
        return out
    avg = neighbour_average(len(out), faces)
    for _ in range(sweeps):
        out = 0.5 * (out + avg @ out)
    return out


def neighbour_average(n_vertices: int, faces):
    """The umbrella operator of the mesh: a sparse ``(n, n)`` matrix whose product with a vertex
    field ``(n,)`` or ``(n, k)`` is each vertex's mean over its edge neighbours (an edge shared by
    two triangles counts once; a vertex no face uses averages to 0). A few Jacobi sweeps
    ``x = 0.5 (x + A x)`` smooth a field over the surface."""
    from scipy.sparse import coo_matrix, diags

    faces = np.asarray(faces).reshape(-1, 3)
    i, j = faces.ravel(), faces[:, [1, 2, 0]].ravel()
    adj = coo_matrix((np.ones(len(i)), (i, j)), shape=(n_vertices, n_vertices)).tocsr()
    adj = adj + adj.T
    adj.data[:] = 1.0
    return diags(1.0 / np.maximum(np.asarray(adj.sum(axis=1)).ravel(), 1.0)) @ adj


def edge_graph(vertices: np.ndarray, faces: np.ndarray):
    """The mesh's edges as a symmetric sparse ``(n, n)`` CSR matrix of their lengths (a
    zero-length edge kept at 1e-300): the graph of shortest edge paths (scipy's ``dijkstra``)."""
    from scipy.sparse import coo_matrix

    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    e = np.unique(np.sort(e, axis=1), axis=0)
    w = np.linalg.norm(vertices[e[:, 0]] - vertices[e[:, 1]], axis=1)
    w = np.maximum(w, 1e-300)  # zero-length edges must still be edges
    n = len(vertices)
    g = coo_matrix((np.r_[w, w], (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])), shape=(n, n))
    return g.tocsr()


def edge_path(graph, a: int, b: int, banned=()) -> list[int]:
    """The shortest edge path ``a -> b`` (vertex ids) over ``graph`` (:func:`edge_graph`) avoiding
    ``banned`` vertices; [] if none."""
    from scipy.sparse.csgraph import dijkstra

    if a == b:
        return [a]
    g = graph
    banned = [x for x in banned if x not in (a, b)]
    if banned:
        g = graph.tolil(copy=True)
        for x in banned:
            g.rows[x] = []
            g.data[x] = []
        g = g.tocsr()
        keep = np.ones(g.shape[0], bool)
        keep[banned] = False
        g = g.multiply(keep[None, :]).tocsr()
    dist, pred = dijkstra(g, indices=a, return_predecessors=True)
    if not np.isfinite(dist[b]):
        return []
    out = [b]
    while out[-1] != a:
        out.append(int(pred[out[-1]]))
    return out[::-1]
