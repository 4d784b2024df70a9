"""Points carried by a coarser mesh: a dense scan's vertices ride its simulation proxy.

Each point is tied to one proxy triangle (of its own piece): barycentric coordinates ``b``
of its foot, an offset ``d`` along the triangle's interpolated vertex normal and a small
rest residual ``r`` in the triangle's own frame (edge, normal x edge, normal), so that

    x = sum_k b_k p_k + d * unit(sum_k b_k n_k) + R(p) r

reproduces every point at rest (to rounding) and moves with the proxy: exactly under any
rigid motion, and a point on a flat proxy patch under any affine map of it. The foot is
found along the interpolated normal (a few fixed-point rounds from the closest point), so
``r`` is ~0 and a curved proxy carries a smooth surface, not its facets.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from faceforge.constants import FLOAT, INT, NUMBA_OPTIONS
from faceforge.geometry.triangles import barycentric_in, vertex_normals

__all__ = ["Embedding", "embed_points", "carry", "area_vertex_normals", "triangle_frames", "working_corners", "carry_plain", "embed_off",
           "embed_apart"]

#: prefix of a skin's embedding arrays in fit.npz (faceforge.fit.proxy)
NPZ_PREFIX = "skin_embed_"

#: fixed-point rounds of the foot along the interpolated normal
FOOT_ROUNDS = 8


@dataclass
class Embedding:
    """``face (n,) int64`` proxy triangle, ``bary (n, 3)``, ``offset (n,)`` mesh units along
    the interpolated normal, ``residual (n, 3)`` in the triangle's frame (mesh units)."""

    face: np.ndarray
    bary: np.ndarray
    offset: np.ndarray
    residual: np.ndarray

    def arrays(self, prefix: str) -> dict:
        """``{prefix + name: array}`` for an npz."""
        return {f"{prefix}face": self.face, f"{prefix}bary": self.bary, f"{prefix}offset": self.offset,
                f"{prefix}residual": self.residual}

    @classmethod
    def from_arrays(cls, data, prefix: str) -> "Embedding | None":
        """The embedding saved by :meth:`arrays`, or None when ``data`` has none."""
        if f"{prefix}face" not in data:
            return None
        return cls(np.asarray(data[f"{prefix}face"], INT), np.asarray(data[f"{prefix}bary"], FLOAT),
                   np.asarray(data[f"{prefix}offset"], FLOAT), np.asarray(data[f"{prefix}residual"], FLOAT))

    def take(self, index) -> "Embedding":
        """The embedding of the points ``index`` (e.g. the user's vertex order)."""
        return Embedding(self.face[index], self.bary[index], self.offset[index], self.residual[index])


def area_vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """``(..., n, 3)`` unit area-weighted vertex normals of ``vertices (..., n, 3)`` (a stack of
    frames allowed) over ``faces (m, 3)``; 0 for a vertex no face uses
    (:func:`faceforge.geometry.triangles.vertex_normals` a frame at a time)."""
    v = np.asarray(vertices, dtype=FLOAT)
    flat = v.reshape(-1, *v.shape[-2:])
    return np.stack([vertex_normals(x, faces) for x in flat]).reshape(v.shape)


def triangle_frames(tri: np.ndarray) -> np.ndarray:
    """``(..., 3, 3)`` orthonormal frames (rows: first edge, normal x edge, normal) of
    triangles ``tri (..., 3, 3)`` (corners); degenerate triangles give the identity."""
    e = tri[..., 1, :] - tri[..., 0, :]
    n = np.cross(e, tri[..., 2, :] - tri[..., 0, :])
    le, ln = np.linalg.norm(e, axis=-1, keepdims=True), np.linalg.norm(n, axis=-1, keepdims=True)
    ok = (le > 0) & (ln > 0)
    e = np.where(ok, e / np.where(ok, le, 1.0), [1.0, 0.0, 0.0])
    n = np.where(ok, n / np.where(ok, ln, 1.0), [0.0, 0.0, 1.0])
    return np.stack([e, np.cross(n, e), n], axis=-2)


