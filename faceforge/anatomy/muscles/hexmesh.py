"""The template hexahedral muscle mesh (§5.1.2, Fig. 4) and its RBF morph.

Particles are laid out on an ``h x w`` grid, twice: the *bottom* sheet (the one
lying on the underlying structures) and the *top* sheet. Index ``i`` runs along
the fibres (``h`` longitudinal samples, from origin ``i = 0`` to insertion
``i = h - 1``), index ``j`` across them (``w`` latitudinal samples)::

    bottom(i, j) = i * w + j          top(i, j) = h * w + i * w + j

Each grid cell is split into two triangles on both sheets; the border of the
sheets is closed by side walls, so the surface is closed, triangulated and
consistently oriented with outward normals (positive signed volume).

A *linear* (sheet) muscle is a box: its bottom contour is the grid border,
``2 (h + w) - 4`` particles (the paper's ``2 (w + h)`` counts the four corners
twice, once per action line). A *sphincter* is periodic in ``i`` (the closed
loops A1, A3 of §5.2.2): an annulus whose bottom contour is the inner ring
``j = 0`` and the outer ring ``j = w - 1``, ``2 h`` particles, and whose
surface is a torus (no border walls, inner and outer walls instead).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from faceforge.constants import FLOAT, INT
from faceforge.geometry.rbf import hardy_rbf
from faceforge.geometry.triangles import check_mesh, vertex_normals

__all__ = ["HexTopology", "hex_topology", "cell_diagonals", "template_positions", "morph_hex", "signed_volume"]


@dataclass(frozen=True)
class HexTopology:
    """Connectivity of an ``h x w`` two-sheet muscle mesh.

    Attributes
    ----------
    h, w : int
        Samples along the fibres / across them.
    closed : bool
        Periodic along ``i`` (sphincter).
    faces : (m, 3) int64
        Closed, consistently oriented triangulation (orientation is outward for
        :func:`template_positions`; :func:`morph_hex` re-checks it).
    contour : (k,) int64
        Bottom particles bound to contour samples, in the order of
        :meth:`contour_grid` (see there).
    """

    h: int
    w: int
    closed: bool
    faces: np.ndarray
    contour: np.ndarray

    @property
    def n_particles(self) -> int:
        return 2 * self.h * self.w

    def bottom(self, i, j):
        """Particle index of bottom grid node(s) ``(i, j)``."""
        return np.asarray(i) * self.w + np.asarray(j)

    def top(self, i, j):
        """Particle index of top grid node(s) ``(i, j)``."""
        return self.h * self.w + np.asarray(i) * self.w + np.asarray(j)

    def contour_grid(self) -> np.ndarray:
        """``(k, 2)`` grid coordinates ``(i, j)`` of :attr:`contour`, in order.

        Linear: the border walked ``(0, 0) -> (0, w-1)`` (origin, A3), then
        ``(1..h-1, w-1)`` (fibre A2), ``(h-1, w-2..0)`` (insertion A1, reversed),
        ``(h-2..1, 0)`` (fibre A0, reversed). Sphincter: inner ring ``(0..h-1,
        0)`` then outer ring ``(0..h-1, w-1)``.
        """
        h, w = self.h, self.w
        if self.closed:
            i = np.arange(h)
            return np.concatenate([np.stack([i, np.zeros(h, INT)], 1), np.stack([i, np.full(h, w - 1)], 1)])
        walk = [(0, j) for j in range(w)]
        walk += [(i, w - 1) for i in range(1, h)]
        walk += [(h - 1, j) for j in range(w - 2, -1, -1)]
        walk += [(i, 0) for i in range(h - 2, 0, -1)]
        return np.asarray(walk, INT)


def _cells(h: int, w: int, closed: bool) -> tuple[np.ndarray, ...]:
    """Corners ``a, b, c, d`` (each ``(cells,)``) of the grid cells, ``(i, j), (i+1, j), (i+1, j+1), (i, j+1)``."""
    rows = h if closed else h - 1
    i, j = np.meshgrid(np.arange(rows), np.arange(w - 1), indexing="ij")
    i, j = i.ravel(), j.ravel()
    i1 = (i + 1) % h
    return i * w + j, i1 * w + j, i1 * w + j + 1, i * w + j + 1


def _sheet(h: int, w: int, closed: bool, flip=None) -> np.ndarray:
    """Bottom-sheet triangles, ``(2 cells, 3)``: cell ``k`` gives rows ``k`` and ``cells + k``.

    Each cell is split along ``(i, j)-(i+1, j+1)`` (``a-c``), or along ``b-d``
    where ``flip (cells,) bool`` is set (see :func:`cell_diagonals`).
    """
    a, b, c, d = _cells(h, w, closed)
    first, second = np.stack([a, b, c], 1), np.stack([a, c, d], 1)
    if flip is not None and np.any(flip):
        first[flip] = np.stack([a, b, d], 1)[flip]
        second[flip] = np.stack([b, c, d], 1)[flip]
    return np.concatenate([first, second]).astype(INT)


def cell_diagonals(h: int, w: int, closed: bool, bottom) -> np.ndarray:
    """Which cells of the bottom sheet ``bottom (h w, 3)`` to split along ``b-d``, ``(cells,) bool``.

    A cell is a quad ``a, b, c, d``; where it is not convex (a sphincter's cells at a
    sharp corner of its inner loop, a fan at a bunched contour) one diagonal runs
    outside it and one of its two triangles is turned over. Both splits are scored by
    the smaller signed area of their triangles about the cell's normal ``(c - a) x
    (d - b)`` (which does not depend on the split); the default ``a-c`` split is kept
    unless the ``b-d`` split's worse triangle is at least twice as large (so a convex
    cell never changes and the choice is stable under round-off).
    """
    p = np.asarray(bottom, dtype=FLOAT)
    a, b, c, d = (p[k] for k in _cells(h, w, closed))
    n = np.cross(c - a, d - b)

    def area(x, y, z):
        return np.einsum("ij,ij->i", np.cross(y - x, z - x), n)

    keep = np.minimum(area(a, b, c), area(a, c, d))
    alt = np.minimum(area(a, b, d), area(b, c, d))
    return (alt > 0.0) & (alt > 2.0 * keep)


def _faces(h: int, w: int, closed: bool, flip=None) -> np.ndarray:
    """Closed two-sheet surface: bottom sheet, top sheet (reversed), border walls, ``(m, 3)``."""
    n = h * w
    bottom = _sheet(h, w, closed, flip)
    top = bottom[:, ::-1] + n
    # border edges of the bottom sheet: directed edges without their reverse
    e = np.concatenate([bottom[:, [0, 1]], bottom[:, [1, 2]], bottom[:, [2, 0]]])
    key = e[:, 0] * n + e[:, 1]
    rkey = e[:, 1] * n + e[:, 0]
    border = e[~np.isin(key, rkey)]
    a, b = border[:, 0], border[:, 1]
    # wall quad (b, a, a', b') uses each border edge in the opposite direction
    walls = np.concatenate([np.stack([b, a, a + n], 1), np.stack([b, a + n, b + n], 1)])
    return np.concatenate([bottom, top, walls]).astype(INT)


def grid_layout(n_vertices: int, faces, closed: bool = True):
    """``(h, w)`` of a two-sheet muscle mesh of ``n_vertices`` laid out as :class:`HexTopology`
    (``bottom(i, j) = i w + j``, ``top(i, j) = h w + i w + j``), found from its ``faces (m, 3)``:
    with :func:`hex_topology`'s face count, the smallest ``w >= 2`` for which every face joins
    nodes at most one row (cyclically when ``closed``) and one column apart; None when no
    ``(h, w)`` fits (a mesh of another origin)."""
    f = np.asarray(faces, dtype=INT).reshape(-1, 3)
    half = n_vertices // 2
    # :func:`_faces` makes 4 h w triangles for a ring, 4 h w - 4 for a sheet
    if n_vertices % 2 or len(f) != 2 * n_vertices - (0 if closed else 4):
        return None
    node = f % half
    for w in range(2, half + 1):
        if half % w:
            continue
        h = half // w
        if h < (3 if closed else 2):
            continue
        row, col = node // w, node % w
        if closed:   # rows relative to the face's first: h - 1 is the row before
            row = (row - row[:, :1]) % h
            row = np.where(row == h - 1, -1, row)
        if (np.ptp(row, axis=1) <= 1).all() and (np.ptp(col, axis=1) <= 1).all():
            return h, w
    return None


def hex_topology(h: int, w: int, closed: bool = False) -> HexTopology:
    """Connectivity of the template mesh (Fig. 4), see :class:`HexTopology`."""
    if w < 2 or h < (3 if closed else 2):
        raise ValueError(f"muscle grid needs w >= 2 and h >= {3 if closed else 2}, got h={h}, w={w}")
    faces = _faces(h, w, closed)
    topo = HexTopology(h, w, closed, faces, np.zeros(0, INT))
    g = topo.contour_grid()
    contour = topo.bottom(g[:, 0], g[:, 1]).astype(INT)
    return HexTopology(h, w, closed, faces, contour)


def template_positions(topo: HexTopology, height: float = 1.0) -> np.ndarray:
    """Canonical rest pose of the template, ``(2 h w, 3) float64``.

    Linear: unit grid in the plane z = 0 (``x = j``, ``y = i``), top sheet at
    ``z = height``. Sphincter: annulus of radii ``1 + j`` at angle ``2 pi i / h``.
    The bottom sheet's outward normal points to -z.
    """
    h, w = topo.h, topo.w
    i, j = np.meshgrid(np.arange(h, dtype=FLOAT), np.arange(w, dtype=FLOAT), indexing="ij")
    if topo.closed:
        ang = 2.0 * np.pi * i / h
        r = 1.0 + j
        x, y = r * np.cos(ang), r * np.sin(ang)
    else:
        x, y = j, i
    bottom = np.stack([x.ravel(), y.ravel(), np.zeros(h * w)], 1)
    pos = np.concatenate([bottom, bottom + [0.0, 0.0, height]])
    return pos


def signed_volume(vertices, faces) -> float:
    """Signed volume enclosed by a closed triangle mesh (positive if outward)."""
    v, f = check_mesh(vertices, faces)
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def morph_hex(topo: HexTopology, samples, sample_normals, thickness: float, surface=None):
    """Morph the template onto the contour samples (§5.1.2) and give it thickness.

    1. A Hardy-multiquadric RBF (§4) maps the template's bottom contour onto the
       ``samples (k, 3)`` (in :attr:`HexTopology.contour` order) and its top
       contour onto ``samples + thickness * sample_normals``; the second set of
       correspondences makes the 3D map well posed (the bottom contour alone
       may be planar). The samples are met exactly.
    2. With ``surface = (vertices, faces)`` (the layer the contour lies on), the
       bottom vertices inside the contour are moved to their closest points on
       it: the RBF interpolates between the contour samples and would cut
       under a curved layer (chord sag) or float above it.
    3. The top sheet is then placed at ``bottom + thickness * n`` with ``n`` the
       bottom sheet's vertex normals (oriented like the sample normals; each cell
       split both ways, so they do not depend on its diagonal), which is the
       paper's "displace the upper surface along the normals".
    4. Cells that came out non-convex are split along their other diagonal
       (:func:`cell_diagonals`), so no sheet triangle starts turned over.
    5. If the morph mirrored the template, the faces are flipped so the
       returned mesh is outward oriented.

    Returns
    -------
    positions (2 h w, 3) float64, faces (m, 3) int64
    """
    s = np.asarray(samples, dtype=FLOAT)
    sn = np.asarray(sample_normals, dtype=FLOAT)
    if s.shape != (len(topo.contour), 3) or sn.shape != s.shape:
        raise ValueError(f"expected {len(topo.contour)} contour samples and normals, "
                         f"got {s.shape}, {sn.shape}")
    if not thickness > 0:
        raise ValueError(f"muscle thickness must be positive, got {thickness}")
    hw = topo.h * topo.w
    gap = np.linalg.norm(np.diff(np.vstack([s, s[:1]]), axis=0), axis=1).mean()
    tmpl = template_positions(topo, height=thickness / max(gap, 1e-300))
    src = np.concatenate([tmpl[topo.contour], tmpl[topo.contour + hw]])
    dst = np.concatenate([s, s + thickness * sn])
    G = hardy_rbf(src, dst)
    bottom = G(tmpl[:hw])
    bottom[topo.contour] = s  # exact (the RBF meets them to round-off)
    if surface is not None:
        from faceforge.geometry.surface_points import closest_points

        inner = np.setdiff1d(np.arange(hw), topo.contour)
        if len(inner):
            bottom[inner] = closest_points(bottom[inner], *surface)[0]
    flip = cell_diagonals(topo.h, topo.w, topo.closed, bottom)
    all_faces = _faces(topo.h, topo.w, topo.closed, flip) if flip.any() else topo.faces
    # normals of both splits of every cell summed: they do not depend on the diagonals, so a
    # muscle built on the mirror image of another's lines gets the mirror image of its top
    # (one diagonal for all cells made the top sheets of twins differ by up to 0.06 ES0, issue 25)
    n = sum(vertex_normals(bottom, _faces(topo.h, topo.w, topo.closed, np.full(len(flip), d))[: len(flip) * 2])
            for d in (False, True))
    n = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    # the bottom sheet faces point away from the top: its outward side is -n
    side = np.sign(np.sum(-n[topo.contour] * sn))
    side = 1.0 if side == 0 else side
    pos = np.concatenate([bottom, bottom - side * thickness * n])
    faces = all_faces
    if signed_volume(pos, faces) < 0:
        faces = faces[:, ::-1].copy()
    return pos, faces
