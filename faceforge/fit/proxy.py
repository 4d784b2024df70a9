"""The simulation mesh of a dense scan (``fit.simulation_vertices``, issues 25/26).

A skin with more internal vertices than the key is fitted, bound, calibrated and simulated on
a decimated copy (:func:`faceforge.geometry.decimate.decimate_pieces`); each of the user's
vertices rides it (:mod:`faceforge.geometry.embed`), and every frame a stage writes in the
user's vertex order is carried back to the dense mesh (``BoundHead.to_user``). ``fit.npz`` then
holds the proxy as ``skin_vertices``/``skin_faces`` and, in addition,

``skin_embed_face (n_user,)``, ``skin_embed_bary (n_user, 3)``, ``skin_embed_offset (n_user,)``,
``skin_embed_residual (n_user, 3)``: each user vertex on the proxy (head space);
``skin_user_faces (t, 3)``: the user's triangles (user vertex ids), for the carried mesh's checks.

``skin_user_to_internal`` is then the proxy vertex nearest each user vertex (its triangle's
corner of largest weight): what older readers of the array get is a coarse but valid copy.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from faceforge.constants import INT
from faceforge.geometry.embed import NPZ_PREFIX as PREFIX   # the npz arrays' prefix


@dataclass
class SimulationMesh:
    """A dense skin's proxy: ``embedding`` (:class:`faceforge.geometry.embed.Embedding`, one
    row per user vertex), ``user_faces (t, 3)`` the user's triangles, ``report`` (dict)."""

    embedding: object
    user_faces: np.ndarray
    report: dict

    def arrays(self) -> dict:
        """The extra arrays of ``fit.npz``."""
        return {**self.embedding.arrays(PREFIX), "skin_user_faces": np.asarray(self.user_faces, INT)}


def border_vertices(faces) -> np.ndarray:
    """Vertex ids ``(b,)`` on an edge only one of ``faces (m, 3)`` uses (an open border)."""
    from faceforge.io.mesh_check import edge_face_counts

    edges, counts = edge_face_counts(np.asarray(faces, INT).reshape(-1, 3))
    return np.unique(edges[counts == 1])


def needs_proxy(n_vertices: int, limit: int) -> bool:
    """True when a skin of ``n_vertices`` internal vertices is simulated on a proxy (``limit``
    ``fit.simulation_vertices``; 0: never)."""
    return int(limit) > 0 and int(n_vertices) > int(limit)


def make_proxy(checked, user_faces, limit: int, keep_below: int | None = None, keep_borders: bool = True,
               locked=None, contours=None):
    """The proxy of a checked dense skin.

    checked
        :class:`faceforge.io.mesh_check.CheckedMesh` in head space (outward winding).
    user_faces
        ``(t, 3)`` the user's triangles (user vertex ids; :func:`faceforge.io.mesh.load_mesh`).
    limit
        the proxy's vertex budget (``fit.simulation_vertices``); pieces of at most ``keep_below``
        vertices (default: a twentieth of it) are kept whole; ``keep_borders``: the open borders
        keep every vertex (``fit.simulation_borders``); ``locked (k,) bool``: internal vertices
        no collapse may touch (:func:`lip_lock`); ``contours`` (or None): the inner lips' ``(upper,
        lower)`` on the dense mesh (:func:`lip_contours`, locked): each dense vertex of one lip
        then rides proxy triangles with no corner on the other (:func:`lip_sides`,
        :func:`faceforge.geometry.embed.embed_apart`; ``fit.simulation_lip_sides``).

    Returns ``(proxy CheckedMesh, SimulationMesh)``: the proxy's ``user_to_internal`` maps each
    user vertex to its nearest proxy corner, ``internal_to_user`` each proxy vertex to the user
    vertex nearest it; its report is the dense mesh's.
    """
    from scipy.spatial import cKDTree

    from faceforge.geometry.decimate import decimate_pieces
    from faceforge.geometry.embed import carry, embed_apart, embed_points
    from faceforge.geometry.triangles import vertex_components

    v, f = checked.vertices, checked.faces
    keep_below = int(limit) // 20 if keep_below is None else int(keep_below)
    pv, pf, piece, merged = decimate_pieces(v, f, int(limit), keep_below=keep_below, keep_borders=keep_borders,
                                            locked=locked)
    labels = vertex_components(len(v), f)
    internal = embed_points(v, pv, pf, labels, piece[pf[:, 0]], point_vertex=merged)
    apart = 0
    if contours is not None:   # the lips' own triangles: where they part, none rides both
        up, low = (np.asarray(c, INT) for c in contours)
        reach = float(np.linalg.norm(v[up[0]] - v[up[-1]]))
        internal, apart = embed_apart(internal, v, pv, pf, lip_sides(v, f, up, low, reach),
                                      lip_sides(pv, pf, merged[up], merged[low], reach), merged, labels,
                                      piece[pf[:, 0]])
    embedding = internal.take(checked.user_to_internal)
    corner = pf[embedding.face, np.argmax(embedding.bary, axis=1)]
    nearest = cKDTree(v).query(pv)[1]
    proxy = replace(checked, vertices=pv, faces=pf, user_to_internal=corner.astype(INT),
                    internal_to_user=np.asarray(checked.internal_to_user)[nearest].astype(INT))
    diag = float(np.linalg.norm(v.max(0) - v.min(0)))
    back = carry(pv, pf, internal)
    report = {"user_vertices": int(len(checked.user_to_internal)), "dense_vertices": int(len(v)),
              "dense_faces": int(len(f)), "proxy_vertices": int(len(pv)), "proxy_faces": int(len(pf)),
              "limit": int(limit), "pieces": int(labels.max() + 1) if len(labels) else 0,
              "border_vertices_dense": len(border_vertices(f)), "border_vertices_proxy": len(border_vertices(pf)),
              "offset_max": float(np.abs(internal.offset).max() / diag),
              "offset_median": float(np.median(np.abs(internal.offset)) / diag),
              "rest_error_max": float(np.abs(back - v).max() / diag),
              "locked_vertices": 0 if locked is None else int(np.count_nonzero(locked)),
              **({} if contours is None else {"lip_vertices_apart": int(apart)})}
    return proxy, SimulationMesh(embedding, np.asarray(user_faces, INT), report)


