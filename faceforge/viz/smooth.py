"""Smooth-shaded renders and displacement heat maps for the contact sheets.

The flat painter's renderer (:mod:`faceforge.viz.render`) gives each triangle one colour, so
a dense face reads as facets and a crease is hard to tell from a triangle edge. Here the mesh is
drawn through a z-buffer (:mod:`faceforge.viz.zbuffer`): each pixel shows the nearest surface,
lit with the area-weighted vertex normals (:func:`faceforge.geometry.triangles.vertex_normals`)
interpolated across the triangle. A heat map colours each pixel by the interpolated displacement
from a reference pose instead. Where the mesh has a hole one can see through (a face mask's
mouth, a mesh without a mouth bag), the hole is drawn dark as a cavity would look
(:func:`fill_holes`), not the page's white.
"""

from __future__ import annotations

import numpy as np

from faceforge.viz.render import LIGHT, view_matrix

#: skin tone at full light; the shade scales it
SKIN = np.array([0.93, 0.86, 0.78])
#: sweeps of :func:`faceforge.geometry.triangles.smooth_field` over the mouth's cavity field (its edge a ramp 2-3 edges wide)
SOFTEN = 3
#: hidden vertices deeper than this (mm behind the inner lip line) stay fully in the cavity: the
#: softening is for the rolled-in lips, where hidden and seen vertices meet
DEEP_MM = 10.0
#: what a hole in the mesh shows (the cavity's shade: :func:`draw_smooth`'s darkest, 0.15 of the skin)
HOLE = tuple(0.15 * SKIN)


def _project(vertices, faces, view: str):
    """Camera coordinates (n, 3) and the triangles (k, 3) of non-zero area."""
    v = np.asarray(vertices, dtype=float) @ view_matrix(view).T
    f = np.asarray(faces, dtype=np.int64)
    t = v[f]
    n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    return v, f[np.linalg.norm(n, axis=1) > 0.0]


def fill_holes(ax, xy: np.ndarray, faces: np.ndarray, colour=HOLE, clip=None, loops=None) -> None:
    """Fill every boundary loop of ``faces`` (m, 3) at the projected vertices ``xy`` (n, >= 2) in
    ``colour``, under the mesh (zorder 0), clipped to the patch ``clip`` when given; ``loops``
    (:func:`faceforge.io.mesh_check.boundary_loops` of ``faces``) saves finding them again. A
    surface covers the inside of its own boundary's picture (the image of a disc covers every
    point its rim winds round), so the fills show only where the mesh has a hole one can see
    through: a mask's mouth, an eye opening with nothing behind it."""
    from faceforge.io.mesh_check import boundary_loops

    for loop in boundary_loops(np.asarray(faces, dtype=np.int64)) if loops is None else loops:
        if len(loop) >= 3:
            for patch in ax.fill(xy[loop, 0], xy[loop, 1], color=colour, lw=0, zorder=0):
                if clip is not None:
                    patch.set_clip_path(clip)


def draw_smooth(ax, vertices: np.ndarray, faces: np.ndarray, view: str = "front",
                ambient: float = 0.3, dim: np.ndarray | None = None, box=None, px: int | None = None) -> None:
    """Draw the mesh ``vertices (n, 3)``, ``faces (m, 3)`` smooth-shaded into ``ax`` through a
    z-buffer (:mod:`faceforge.viz.zbuffer`: the vertex normals interpolated and lit at each pixel);
    ``dim`` (n,) in [0, 1] darkens vertices (the mouth's cavity, :func:`mouth_cavity`, which a lamp
    in front would light like the skin): the light times ``1 - 0.85 dim``, interpolated like the
    normals. ``box = (lo (2,), hi (2,))``: the part of the view to draw (camera x, y; default the
    whole mesh), ``px`` its pixels a side (default :data:`faceforge.viz.zbuffer.PX`)."""
    from faceforge.viz.zbuffer import PX, shade, show

    v, f = _project(vertices, faces, view)
    fill_holes(ax, v, faces)
    light, face_id, extent = shade(v, f, _box(v, box), px or PX, LIGHT, ambient, dim)
    show(ax, light[:, :, None] * SKIN, face_id, extent)


def _box(v: np.ndarray, box):
    """The part of the view to draw: ``box`` as given, else the projected mesh's extent."""
    return (v[:, :2].min(axis=0), v[:, :2].max(axis=0)) if box is None else box


