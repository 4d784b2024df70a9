"""A coarser copy of a dense mesh to simulate on (issues 25/26: a scan of any density).

Quadric edge collapse (``fast_simplification``, the library trimesh's
``simplify_quadric_decimation`` calls) run on each connected piece alone, so that separate
pieces (eyeballs, teeth, a second head) are never joined; pieces of at most ``keep_below``
vertices are kept as they are. The collapse never touches an edge with a border vertex
(``preserve_border``): the open boundaries (the neck cut, the mouth slit, the eye openings)
keep every vertex and edge, so two lips are never welded across their slit (a collapse joins
only the two ends of an edge, and the slit's two rims share no edge).
"""

from __future__ import annotations

import numpy as np

from faceforge.constants import FLOAT, INT

__all__ = ["decimate_pieces"]


def _compact(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The used vertices only, faces renumbered (faces with a repeated corner dropped), and
    ``(n,)`` the new id of each old vertex (-1: unused)."""
    f = np.asarray(faces, dtype=INT).reshape(-1, 3)
    f = f[(f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 2] != f[:, 0])]
    used, inverse = np.unique(f.ravel(), return_inverse=True)
    new = np.full(len(vertices), -1, INT)
    new[used] = np.arange(len(used))
    return np.asarray(vertices, dtype=FLOAT)[used], inverse.reshape(-1, 3).astype(INT), new


def _with_lock_flags(vertices: np.ndarray, faces: np.ndarray, lock: np.ndarray):
    """``(vertices, faces)`` with a small loose triangle hung on each vertex of ``lock``: two new
    vertices (appended last) and a triangle whose edges only it uses, so the vertex is on a
    border and the collapse (``preserve_border``) leaves it and its edges alone."""
    if not len(lock):
        return vertices, faces
    n, k = len(vertices), len(lock)
    scale = 1e-6 * float(np.ptp(vertices, axis=0).max())
    extra = np.concatenate([vertices[lock] + [scale, 0.0, 0.0], vertices[lock] + [0.0, scale, 0.0]])
    tri = np.stack([lock, n + np.arange(k), n + k + np.arange(k)], axis=1)
    return np.concatenate([vertices, extra]), np.concatenate([faces, tri])


def decimate_pieces(vertices, faces, target_vertices: int, keep_below: int = 2000,
                    aggressiveness: float = 7.0, keep_borders: bool = True, locked=None
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Decimate each connected piece of ``(vertices (n, 3), faces (m, 3))`` to about
    ``target_vertices`` vertices in all.

    Pieces of at most ``keep_below`` vertices are copied unchanged; the others share what
    is left of the budget in proportion to their triangles (each keeps at least 8
    triangles). ``locked (n,) bool`` (or None): vertices no collapse may touch (they and their
    edges are kept: the lips' contours, which a collapse would otherwise zip shut from the
    corners where they meet). Open borders are kept whole (see the module's docstring), or with
    ``keep_borders`` False collapsed along themselves like the rest (the library's border
    quadrics hold them in place; two rims that share no edge still cannot be welded).

    Returns ``(proxy_vertices (k, 3) float64, proxy_faces (l, 3) int64, proxy_piece (k,)
    int64, merged_into (n,) int64)``: ``proxy_piece`` is the label of the input piece
    (:func:`faceforge.geometry.triangles.vertex_components`) each proxy vertex comes from;
    ``merged_into`` the proxy vertex each input vertex was collapsed into (the library's
    collapses, replayed; -1 for a vertex no face uses, which is dropped). The winding is kept.
    """
    import fast_simplification

    from faceforge.geometry.triangles import vertex_components

    v = np.asarray(vertices, dtype=FLOAT).reshape(-1, 3)
    f = np.asarray(faces, dtype=INT).reshape(-1, 3)
    labels = vertex_components(len(v), f)
    face_piece = labels[f[:, 0]]
    pieces = np.unique(face_piece)
    counts = {int(p): int(np.count_nonzero(labels == p)) for p in pieces}
    small = [p for p in counts if counts[p] <= keep_below]
    big = [p for p in counts if counts[p] > keep_below]
    budget = max(int(target_vertices) - sum(counts[p] for p in small), 0)
    big_total = sum(counts[p] for p in big)
    ratio = min(1.0, budget / big_total) if big_total else 1.0
    out_v, out_f, out_p, offset = [], [], [], 0
    merged = np.full(len(v), -1, INT)
    for p in (int(p) for p in pieces):
        pv, pf, new = _compact(v, f[face_piece == p])
        mine = np.flatnonzero(new >= 0)
        into = new[mine]
        target = max(8, int(round(len(pf) * ratio)))
        if p in big and ratio < 1.0 and target < len(pf):   # (a piece already that small is kept)
            lock = np.zeros(len(pv), bool) if locked is None else np.asarray(locked, bool)[mine]
            sv, sf = _with_lock_flags(pv, pf, np.flatnonzero(lock))
            _, _, collapses = fast_simplification.simplify(
                sv, sf.astype(np.int32), target_count=target + (len(sf) - len(pf)), agg=aggressiveness,
                preserve_border=keep_borders or bool(lock.any()), return_collapses=True)
            dv, df, mapping = fast_simplification.replay_simplification(sv, sf.astype(np.int32), collapses)
            mapping = np.asarray(mapping, INT)
            df = np.asarray(df, INT)
            df = df[~np.isin(df, mapping[len(pv):]).any(axis=1)]   # the lock flags go
            pv, pf, again = _compact(dv, df)
            into = again[mapping[into]]
        merged[mine] = np.where(into >= 0, into + offset, -1)
        out_v.append(pv)
        out_f.append(pf + offset)
        out_p.append(np.full(len(pv), p, INT))
        offset += len(pv)
    if not out_v:
        return np.zeros((0, 3), FLOAT), np.zeros((0, 3), INT), np.zeros(0, INT), merged
    return np.concatenate(out_v), np.concatenate(out_f), np.concatenate(out_p), merged