def landmarks_by_position(raw, user_vertices):
    """``raw`` (:class:`faceforge.io.landmarks.RawLandmarks`) with every vertex id given as
    that user vertex's position ``user_vertices (n, 3)`` (user frame) instead: the ids of the
    dense mesh mean nothing on its proxy, their places do (snapped onto it). Ids out of range
    are left for :func:`faceforge.io.landmarks.load_landmarks` to report."""
    if raw is None:
        return None
    uv = np.asarray(user_vertices, dtype=float)
    has = (raw.vertex >= 0) & (raw.vertex < len(uv))
    position = np.where(has[:, None], uv[np.where(has, raw.vertex, 0)], raw.position)
    return replace(raw, vertex=np.where(has, -1, raw.vertex).astype(np.int64), position=position)


#: the inner lips' contours, corner to corner (as skin.mouth's)
LIP_PATHS = (("2.4", "2.6", "2.2", "2.7", "2.5"), ("2.4", "2.8", "2.3", "2.9", "2.5"))


def lip_contours(vertices, faces, points: dict):
    """``(upper, lower)`` vertex-id paths of the inner lips, corner to corner: the shortest edge
    paths through the FDPs of :data:`LIP_PATHS` found in ``points {fdp: (3,)}``, each at its
    nearest vertex (as skin.mouth's, without its lip cut); None without 2.2-2.5."""
    from scipy.spatial import cKDTree

    from faceforge.geometry.triangles import edge_graph, edge_path

    if not all(k in points for k in ("2.2", "2.3", "2.4", "2.5")):
        return None
    v = np.asarray(vertices, dtype=float)
    graph = edge_graph(v, np.asarray(faces, INT))
    tree = cKDTree(v)
    out = []
    for path in LIP_PATHS:
        stops = [int(tree.query(points[k])[1]) for k in path if k in points]
        ids = [stops[0]]
        for a, b in zip(stops[:-1], stops[1:]):
            ids.extend(int(i) for i in edge_path(graph, a, b)[1:])
        out.append(np.asarray(ids, INT))
    return out[0], out[1]


def lip_lock(vertices, faces, points: dict, rings: int = 1, corner_reach: float = 0.0,
             contours: bool = True) -> np.ndarray:
    """``(n,) bool``: the vertices of the inner lips' contours (:func:`lip_contours`) and
    ``rings`` rings of neighbours: the decimation may not collapse them (where the lips touch
    a collapse zips them shut from the corners). ``corner_reach`` (a fraction of the mouth's
    width, corner to corner; 0: none) also locks every vertex that near either corner along
    the surface (edge paths): the commissure, which stretches most as the lips part, stays
    the dense mesh itself. ``contours`` False locks the two corners (and their ``rings``) in
    place of the whole contours: a collapse can only weld the lips through an edge joining
    them, which an open mouth has in the corners' fans only, so the contours may coarsen to
    the proxy's spacing. None locked without 2.2-2.5."""
    f = np.asarray(faces, INT)
    lock = np.zeros(len(vertices), bool)
    found = lip_contours(vertices, faces, points)
    if found is None:
        return lock
    for c in found:
        lock[c if contours else [c[0], c[-1]]] = True
    for _ in range(int(rings)):
        lock[np.unique(f[lock[f].any(axis=1)])] = True
    if corner_reach > 0:
        from scipy.sparse.csgraph import dijkstra

        from faceforge.geometry.triangles import edge_graph

        v = np.asarray(vertices, dtype=float)
        ends = [int(found[0][0]), int(found[0][-1])]
        reach = float(corner_reach) * float(np.linalg.norm(v[ends[0]] - v[ends[1]]))
        lock |= np.isfinite(dijkstra(edge_graph(v, f), indices=ends, min_only=True, limit=reach))
    return lock


def lip_sides(vertices, faces, upper, lower, reach: float | None = None) -> np.ndarray:
    """``(n,) int8``: +1 for a vertex nearer (along the surface: edge paths) the upper
    contour's interior than the lower's and the corners, -1 nearer the lower's, 0 else (the
    corners, the cheeks beside them, whose paths to both lips go round a corner) or farther
    than ``reach`` (mesh units; default the mouth's width, corner to corner) from all three.
    ``upper``/``lower`` (:func:`lip_contours`) share their two corners. Contours that share
    interior vertices (one ring for both lips) give 0 there."""
    from scipy.sparse.csgraph import dijkstra

    from faceforge.geometry.triangles import edge_graph

    v = np.asarray(vertices, dtype=float)
    up, low = np.asarray(upper, INT), np.asarray(lower, INT)
    out = np.zeros(len(v), np.int8)
    if len(up) < 3 or len(low) < 3:
        return out
    r = float(np.linalg.norm(v[up[0]] - v[up[-1]])) if reach is None else float(reach)
    g = edge_graph(v, np.asarray(faces, INT))
    d_up, d_low, d_corner = (dijkstra(g, indices=ids, min_only=True, limit=r) for ids in (
        up[1:-1], low[1:-1], np.unique([up[0], up[-1], low[0], low[-1]])))
    out[(d_up < d_low) & (d_up < d_corner)] = 1
    out[(d_low < d_up) & (d_low < d_corner)] = -1
    return out
