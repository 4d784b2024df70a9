"""A closed mesh made its own mirror image about the plane x = 0 (the template skull, issue 25).

A mesh whose *shape* is symmetric but whose triangulation is not (a scanned skull, remeshed)
has no vertex-to-vertex mirror map, so a fit that moves its vertices one by one cannot stay
symmetric. :func:`mirror_half` keeps the mesh's +x half (cut exactly at x = 0), mirrors it with
the mirror-image triangulation and welds the two halves along the cut: every vertex then has
a partner (:func:`vertex_partners`), midline vertices being their own.
"""

from __future__ import annotations

import numpy as np

__all__ = ["mirror_half", "vertex_partners"]


def _weld(v: np.ndarray, f: np.ndarray, tol: float) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (n, 3) closer than ``tol`` merged (the first kept), faces (m, 3) reindexed,
    faces that lost a corner dropped, unused vertices removed."""
    from scipy.sparse.csgraph import connected_components
    from scipy.sparse import coo_matrix
    from scipy.spatial import cKDTree

    pairs = cKDTree(v).query_pairs(tol, output_type="ndarray")
    n = len(v)
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])) if len(pairs) else
                       (np.zeros(0), (np.zeros(0, int), np.zeros(0, int))), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    first = np.full(label.max() + 1, n)
    np.minimum.at(first, label, np.arange(n))
    f = first[label][f]
    f = f[(f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 2] != f[:, 0])]
    used = np.unique(f)
    remap = -np.ones(n, dtype=np.int64)
    remap[used] = np.arange(len(used))
    return v[used], remap[f]


def mirror_half(vertices: np.ndarray, faces: np.ndarray, snap: float = 0.2
                ) -> tuple[np.ndarray, np.ndarray]:
    """The closed mesh ``(vertices (n, 3), faces (m, 3))`` replaced by its +x half and that
    half's mirror image (x -> -x, faces turned so the normals stay outward), welded at x = 0.

    ``snap`` (fraction of the mean edge length): vertices this close to the plane are put on
    it first, so the cut makes no sliver triangles (the YahooJAPAN-derived template skull:
    0.2 moves 1 mm at most, the smallest edge 0.1 cm against 0.004 without it); faces lying
    in the plane are dropped (each half would bring one). Returns new ``(v (k, 3) float64, f (l, 3) int64)``; the result is its own mirror
    image vertex for vertex (:func:`vertex_partners` finds every partner at distance 0).
    """
    from trimesh.intersections import slice_faces_plane

    v = np.array(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    edges = np.linalg.norm(v[f] - v[np.roll(f, 1, axis=1)], axis=2)
    v[np.abs(v[:, 0]) < snap * float(edges.mean()), 0] = 0.0
    hv, hf = slice_faces_plane(v, f, plane_normal=np.array([1.0, 0.0, 0.0]), plane_origin=np.zeros(3))[:2]
    hv = np.array(hv, dtype=np.float64)
    hf = np.asarray(hf, dtype=np.int64)
    hv[np.abs(hv[:, 0]) < 1e-9, 0] = 0.0
    hv, hf = _weld(hv, hf, 1e-9)
    hf = hf[~np.all(hv[hf][:, :, 0] == 0.0, axis=1)]   # lying in the plane
    on = hv[:, 0] == 0.0
    off = np.flatnonzero(~on)
    index = np.arange(len(hv))
    index[off] = len(hv) + np.arange(len(off))             # mirrored copies of the off-plane vertices
    mv = np.vstack([hv, hv[off] * [-1.0, 1.0, 1.0]])
    mf = np.vstack([hf, index[hf][:, ::-1]])
    return _weld(mv, mf, 1e-12)


def vertex_partners(vertices: np.ndarray, tol: float = 1e-9) -> np.ndarray | None:
    """For a mesh that is its own mirror image about x = 0: the index (n,) of each vertex's
    mirror partner (itself on the plane); None when some vertex has none within ``tol``."""
    from scipy.spatial import cKDTree

    v = np.asarray(vertices, dtype=np.float64)
    d, j = cKDTree(v).query(v * [-1.0, 1.0, 1.0])
    return j if len(v) and float(d.max()) <= tol else None