def mouth_cavity(rest: np.ndarray, faces: np.ndarray, inner_upper, inner_lower, corners, outer,
                 mm: float, soften: int = SOFTEN) -> np.ndarray:
    """(n,) in [0, 1]: how deep inside the mouth each vertex of ``rest`` (n, 3) lies, from the
    rest geometry, ``faces`` (m, 3): the vertices of the mouth's box (x between the ``corners``
    (2, 3) widened by 10 %, y within 15 mm of the inner lip line, FDP 2.2 / 2.3, points (3,))
    hidden at rest behind the skin (a ray toward the front, straight or tilted 20 degrees up or
    down, meets the skin: a straight one can escape along the closed lips' seam; or most of its
    neighbours (half) are hidden), 0 at the inner
    lip line rising to 1 at 0.5 mm behind it; ``mm`` skin units per mm. +Z is the face's front.
    The tilted rays count only within the outer lip contour (``outer`` (2, 3): FDP 8.1, 8.2)
    +- 2 mm, so that the hollow under the lower lip (a tilted ray meets the lip) stays skin; a
    straight one counts over the whole box (a mouth bag's walls above and below the lips). The
    field is then softened ``soften`` times over the mesh's edges (:func:`faceforge.geometry.triangles.smooth_field`): the hidden set is
    decided a vertex at a time, and a fine mesh's rolled-in lips mix hidden and seen vertices,
    whose edge drawn as is traced a ragged outline round an opened mouth; hidden vertices more
    than :data:`DEEP_MM` behind the inner lip line keep their full depth (a coarse mouth bag's
    or head's inside, a band of a row or two, would fade)."""
    from faceforge.geometry.triangles import smooth_field

    rest = np.asarray(rest, dtype=float)
    corners = np.asarray(corners, dtype=float)
    mid_x, half = corners[:, 0].mean(), 0.55 * abs(corners[0, 0] - corners[1, 0])
    y0 = 0.5 * (inner_upper[1] + inner_lower[1])
    outer = np.asarray(outer, dtype=float)
    z0 = max(inner_upper[2], inner_lower[2])
    box = (np.abs(rest[:, 0] - mid_x) < half) & (np.abs(rest[:, 1] - y0) < 15.0 * mm)
    lo, hi = min(outer[0][1], outer[1][1]) - 2.0 * mm, max(outer[0][1], outer[1][1]) + 2.0 * mm
    cand = np.flatnonzero(box & (rest[:, 2] < z0 - 0.1 * mm))
    band = (rest[cand, 1] > lo) & (rest[cand, 1] < hi)
    mesh_faces = np.asarray(faces, dtype=np.int64)
    faces = mesh_faces[np.all(box[mesh_faces], axis=1)]     # the box's triangles (all 3 in it)
    hits = np.zeros(len(cand), dtype=int)
    for tilt in (0.0, 0.36, -0.36):                          # rays (0, tilt, 1)
        p = np.column_stack([rest[:, 0], rest[:, 1] - tilt * rest[:, 2], rest[:, 2]])
        seen = _hidden(p, faces, cand, 0.5 * mm)
        hits += seen if tilt == 0.0 else seen & band
    out = np.zeros(len(rest))
    hidden = np.zeros(len(rest), dtype=bool)
    hidden[cand[hits >= 1]] = True
    # a candidate most of whose neighbours are hidden is too (a ray can slip through a seam)
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    votes, count = np.zeros(len(rest)), np.zeros(len(rest))
    for a, b in ((edges[:, 0], edges[:, 1]), (edges[:, 1], edges[:, 0])):
        np.add.at(votes, a, hidden[b])
        np.add.at(count, a, 1.0)
    hidden[cand[votes[cand] >= 0.5 * count[cand]]] = True
    inside = np.flatnonzero(hidden)
    out[inside] = np.clip((z0 - rest[inside, 2]) / (0.5 * mm), 0.0, 1.0)
    soft = smooth_field(out, mesh_faces, soften)
    # deep inside (a bag's walls, the head's inside): whole, with the deep vertices just outside
    # the box that share a triangle with them (a coarse mesh's long triangles cross the box)
    far = rest[:, 2] < z0 - DEEP_MM * mm
    deep = np.zeros(len(rest), dtype=bool)
    deep[inside] = far[inside]
    touching = mesh_faces[deep[mesh_faces].any(axis=1)].ravel()
    deep[touching[far[touching] & ~box[touching]]] = True
    soft[deep] = 1.0
    return soft
    avg = neighbour_average(len(out), faces)
    for _ in range(passes):
        out = 0.5 * (out + avg @ out)
    return out


def _hidden(p: np.ndarray, faces: np.ndarray, cand: np.ndarray, eps: float) -> np.ndarray:
    """(len(cand),) bool: a ray from ``p[cand]`` toward +Z meets a triangle ``faces`` of ``p``
    (n, 3) more than ``eps`` in front of it (a few hundred points and triangles: plain numpy)."""
    tri = p[faces]
    a, e1, e2 = tri[:, 0, :2], tri[:, 1, :2] - tri[:, 0, :2], tri[:, 2, :2] - tri[:, 0, :2]
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    ok = np.abs(det) > 1e-18
    a, e1, e2, det, tri = a[ok], e1[ok], e2[ok], det[ok], tri[ok]
    out = np.zeros(len(cand), dtype=bool)
    for j, i in enumerate(cand):
        d = p[i, :2] - a
        u = (d[:, 0] * e2[:, 1] - d[:, 1] * e2[:, 0]) / det
        v = (e1[:, 0] * d[:, 1] - e1[:, 1] * d[:, 0]) / det
        k = (u >= 0) & (v >= 0) & (u + v <= 1)
        z = tri[k, 0, 2] * (1 - u[k] - v[k]) + tri[k, 1, 2] * u[k] + tri[k, 2, 2] * v[k]
        out[j] = bool(np.any(z > p[i, 2] + eps))
    return out


def draw_heat(ax, vertices: np.ndarray, rest: np.ndarray, faces: np.ndarray, scale: float,
              view: str = "front", cmap: str = "inferno", box=None, px: int | None = None):
    """Draw the mesh at ``vertices`` coloured by each vertex's distance from ``rest`` (n, 3),
    ``scale`` (same units) the top of the colour scale, through a z-buffer as :func:`draw_smooth`
    (``box``, ``px`` as there). Returns a mappable of the scale (for a colour bar)."""
    import matplotlib.cm
    from matplotlib.colors import Normalize

    from faceforge.viz.zbuffer import PX, interpolate, panel_buffers, show

    v, f = _project(vertices, faces, view)
    d = np.linalg.norm(np.asarray(vertices, float) - np.asarray(rest, float), axis=1)
    fill_holes(ax, v, faces)
    face_id, bary, extent = panel_buffers(v, f, _box(v, box), px or PX)
    mappable = matplotlib.cm.ScalarMappable(Normalize(0.0, max(float(scale), 1e-30)), cmap)
    heat = interpolate(d[:, None], f, face_id, bary)[:, :, 0]
    show(ax, mappable.to_rgba(heat)[:, :, :3], face_id, extent)
    return mappable
