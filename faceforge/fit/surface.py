"""The skin as the fit sees it (§7): outward winding, holes closed virtually, normals, and
the queries the fit asks of it (depth beneath the skin, the front region, inside a closed mesh)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from faceforge.anatomy import tissue as fit_tissue
from faceforge.geometry.rays import RayCaster
from faceforge.geometry.triangles import smooth_vertex_normals, vertex_normals


@dataclass
class SkinSurface:
    """The skin with what the fit queries repeatedly.

    vertices (n, 3) float64, faces (m, 3) int64 with outward winding, normals (n, 3) unit
    area-weighted vertex normals, diagonal float (bounding-box diagonal, mesh units).
    """

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray
    diagonal: float
    caster: RayCaster
    boundary_vertices: np.ndarray
    n_real: int = -1                 # vertices [0, n_real) are the skin's own; the rest are fan centres

    @classmethod
    def build(cls, vertices, faces, close_holes: bool = True, normal_rounds: int = 0) -> "SkinSurface":
        """The skin as the fit sees it: outward winding, and with ``close_holes`` every hole
        but the longest (eyes, the mouth behind the lips, not the neck or a mask's rim)
        closed virtually by a fan, as an eyeball or closed lips would. Only the largest
        connected piece is the skin (iris points, eyeballs are left out). Fan centres are
        appended after the skin's own vertices. ``normal_rounds`` (``fit.normal_rounds``): the
        normals averaged over neighbours that many times
        (:func:`faceforge.geometry.triangles.smooth_vertex_normals`), so a scan's noise does not
        tilt the tissue depths, the enhancement rays and the inside test."""
        from faceforge.io.mesh_check import edge_face_counts, fill_holes

        from faceforge.io.mesh_check import largest_component

        v = np.asarray(vertices, dtype=np.float64)
        n_real = len(v)
        f = largest_component(np.asarray(faces, dtype=np.int64), len(v))
        if close_holes:
            v, f, _ = fill_holes(v, f, keep_open=1)
        f = orient_outward(v, f)
        edges, counts = edge_face_counts(f)
        bnd = np.unique(edges[counts == 1])
        return cls(v, f, smooth_vertex_normals(v, f, normal_rounds), float(np.linalg.norm(np.ptp(v, axis=0))),
                   RayCaster(v, f), bnd, n_real)

    def closest(self, points: np.ndarray):
        """Closest skin points ``(closest (q, 3), distance (q,), face_ids (q,))`` (exact;
        :class:`faceforge.geometry.closest.TriangleGrid`, built once per skin)."""
        from faceforge.geometry.surface_points import SurfaceProjector

        if getattr(self, "_projector", None) is None:
            self._projector = SurfaceProjector(self.vertices, self.faces)
        return self._projector.closest(np.asarray(points, dtype=np.float64).reshape(-1, 3))

    def normal_near(self, points: np.ndarray) -> np.ndarray:
        """Unit smooth skin normals (k, 3) at the closest skin points of ``points`` (k, 3)."""
        from faceforge.geometry.triangles import barycentric

        closest, _, tri = self.closest(points)
        return self.normals_at(tri, barycentric(closest, self.vertices, self.faces, tri))

    def normals_at(self, face_ids, bary) -> np.ndarray:
        """Unit smooth normals (k, 3) at surface points given by face ids and barycentrics."""
        n = np.einsum("ki,kij->kj", bary, self.normals[self.faces[face_ids]])
        return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)


def orient_outward(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Faces (m, 3) wound so that normals point out of the face (+Z side of the head).

    The face looks along +Z: the area-weighted mean normal of the front half (faces whose
    centroid lies in front of the median z) must point along +Z; otherwise every face is
    flipped. Assumes a consistently wound mesh.
    """
    tri = vertices[faces]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    cz = tri[:, :, 2].mean(axis=1)
    front = cz >= np.median(cz)
    return faces if cross[front, 2].sum() >= 0 else faces[:, ::-1].copy()


def outer_vertices(vertices: np.ndarray, faces: np.ndarray, caster: RayCaster | None = None) -> np.ndarray:
    """Bool (n,): the ray from a vertex along its normal leaves the mesh without hitting it.

    The start is nudged along the normal by 1e-4 of the diagonal to skip its own faces.
    """
    caster = caster or RayCaster(vertices, faces)
    n = vertex_normals(vertices, faces)
    eps = 1e-4 * float(np.linalg.norm(np.ptp(vertices, axis=0)))
    face, _, _ = caster.first_hit(vertices + eps * n, n)
    return face < 0


def signed_skin_depth(points: np.ndarray, skin: SkinSurface):
    """How deep points (k, 3) lie beneath the skin, by their closest skin point.

    Returns ``(depth (k,), closest (k, 3), normal (k, 3), covered (k,) bool, pocket (k,) bool)``.
    ``depth`` is the distance to the closest skin point, positive when the point lies on
    the inner side of the skin there (smooth normal, interpolated area-weighted vertex
    normals). A point on the outer side whose ray along that outward normal meets the skin
    again lies in a *pocket* the skin wraps around (a modelled mouth cavity or eye socket,
    where teeth and orbits belong): ``pocket`` is true and ``depth`` 0. A point whose
    closest skin point lies on the skin's open boundary (beyond a mask's rim, below the
    neck) is not ``covered``.
    """
    from faceforge.geometry.triangles import barycentric

    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    k = len(points)
    if k == 0:
        z = np.zeros((0, 3))
        return np.zeros(0), z, z, np.zeros(0, bool), np.zeros(0, bool)
    closest, dist, tri = skin.closest(points)
    bary = barycentric(closest, skin.vertices, skin.faces, tri)
    normal = skin.normals_at(tri, bary)
    sign = np.where(np.einsum("ij,ij->i", normal, closest - points) >= 0, 1.0, -1.0)
    covered = np.ones(k, bool)
    if len(skin.boundary_vertices):
        on_bnd = np.isin(skin.faces[tri], skin.boundary_vertices)
        covered = (on_bnd * bary).sum(axis=1) <= 0.999
    pocket = np.zeros(k, bool)
    out = np.flatnonzero(sign < 0)
    if len(out):
        face, _, _ = skin.caster.first_hit(points[out] + 1e-6 * skin.diagonal * normal[out], normal[out])
        pocket[out[face >= 0]] = True
    depth = np.where(pocket, 0.0, sign * dist)
    return depth, closest, normal, covered, pocket


def front_mask(points: np.ndarray, skin_landmarks: dict, offset_es0: float) -> np.ndarray:
    """Bool (n,): in front (+Z) of the coronal plane ``offset_es0`` ES0 behind the outer eye corners."""
    z0 = 0.5 * (skin_landmarks["3.7"][2] + skin_landmarks["3.12"][2])
    return points[:, 2] > z0 - offset_es0 * fit_tissue.es0(skin_landmarks)


def inside_closed(vertices: np.ndarray, faces: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Bool (k,): points inside the closed mesh by ray parity along two fixed directions
    (both must agree, so a ray grazing an edge cannot flip a point). Deterministic."""
    caster = RayCaster(vertices, faces)
    inside = np.ones(len(points), bool)
    for d in ([0.3129, 0.6214, 0.7183], [-0.5773, 0.2151, -0.7877]):
        ray, _, _, dist = caster.all_hits(points, np.asarray(d, dtype=np.float64)[None])
        counts = np.bincount(ray[dist > 0], minlength=len(points))
        inside &= counts % 2 == 1
    return inside
