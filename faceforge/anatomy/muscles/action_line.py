"""Action lines (§5.1.1) and their regular sampling (§5.1.2 Eq. 3, §5.2.1 Eq. 4).

An action line is an ordered list of surface points on a triangulated layer
(the skull, a deeper muscle, or several of them concatenated into one mesh with
:func:`faceforge.geometry.triangles.concatenate_meshes`). It has no positions
of its own: :meth:`ActionLine.positions` and :meth:`ActionLine.normals`
evaluate the surface points on the layer's *current* vertices, so the line
follows the layer (Fig. 2).

Sampling (Eq. 3). An open line of arc length ``L`` sampled with ``n`` samples
uses ``step = L / (n - 1)`` so that the first and last samples are the line's
end points (the corners of the muscle contour); a closed line uses
``step = L / n`` (the sample after the last would be the first again). The
paper's Eq. 3 divides by N; we read N as the number of *intervals*, which is
what makes the contour corners shared by the latitudinal and longitudinal
lines. Eq. 4 scales the step, ``step' = step (1 - c)``: sample ``k`` sits at
arc length ``k step'`` from the line's first point (the origin), so for
``c > 0`` every sample slides toward the origin along the line itself.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from faceforge.constants import FLOAT, NUMBA_OPTIONS
from faceforge.geometry.surface_points import SurfacePoints, project_to_surface
from faceforge.geometry.triangles import check_mesh, vertex_normals

__all__ = ["ActionLine", "sample_polyline", "polyline_parameters", "eval_polyline", "sample_positions",
           "mean_edge_length",
           "project_outermost"]


def mean_edge_length(vertices, faces) -> float:
    """Mean length of the (directed, so each interior edge twice) triangle edges."""
    v, f = check_mesh(vertices, faces)
    e = v[f[:, [1, 2, 0]]] - v[f]
    return float(np.linalg.norm(e, axis=2).mean())


def polyline_parameters(points, n: int, closed: bool = False, step_scale: float = 1.0):
    """Where the regular samples of Eq. 3/4 fall: segment index and fraction.

    Returns ``(segment (n,) int64, t (n,) float64, arc (n,) float64)``: sample
    ``s`` lies at ``(1 - t) p[segment] + t p[segment + 1]`` (indices into the
    points with the first appended again for a closed line), at arc length
    ``arc[s] = s * step * step_scale`` from the first point, clipped to the
    line. See :func:`sample_polyline` for the arguments.
    """
    p = np.asarray(points, dtype=FLOAT)
    if closed:
        p = np.vstack([p, p[:1]])
    if len(p) < 2:
        raise ValueError("an action line needs at least two surface points")
    if n < (3 if closed else 2):
        raise ValueError(f"cannot sample {'a closed' if closed else 'an open'} line with {n} samples")
    seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    length = cum[-1]
    step = length / (n if closed else n - 1)
    arc = np.clip(np.arange(n) * step * float(step_scale), 0.0, length)
    k = np.clip(np.searchsorted(cum, arc, side="right") - 1, 0, len(seg) - 1)
    t = np.divide(arc - cum[k], seg[k], out=np.zeros_like(arc), where=seg[k] > 0)
    return k.astype(np.int64), np.clip(t, 0.0, 1.0), arc


def eval_polyline(points, normals, segment, t, closed: bool = False):
    """Positions (and unit normals, or None) at ``(segment, t)`` of :func:`polyline_parameters`."""
    p = np.asarray(points, dtype=FLOAT)
    nn = None if normals is None else np.asarray(normals, dtype=FLOAT)
    if closed:
        p = np.vstack([p, p[:1]])
        nn = None if nn is None else np.vstack([nn, nn[:1]])
    k = np.asarray(segment)
    tt = np.asarray(t, dtype=FLOAT)[:, None]
    pos = (1.0 - tt) * p[k] + tt * p[k + 1]
    if nn is None:
        return pos, None
    nrm = (1.0 - tt) * nn[k] + tt * nn[k + 1]
    length_n = np.linalg.norm(nrm, axis=1, keepdims=True)
    return pos, np.divide(nrm, length_n, out=np.zeros_like(nrm), where=length_n > 0)


@numba.njit(**NUMBA_OPTIONS)
def _polyline_samples(p, n, closed, scale, out):
    """Positions of :func:`sample_polyline` into ``out (n, 3)`` (no normals); compiled twin."""
    m = p.shape[0]
    segs = m if closed else m - 1
    total = 0.0
    for i in range(segs):
        j = (i + 1) % m
        total += math.sqrt((p[j, 0] - p[i, 0]) ** 2 + (p[j, 1] - p[i, 1]) ** 2 + (p[j, 2] - p[i, 2]) ** 2)
    step = total / (n if closed else n - 1)
    seg = 0
    cum = 0.0
    j = 1 % m
    seglen = math.sqrt((p[j, 0] - p[0, 0]) ** 2 + (p[j, 1] - p[0, 1]) ** 2 + (p[j, 2] - p[0, 2]) ** 2)
    for s in range(n):
        arc = min(max(s * step * scale, 0.0), total)
        while seg < segs - 1 and cum + seglen <= arc:
            cum += seglen
            seg += 1
            j = (seg + 1) % m
            seglen = math.sqrt((p[j, 0] - p[seg, 0]) ** 2 + (p[j, 1] - p[seg, 1]) ** 2
                               + (p[j, 2] - p[seg, 2]) ** 2)
        t = (arc - cum) / seglen if seglen > 0.0 else 0.0
        t = min(max(t, 0.0), 1.0)
        j = (seg + 1) % m
        for d in range(3):
            out[s, d] = (1.0 - t) * p[seg, d] + t * p[j, d]


def sample_polyline(points, normals, n: int, closed: bool = False, step_scale: float = 1.0):
    """Samples at a regular arc-length step along a polyline (Eq. 3, Eq. 4).

    Parameters
    ----------
    points, normals : (p, 3) float
        Polyline vertices and their unit normals (p >= 2; for ``closed`` the
        segment from the last point back to the first is included).
        ``normals=None`` skips the normals (None is returned for them).
    n : int
        Number of samples (>= 2 open, >= 3 closed).
    step_scale : float
        ``1 - c`` of Eq. 4; 1 samples the whole line, 0 puts every sample on
        the first point.

    Returns
    -------
    positions (n, 3), normals (n, 3), arc (n,) float64
        ``arc`` is each sample's arc length from the first point. Positions are
        the linear interpolation of the two end points of the segment holding
        the sample, the normal the same combination of their normals,
        normalized (§5.1.2).
    """
    k, t, arc = polyline_parameters(points, n, closed, step_scale)
    pos, nrm = eval_polyline(points, normals, k, t, closed)
    return pos, nrm, arc


def sample_positions(points, n: int, closed: bool = False, step_scale: float = 1.0) -> np.ndarray:
    """Fast path of :func:`sample_polyline` for positions only, ``(n, 3)`` (compiled)."""
    p = np.ascontiguousarray(points, dtype=FLOAT)
    if len(p) < 2 or n < (3 if closed else 2):
        return sample_polyline(p, None, n, closed, step_scale)[0]  # raises the ValueError
    out = np.empty((n, 3))
    _polyline_samples(p, int(n), bool(closed), float(step_scale), out)
    return out


def _smooth_along(n: np.ndarray, half: int, closed: bool) -> np.ndarray:
    """Moving average of the rows of ``n (p, 3)`` over ``2 half + 1`` neighbours, unit length."""
    if half <= 0 or len(n) < 3:
        return n
    k = np.arange(-half, half + 1)
    idx = np.arange(len(n))[:, None] + k[None, :]
    idx = idx % len(n) if closed else np.clip(idx, 0, len(n) - 1)
    s = n[idx].sum(axis=1)
    norm = np.linalg.norm(s, axis=1, keepdims=True)
    return np.where(norm > 0, s / np.maximum(norm, 1e-300), n)


def project_outermost(points, vertices, faces, reach: float = 0.05, closed: bool = False,
                      smooth: int = 2) -> SurfacePoints:
    """Surface points seen from outside along the local normal (see ActionLine.from_points).

    ``points (p, 3)`` are the consecutive points of one line (``closed`` for a loop);
    the ray directions are the closest points' oriented normals averaged over
    ``2 smooth + 1`` consecutive points, and a hit counts only within ``2 reach``
    (as a fraction of the layer's diagonal) of where the ray started, i.e. no farther
    than ``reach`` behind the point itself.
    """
    from faceforge.geometry.surface_points import projector
    from faceforge.geometry.triangles import barycentric, face_normals

    v, f = check_mesh(vertices, faces)
    p = np.asarray(points, dtype=FLOAT).reshape(-1, 3)
    proj = projector(v, f)   # shared by every line on this mesh, with its normals and centre
    near = proj.project(p)
    n = near.normals(v, f, proj.derived("vertex_normals", vertex_normals))
    # "outside" is away from the layer's centre: a deeper muscle's bottom sheet
    # touches the skull with the opposite normal, so orient n radially outward
    centre = proj.derived("centre", lambda v, f: v[np.unique(f)].mean(axis=0))
    flip = np.einsum("ij,ij->i", n, near.positions(v, f) - centre) < 0
    n[flip] *= -1.0
    # the points of one line are seen from one side: a point whose normal still
    # disagrees with the line's mean (the back of a thin bone) is turned around
    mean = n.sum(axis=0)
    if np.linalg.norm(mean) > 0:
        n[n @ mean < 0] *= -1.0
    # one line is seen from one side by rays that turn smoothly along it: a single
    # point's normal on a sharp edge (the border of a deeper muscle, the lower edge of
    # a bone) would otherwise send its ray across to another surface (a zigzag)
    n = _smooth_along(n, int(smooth), closed)
    r = reach * float(np.linalg.norm(v.max(axis=0) - v.min(axis=0)))
    ray, tri, loc, dist = proj.caster.all_hits(p + r * n, -n)
    # keep the first hit on a face turned toward the ray's origin: when the origin is
    # still inside a thin bone (the zygomatic arch), its back side is not a surface to lie on;
    # a hit more than ``reach`` beyond the point is another part of the head, not this point
    fn = proj.derived("face_normals", face_normals)[tri]
    front = (np.einsum("ij,ij->i", fn, n[ray]) > 0) & (dist >= 0) & (dist <= 2.0 * r)
    ray, tri, loc = ray[front], tri[front], loc[front]
    first = np.r_[True, ray[1:] != ray[:-1]] if len(ray) else np.zeros(0, bool)
    face = np.full(len(p), -1, dtype=np.int64)
    hit = np.full((len(p), 3), np.nan)
    face[ray[first]], hit[ray[first]] = tri[first], loc[first]
    ok = face >= 0
    if not ok.any():
        return near
    w = np.clip(barycentric(hit[ok], v, f, face[ok]), 0.0, None)
    w /= np.maximum(w.sum(axis=1, keepdims=True), 1e-300)
    ids = near.face_ids.copy()
    bary = near.bary.copy()
    ids[ok], bary[ok] = face[ok], w
    return SurfacePoints(ids, bary)


@dataclass(frozen=True)
class ActionLine:
    """Ordered surface points on one (possibly concatenated) layer mesh.

    Attributes
    ----------
    points : SurfacePoints
        The line's vertices in order, first = origin end.
    closed : bool
        True for the sphincter's loops (the last point connects to the first).
    """

    points: SurfacePoints
    closed: bool = False

    def __len__(self) -> int:
        return len(self.points)

    @classmethod
    def from_points(cls, points, vertices, faces, closed: bool = False, spacing: float | None = None,
                    project: str = "closest"):
        """Build a line through the 3D ``points (p, 3)`` that hugs the surface.

        Every straight segment between consecutive given points is subdivided
        so that no piece is longer than ``spacing`` (default: the layer's mean
        edge length, i.e. about one surface point per triangle crossed); all
        points are then projected onto the layer (closest point). Consecutive
        points that project onto the same spot are merged. The given points
        themselves are kept (projected), so the line's ends are the projections
        of the first and last given points.

        ``project``: "closest" takes the closest point of the layer; "outermost"
        (for layers stacked on each other, e.g. a muscle over the skull, whose
        surfaces nearly touch) finds the closest point's normal ``n``, turned
        to point away from the layer's centre (mean of its vertices: "outside"
        for a head) and then to agree with the mean of the line's normals (one
        line is seen from one side), casts a ray from ``p + r n`` along ``-n`` (``r`` = 5 % of
        the layer's bounding-box diagonal) and keeps the first hit on a face
        turned toward the ray (a back face means the ray started inside a thin
        bone), i.e. what an artist clicking on the layer from outside would
        pick; points whose ray finds no such face fall back to the closest point.
        """
        v, f = check_mesh(vertices, faces)
        p = np.asarray(points, dtype=FLOAT).reshape(-1, 3)
        if len(p) < 2:
            raise ValueError(f"an action line needs at least two points, got {len(p)}")
        if spacing is None:
            from faceforge.geometry.surface_points import projector

            spacing = projector(v, f).derived("mean_edge_length", mean_edge_length)
        ends = np.vstack([p, p[:1]]) if closed else p
        dense = [ends[0]]
        for a, b in zip(ends[:-1], ends[1:]):
            pieces = max(1, int(np.ceil(np.linalg.norm(b - a) / spacing)))
            t = np.arange(1, pieces + 1)[:, None] / pieces
            dense.extend(a + t * (b - a))
        dense = np.asarray(dense)
        if closed:
            dense = dense[:-1]
        if project == "closest":
            sp = project_to_surface(dense, v, f)
        elif project == "outermost":
            sp = project_outermost(dense, v, f, closed=closed)
        else:
            raise ValueError(f"project must be 'closest' or 'outermost', got {project!r}")
        pos = sp.positions(v, f)
        keep = np.r_[True, np.linalg.norm(np.diff(pos, axis=0), axis=1) > 1e-12 * max(spacing, 1e-300)]
        if closed and keep.sum() > 1 and np.linalg.norm(pos[-1] - pos[0]) <= 1e-12 * spacing:
            keep[-1] = False
        return cls(sp.take(np.flatnonzero(keep)), closed)

    def positions(self, vertices, faces) -> np.ndarray:
        """Current positions of the line's surface points, ``(p, 3)``."""
        return self.points.positions(vertices, faces)

    def normals(self, vertices, faces, vnormals=None) -> np.ndarray:
        """Current unit normals of the line's surface points, ``(p, 3)``."""
        return self.points.normals(vertices, faces, vnormals)

    def length(self, vertices, faces) -> float:
        """Current arc length (including the closing segment of a closed line)."""
        p = self.positions(vertices, faces)
        if self.closed:
            p = np.vstack([p, p[:1]])
        return float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())

    def sample(self, vertices, faces, n: int, step_scale: float = 1.0, vnormals=None,
               with_normals: bool = True):
        """``n`` samples at a regular step (Eq. 3) scaled by ``step_scale = 1 - c`` (Eq. 4).

        Returns ``positions (n, 3), normals (n, 3)`` on the current layer
        ``(vertices, faces)``; see :func:`sample_polyline`. With
        ``with_normals=False`` the normals (and the vertex normals they need)
        are skipped and None is returned in their place.
        """
        v, f = check_mesh(vertices, faces)
        nrm = None
        if with_normals:
            vn = vertex_normals(v, f) if vnormals is None else vnormals
            nrm = self.normals(v, f, vn)
        pos, nrm, _ = sample_polyline(self.positions(v, f), nrm, n, self.closed, step_scale)
        return pos, nrm

    def parameters(self, vertices, faces, n: int, step_scale: float = 1.0):
        """``(segment, t)`` of the ``n`` regular samples on the current layer (Eq. 3, 4)."""
        k, t, _ = polyline_parameters(self.positions(vertices, faces), n, self.closed, step_scale)
        return k, t

    def sample_at(self, vertices, faces, segment, t) -> np.ndarray:
        """Positions ``(n, 3)`` at fixed ``(segment, t)`` parameters (material sampling)."""
        return eval_polyline(self.positions(vertices, faces), None, segment, t, self.closed)[0]