def _interpolated_normals(normals: np.ndarray, faces: np.ndarray, face: np.ndarray,
                          bary: np.ndarray) -> np.ndarray:
    """``(..., k, 3)`` unit normals interpolated at ``bary (k, 3)`` on ``face (k,)``."""
    n = np.einsum("kj,...kjc->...kc", bary, normals[..., faces[face], :])
    length = np.linalg.norm(n, axis=-1, keepdims=True)
    return np.divide(n, length, out=np.zeros_like(n), where=length > 0)


def _bary_in_plane(points: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """``(k, 3)`` barycentric coordinates of the feet of ``points (k, 3)`` on the planes of
    ``tri (k, 3, 3)`` (unbounded: a foot outside its triangle gets a negative one; a degenerate
    triangle its centroid)."""
    return barycentric_in(points, tri, degenerate=(1.0 / 3.0, 1.0 / 3.0, 1.0 / 3.0))


def ring_choice(points, proxy_vertices, proxy_faces, point_vertex) -> np.ndarray:
    """``(n,) int64``: for each point the triangle, among those around its proxy vertex
    ``point_vertex (n,)`` (the vertex it was collapsed into), whose nearest point (barycentric
    coordinates of the foot, clamped into it) is closest; -1 where ``point_vertex`` is -1."""
    p = np.asarray(points, dtype=FLOAT).reshape(-1, 3)
    v = np.asarray(proxy_vertices, dtype=FLOAT)
    f = np.asarray(proxy_faces, dtype=INT)
    pv = np.asarray(point_vertex, INT)
    corner = f.ravel()
    order = np.argsort(corner, kind="stable")
    start = np.searchsorted(corner[order], np.arange(len(v) + 1))
    count = np.diff(start)
    out = np.full(len(p), -1, INT)
    has = np.flatnonzero((pv >= 0) & (count[np.maximum(pv, 0)] > 0))
    if not len(has):
        return out
    width = int(count[pv[has]].max())
    best = np.full(len(has), np.inf)
    for j in range(width):
        ok = count[pv[has]] > j
        cand = np.where(ok, order[np.minimum(start[pv[has]] + j, len(order) - 1)] // 3, 0)
        tri = v[f[cand]]
        b = _clamp_to_triangle(_bary_in_plane(p[has], tri))
        d = np.linalg.norm(np.einsum("kj,kjc->kc", b, tri) - p[has], axis=1)
        better = ok & (d < best)
        best[better] = d[better]
        out[has[better]] = cand[better]
    return out


def embed_points(points, proxy_vertices, proxy_faces, point_piece=None, face_piece=None,
                 point_vertex=None, normal_faces=None) -> Embedding:
    """Tie ``points (n, 3)`` to the proxy ``(proxy_vertices (k, 3), proxy_faces (l, 3))``.

    ``point_piece (n,)`` and ``face_piece (l,)`` (piece labels, or None: one piece) restrict
    each point to the triangles of its own piece; a point whose piece has no triangle (or
    label -1) searches them all. The triangle is the closest one; the foot then slides, on
    that triangle's plane, to where the interpolated normal through the point meets it.
    ``point_vertex (n,)`` (or None): the proxy vertex each point was collapsed into
    (:func:`faceforge.geometry.decimate.decimate_pieces`); a point with one takes a triangle
    around it (:func:`ring_choice`), not the nearest anywhere: a lip's vertex stays on its own
    lip where the other lip touches it. ``normal_faces``: the triangles the vertex normals are
    averaged over when :func:`carry` will see more than ``proxy_faces`` (default: these).
    Returns the :class:`Embedding`; :func:`carry` of the proxy's own vertices gives ``points``
    back to rounding.
    """
    from faceforge.geometry.closest import TriangleGrid

    p = np.asarray(points, dtype=FLOAT).reshape(-1, 3)
    v = np.asarray(proxy_vertices, dtype=FLOAT).reshape(-1, 3)
    f = np.asarray(proxy_faces, dtype=INT).reshape(-1, 3)
    pp = np.zeros(len(p), INT) if point_piece is None else np.asarray(point_piece, INT)
    fp = np.zeros(len(f), INT) if face_piece is None else np.asarray(face_piece, INT)
    face = np.full(len(p), -1, INT) if point_vertex is None else ring_choice(p, v, f, point_vertex)
    for piece in np.unique(pp):
        mine = np.flatnonzero(fp == piece)
        if piece < 0 or not len(mine):
            continue
        at = np.flatnonzero((pp == piece) & (face < 0))
        if len(at):
            face[at] = mine[TriangleGrid(v[f[mine]]).closest(p[at])[1]]
    rest = face < 0
    if rest.any():
        face[rest] = TriangleGrid(v[f]).closest(p[rest])[1]
    tri = v[f[face]]
    normals = area_vertex_normals(v, f if normal_faces is None else np.asarray(normal_faces, INT))
    bary = _clamp_to_triangle(_bary_in_plane(p, tri))   # the start: about the closest point's
    plane_n = triangle_frames(tri)[:, 2]
    a = tri[:, 0]
    for _ in range(FOOT_ROUNDS):
        n = _interpolated_normals(normals, f, face, bary)
        along = np.einsum("ij,ij->i", n, plane_n)
        t = np.where(np.abs(along) > 0.2, np.einsum("ij,ij->i", p - a, plane_n) / np.where(
            np.abs(along) > 0.2, along, 1.0), 0.0)
        bary = _clamp_to_triangle(_bary_in_plane(p - t[:, None] * n, tri))
    n = _interpolated_normals(normals, f, face, bary)
    foot = np.einsum("kj,kjc->kc", bary, tri)
    offset = np.einsum("ij,ij->i", p - foot, n)
    left = p - foot - offset[:, None] * n
    residual = np.einsum("kij,kj->ki", triangle_frames(tri), left)
    return Embedding(face, bary, offset, residual)


def _clamp_to_triangle(bary: np.ndarray) -> np.ndarray:
    """Barycentric coordinates pulled into the triangle (negatives to 0, renormalised)."""
    b = np.maximum(bary, 0.0)
    s = b.sum(axis=1, keepdims=True)
    return np.divide(b, s, out=np.full_like(b, 1.0 / 3.0), where=s > 0)


def carry(frames, proxy_faces, embedding: Embedding) -> np.ndarray:
    """The carried points ``(F, n, 3)`` (or ``(n, 3)`` for one frame) of proxy ``frames
    (F, k, 3)`` (or ``(k, 3)``), ``proxy_faces (l, 3)`` the ones :func:`embed_points` saw.
    Compiled (:func:`_carry_frame`, a frame at a time); :func:`carry_plain` is its numpy twin."""
    x = np.asarray(frames, dtype=FLOAT)
    one = x.ndim == 2
    x = x[None] if one else x
    f = np.ascontiguousarray(proxy_faces, dtype=INT)
    e = embedding
    out = np.empty((len(x), len(e.face), 3), FLOAT)
    normals = np.empty((x.shape[1], 3), FLOAT)
    face, bary = np.ascontiguousarray(e.face, INT), np.ascontiguousarray(e.bary, FLOAT)
    offset, residual = np.ascontiguousarray(e.offset, FLOAT), np.ascontiguousarray(e.residual, FLOAT)
    for i in range(len(x)):
        _carry_frame(np.ascontiguousarray(x[i]), f, face, bary, offset, residual, normals, out[i])
    return out[0] if one else out


@numba.njit(**NUMBA_OPTIONS)
def _carry_frame(x, f, face, bary, offset, residual, normals, out):  # pragma: no cover - numba
    """One frame of :func:`carry_plain`: area-weighted vertex normals of ``x (k, 3)`` over ``f``
    into ``normals (k, 3)``, then each point ``out[i]`` from its triangle ``face[i]`` (scalars
    only: no array is made in the loops)."""
    normals[:] = 0.0
    for t in range(f.shape[0]):
        a, b, c = f[t, 0], f[t, 1], f[t, 2]
        ex, ey, ez = x[b, 0] - x[a, 0], x[b, 1] - x[a, 1], x[b, 2] - x[a, 2]
        gx, gy, gz = x[c, 0] - x[a, 0], x[c, 1] - x[a, 1], x[c, 2] - x[a, 2]
        cx, cy, cz = ey * gz - ez * gy, ez * gx - ex * gz, ex * gy - ey * gx
        for k in range(3):
            normals[f[t, k], 0] += cx
            normals[f[t, k], 1] += cy
            normals[f[t, k], 2] += cz
    for v in range(normals.shape[0]):
        ln = np.sqrt(normals[v, 0] ** 2 + normals[v, 1] ** 2 + normals[v, 2] ** 2)
        if ln > 0.0:
            for k in range(3):
                normals[v, k] /= ln
    for i in range(face.shape[0]):
        a, b, c = f[face[i], 0], f[face[i], 1], f[face[i], 2]
        w0, w1, w2 = bary[i, 0], bary[i, 1], bary[i, 2]
        nx = w0 * normals[a, 0] + w1 * normals[b, 0] + w2 * normals[c, 0]
        ny = w0 * normals[a, 1] + w1 * normals[b, 1] + w2 * normals[c, 1]
        nz = w0 * normals[a, 2] + w1 * normals[b, 2] + w2 * normals[c, 2]
        ln = np.sqrt(nx * nx + ny * ny + nz * nz)
        if ln > 0.0:
            nx, ny, nz = nx / ln, ny / ln, nz / ln
        else:
            nx, ny, nz = 0.0, 0.0, 0.0
        ex, ey, ez = x[b, 0] - x[a, 0], x[b, 1] - x[a, 1], x[b, 2] - x[a, 2]
        gx, gy, gz = x[c, 0] - x[a, 0], x[c, 1] - x[a, 1], x[c, 2] - x[a, 2]
        fx, fy, fz = ey * gz - ez * gy, ez * gx - ex * gz, ex * gy - ey * gx
        le = np.sqrt(ex * ex + ey * ey + ez * ez)
        lf = np.sqrt(fx * fx + fy * fy + fz * fz)
        if le > 0.0 and lf > 0.0:
            ex, ey, ez, fx, fy, fz = ex / le, ey / le, ez / le, fx / lf, fy / lf, fz / lf
        else:
            ex, ey, ez, fx, fy, fz = 1.0, 0.0, 0.0, 0.0, 0.0, 1.0
        sx, sy, sz = fy * ez - fz * ey, fz * ex - fx * ez, fx * ey - fy * ex
        r0, r1, r2, d = residual[i, 0], residual[i, 1], residual[i, 2], offset[i]
        out[i, 0] = w0 * x[a, 0] + w1 * x[b, 0] + w2 * x[c, 0] + d * nx + r0 * ex + r1 * sx + r2 * fx
        out[i, 1] = w0 * x[a, 1] + w1 * x[b, 1] + w2 * x[c, 1] + d * ny + r0 * ey + r1 * sy + r2 * fy
        out[i, 2] = w0 * x[a, 2] + w1 * x[b, 2] + w2 * x[c, 2] + d * nz + r0 * ez + r1 * sz + r2 * fz


def carry_plain(frames, proxy_faces, embedding: Embedding) -> np.ndarray:
    """The numpy twin of :func:`carry` (the tests compare them)."""
    x = np.asarray(frames, dtype=FLOAT)
    one = x.ndim == 2
    x = x[None] if one else x
    f = np.asarray(proxy_faces, dtype=INT)
    e = embedding
    tri = x[:, f[e.face]]                                   # (F, n, 3, 3)
    normals = area_vertex_normals(x, f)
    n = _interpolated_normals(normals, f, e.face, e.bary)  # (F, n, 3)
    out = np.einsum("kj,Fkjc->Fkc", e.bary, tri) + e.offset[:, None] * n
    out += np.einsum("Fkic,ki->Fkc", triangle_frames(tri), e.residual)
    return out[0] if one else out


def working_corners(fit_faces, working_faces, n_fit: int, duplicate_source) -> np.ndarray:
    """``(l, 3)`` the corners, in the working mesh's vertex ids, of each proxy triangle of
    ``fit_faces (l, 3)``: bind's lip cut appends copies of lip vertices (``duplicate_source
    (c,)``: the fit vertex that working vertex ``n_fit + i`` copies) and rewires the lower
    lip's triangles to them, so a user vertex on the lower lip rides the copies, not the upper
    lip. A triangle bind removed (a bridge across the lips) keeps its fit corners. With no
    copies this is ``fit_faces`` itself."""
    ff = np.asarray(fit_faces, INT).reshape(-1, 3)
    src = np.asarray(duplicate_source, INT).reshape(-1)
    if not len(src):
        return ff
    wf = np.asarray(working_faces, INT).reshape(-1, 3)
    as_fit = np.concatenate([np.arange(int(n_fit), dtype=INT), src])[wf]
    key = {tuple(sorted(t)): i for i, t in enumerate(as_fit.tolist())}
    out = ff.copy()
    for k, t in enumerate(ff.tolist()):
        i = key.get(tuple(sorted(t)))
        if i is not None:   # the same corners in the working triangle's order (winding kept)
            out[k] = [wf[i][list(as_fit[i]).index(c)] for c in t]
    return out


def embed_off(embedding: Embedding, proxy_vertices, proxy_faces, removed_faces, anchor) -> Embedding:
    """``embedding`` with the points on any of ``removed_faces`` (proxy triangle ids: bind
    deletes a triangle bridging the lips) tied again to a kept triangle around their
    ``anchor (n,)`` proxy vertex (:func:`ring_choice`; the nearest kept one where none is
    around it), at their carried rest places: a bridge's points then move with one lip, not
    stretched across the opening mouth. Unchanged when no point is on a removed triangle."""
    removed = np.asarray(removed_faces, INT).reshape(-1)
    off = np.isin(embedding.face, removed)
    if not off.any():
        return embedding
    v = np.asarray(proxy_vertices, dtype=FLOAT)
    f = np.asarray(proxy_faces, dtype=INT)
    kept = np.setdiff1d(np.arange(len(f)), removed)
    points = carry(v, f, embedding.take(np.flatnonzero(off)))
    again = embed_points(points, v, f[kept], point_vertex=np.asarray(anchor, INT)[off], normal_faces=f)
    out = Embedding(embedding.face.copy(), embedding.bary.copy(), embedding.offset.copy(), embedding.residual.copy())
    at = np.flatnonzero(off)
    out.face[at], out.bary[at], out.offset[at], out.residual[at] = kept[again.face], again.bary, again.offset, \
        again.residual
    return out


def embed_apart(embedding: Embedding, points, proxy_vertices, proxy_faces, point_side, vertex_side,
                point_vertex=None, point_piece=None, face_piece=None) -> tuple[Embedding, int]:
    """``embedding`` of ``points (n, 3)`` (their rest places) with two sides kept apart.

    ``point_side (n,)`` and ``vertex_side (k,)`` (the proxy's vertices) label two regions
    that part in motion (+1 / -1; 0: neither, e.g. the lips and the cheeks around them): a
    point of side ``s`` whose triangle has a corner of side ``-s`` is tied again to a
    triangle with none (around its ``point_vertex`` first, :func:`ring_choice`, else the
    nearest such of its piece, :func:`embed_points`), so it moves with its own side only
    and not half with the other where they part. Returns ``(embedding, points re-tied)``;
    unchanged (the same object) when no point needs it.
    """
    p = np.asarray(points, dtype=FLOAT).reshape(-1, 3)
    v = np.asarray(proxy_vertices, dtype=FLOAT)
    f = np.asarray(proxy_faces, dtype=INT)
    ps = np.asarray(point_side).reshape(-1)
    vs = np.asarray(vertex_side)[f]
    out, moved = None, 0
    for s in (1, -1):
        banned = (vs == -s).any(axis=1)
        at = np.flatnonzero((ps == s) & banned[embedding.face])
        ok = np.flatnonzero(~banned)
        if not len(at) or not len(ok):
            continue
        if out is None:
            out = Embedding(embedding.face.copy(), embedding.bary.copy(), embedding.offset.copy(),
                            embedding.residual.copy())
        again = embed_points(p[at], v, f[ok], None if point_piece is None else np.asarray(point_piece)[at],
                             None if face_piece is None else np.asarray(face_piece)[ok],
                             point_vertex=None if point_vertex is None else np.asarray(point_vertex, INT)[at],
                             normal_faces=f)
        out.face[at], out.bary[at], out.offset[at], out.residual[at] = ok[again.face], again.bary, again.offset, \
            again.residual
        moved += len(at)
    return (embedding if out is None else out), moved
