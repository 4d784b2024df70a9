"""Fit the template skull and muscle map into a skin mesh (§7, Fig. 8).

Functions on arrays. The construction, in order:

1. **Targets.** For each FDP present on both the skull template and the skin, the skin
   landmark is moved inward along the skin normal by the published soft-tissue depth
   beneath it (:mod:`faceforge.anatomy.fit_tissue`, scaled by ES0). FDPs without bone
   beneath them (nose tip, inner lips, pupils, ears) are not skull targets.
2. **Initial alignment.** A similarity transform (scale, rotation, translation; Umeyama
   1991 least squares) takes the skull landmarks onto the targets, so heads in any unit
   and a moderately rotated pose fit.
3. **Hardy multiquadric RBF** (§4, :func:`faceforge.geometry.rbf.hardy_rbf`) from the
   aligned skull landmarks to the targets; exact at the landmarks.
4. **Enhancement landmarks** (red dots of Fig. 8). Candidate points are the outer-surface
   vertices (one per ``enhancement_cell`` grid cell) of the morphed skull in front of the
   ears (a vertex is *outer* when a ray along its normal leaves the skull without hitting
   it again) that face the skin (their normal within ~70 degrees of the skin normal at
   their closest skin point: this leaves out the back of the teeth and the inside of the
   jaw). The signed depth ``D`` beneath
   the closest skin point (:func:`signed_skin_depth`; negative when the bone pokes
   through) is compared with the expected depth ``t*`` (Shepard interpolation of the
   landmark depths); where ``D < enhancement_min_ratio * t*`` the vertex is *bad*.
   Up to ``enhancement_samples`` bad vertices are taken, worst first, each at least
   ``enhancement_spacing`` apart from the others and from every existing source; each
   pair (skull point -> closest skin point - ``t*`` along the skin normal) is a ray from
   the skin inward to the bone (the red dots of Fig. 8); ``enhancement_rounds`` rounds or
   until nothing is bad. With ``enhancement_flow_steps`` > 0 (the default, 8) each round's pairs are met by a
   *flow* (:func:`enhancement_field`, :class:`Flow`): a smooth displacement field, zero at
   every earlier pair's target (the FDP landmarks lie on theirs, exactly) and the correction
   at each new pair, integrated in that many midpoint steps. A flow is one-to-one in the
   continuum, so it does not turn the bone over the way the exact RBF through a close-spaced
   enhancement pair and an FDP landmark does (only triangles larger than the field's
   detail still can): on MakeHuman the whole fit turns over 250 cranium and 64 mandible
   triangles with the exact RBF, 140 and 10 with the flow (of which 40 and 0 already come
   from the FDP RBF). A flow moves each new pair most of the way to its target (~70 %), not
   onto it, and stops short of a landmark in its way; enhancement targets are a depth
   ratio, and the next round tests again. With 0 the RBF through all pairs is rebuilt each
   round with the landmarks' shape parameter (the paper's construction; it can also run
   away: with a template whose teeth sit at the lips, one round moved the inside of
   MediaPipe's orbit by 40 % of the skin diagonal).
   Points in pockets (teeth in a modelled mouth) and points no skin covers (beyond a
   mask's rim, below the neck) are left alone: the back need not fit (§7). The other way
   round, skin of the face that the bone swallows (a deep modelled eye socket, a nostril
   reaching into the nasal aperture) adds pairs that push the nearest bone vertex along
   its normal until the skin is ``skin_clearance_mm`` outside
   (:func:`skin_inside_bone_pairs`). Template
   landmarks the skin cannot place and that lie far from every target (a face mask has
   no skull top, back or jaw angles) are *anchors*: held where the similarity puts them,
   so the RBF does not extrapolate the back of the skull.
5. **Muscles** (:mod:`faceforge.anatomy.fit_muscles`): the muscles (built on the template
   skull) are morphed by the same map, thickness rescaled by Eq. 5; skull landmarks
   covered by muscles are brought onto the muscle surface by cylindrical projection and
   the fit is run again (the refit), so the muscles lie at least ``muscle_gap_mm``
   beneath the skin there. Before that, with ``mouth_follows_lips`` (experimental, off by
   default), the muscle map (not the skull) around the mouth is shifted so that the lips'
   bone counterparts come in front of the skin's lips (:mod:`faceforge.anatomy.fit_mouth`):
   the lips are no skull targets, and the orbicularis oris otherwise lands where the
   template's mouth sits on its teeth.
6. **Eye sockets** (:mod:`faceforge.anatomy.fit_orbits`): where the skin models the closed
   eye socket (a pocket behind the lids), the bone inside the pocket moves out along rays
   from the pocket's centre, by a one-to-one map that cannot fold the thin orbital walls
   (pushing single bone vertices out does). Heads without a socket are left alone.
7. **Clearance** (:mod:`faceforge.anatomy.fit_clearance`): where the bone still swallows
   skin, it gives way locally (compact bumps of ``clearance_radius``, each pushing the
   closest bone point to ``skin_clearance_mm`` beneath the skin vertex; the bumps sit on the
   corners of the closest face of the bones' common outer surface) until no skin vertex is
   inside or ``clearance_rounds`` is reached; the muscles, landmarks and axes move with it.

The map is kept as a composition of callables (similarity, RBF, enhancement flows, refit
RBF, orbit maps, clearance fields) and is applied to every template point: cranium, mandible, landmarks,
muscle-map points and the jaw axes' points; the axes' directions turn with the best rotation of the whole
mandible (the jaw is one rigid body).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from faceforge.anatomy import fit_tissue
from faceforge.geometry.rbf import hardy_epsilon, hardy_rbf
from faceforge.geometry.rays import RayCaster
from faceforge.geometry.triangles import vertex_normals


@dataclass(frozen=True)
class FitSettings:
    """Parameters of the fit (config section ``fit``)."""

    tissue_depth: bool = True          # move skin targets inward by tissue depth
    enhancement_rays: bool = True      # add ray-cast enhancement landmarks
    refit: bool = True                 # cylindrical projection onto muscles and second fit
    enhancement_rounds: int = 3
    enhancement_samples: int = 48      # new pairs considered per round
    enhancement_spacing: float = 0.035  # min distance between RBF sources, fraction of skin diagonal
    enhancement_min_ratio: float = 0.7  # add a pair where thickness < ratio * expected depth
    enhancement_cell: float = 0.015    # candidates: one skull vertex per cell of this size (x skin diagonal)
    enhancement_flow_steps: int = 8    # >0: each enhancement round is a flow of this many midpoint steps; 0: exact RBF
    skin_clearance_mm: float = 1.0     # skin found inside the bone is cleared by this much (mm); 0: off
    skin_clearance_samples: int = 16   # bone pairs per round for skin inside the bone
    front_offset_es0: float = 0.75     # front region: in front of eye corners minus this * ES0
    muscle_gap_mm: float = 1.5         # skin tissue kept above the muscle top at landmarks (mm)
    clearance_radius: float = 0.03     # bone bends around skin it swallowed within this (x skin diagonal)
    clearance_rounds: int = 6          # at most this many bump fields (fit_clearance)
    orbit_hollow: bool = True          # clear bone out of modelled eye sockets (fit_orbits)
    orbit_blend: float = 0.5           # the orbit map fades out over this fraction of the socket radius
    mouth_follows_lips: bool = False   # the muscle map around the mouth follows the skin's lips (fit_mouth)

    @classmethod
    def from_config(cls, cfg: dict | None) -> "FitSettings":
        """From the config's ``fit`` section (validated against configs/default.yaml)."""
        cfg = dict(cfg or {})
        kernel = cfg.pop("rbf_kernel", "multiquadric")
        if kernel != "multiquadric":
            from faceforge.exceptions import ConfigError

            raise ConfigError(f"fit.rbf_kernel: only 'multiquadric' (Hardy, §4) is implemented, got {kernel!r}")
        known = {k: v for k, v in cfg.items() if k in cls.__dataclass_fields__}
        return cls(**known)


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
    def build(cls, vertices, faces, close_holes: bool = True) -> "SkinSurface":
        """The skin as the fit sees it: outward winding, and with ``close_holes`` every hole
        but the longest (eyes, the mouth behind the lips, not the neck or a mask's rim)
        closed virtually by a fan, as an eyeball or closed lips would. Only the largest
        connected piece is the skin (iris points, eyeballs are left out). Fan centres are
        appended after the skin's own vertices."""
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
        return cls(v, f, vertex_normals(v, f), float(np.linalg.norm(np.ptp(v, axis=0))), RayCaster(v, f), bnd,
                   n_real)

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


# ----------------------------------------------------------------------------- alignment


def similarity_transform(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Least-squares similarity (4, 4) with ``dst ~ s R src + t`` (Umeyama 1991).

    src, dst : (n, 3) float, n >= 3 corresponding points. R is a proper rotation.
    """
    src = np.asarray(src, dtype=np.float64)
    dst = np.asarray(dst, dtype=np.float64)
    if src.shape != dst.shape or src.ndim != 2 or src.shape[1] != 3 or len(src) < 3:
        raise ValueError(f"similarity_transform: src {src.shape} and dst {dst.shape} must be (n>=3, 3)")
    mu_s, mu_d = src.mean(0), dst.mean(0)
    xs, xd = src - mu_s, dst - mu_d
    cov = xd.T @ xs / len(src)
    u, sig, vt = np.linalg.svd(cov)
    e = np.eye(3)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:
        e[2, 2] = -1.0
    rot = u @ e @ vt
    var_s = (xs ** 2).sum() / len(src)
    scale = float(np.trace(np.diag(sig) @ e) / var_s)
    out = np.eye(4)
    out[:3, :3] = scale * rot
    out[:3, 3] = mu_d - scale * rot @ mu_s
    return out


def apply_affine(matrix: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply a (4, 4) affine map to points (..., 3)."""
    p = np.asarray(points, dtype=np.float64)
    return p @ matrix[:3, :3].T + matrix[:3, 3]


def map_directions(warp: Callable, points: np.ndarray, directions: np.ndarray, step: float) -> np.ndarray:
    """Unit directions (k, 3) after ``warp``: map ``p`` and ``p + step d``, normalise."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    a, b = warp(p - 0.5 * step * d), warp(p + 0.5 * step * d)
    out = b - a
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def enhancement_field(held: np.ndarray, start: np.ndarray, displacement: np.ndarray,
                      epsilon: float) -> Callable[[np.ndarray], np.ndarray]:
    """The displacement field of one enhancement round: a Hardy RBF (affine part included)
    that is zero at ``held`` (h, 3) (the targets of the pairs already placed)
    and ``displacement`` (k, 3) at ``start`` (k, 3) (the new pairs' bone points), all head
    space, length units; ``epsilon``: the shape parameter (1 / length) of the landmarks.
    Returns ``u(points (q, 3)) -> (q, 3)`` displacement (length units)."""
    held = np.asarray(held, dtype=np.float64).reshape(-1, 3)
    start = np.asarray(start, dtype=np.float64).reshape(-1, 3)
    value = np.vstack([np.zeros_like(held), np.asarray(displacement, dtype=np.float64).reshape(-1, 3)])
    return hardy_rbf(np.vstack([held, start]), value, epsilon=epsilon)


def integrate_flow(u: Callable, points: np.ndarray, steps: int) -> np.ndarray:
    """Carry ``points`` (..., 3) along the stationary velocity field ``u`` ((q, 3) -> (q, 3),
    length per unit time) for unit time: ``steps`` explicit midpoint (RK2) steps of 1/steps.
    A point where ``u`` is zero does not move; for a smooth ``u`` and enough steps distinct
    points stay distinct (the flow is one-to-one), so a surface carried along cannot turn
    over. Returns the moved points, same shape."""
    p = np.asarray(points, dtype=np.float64)
    x = p.reshape(-1, 3).copy()
    h = 1.0 / int(steps)
    for _ in range(int(steps)):
        x = x + h * u(x + 0.5 * h * u(x))
    return x.reshape(p.shape)


@dataclass(frozen=True)
class Flow:
    """One enhancement round as a map in the :class:`Warp` composition: ``integrate_flow(field,
    points, steps)``. ``field``: :func:`enhancement_field`."""

    field: Callable
    steps: int = 8

    def __call__(self, points) -> np.ndarray:
        return integrate_flow(self.field, points, self.steps)


@dataclass
class Warp:
    """The fitted map template -> head: similarity, then RBFs in order."""

    similarity: np.ndarray
    rbfs: list = field(default_factory=list)

    def __call__(self, points) -> np.ndarray:
        p = np.asarray(points, dtype=np.float64)
        out = apply_affine(self.similarity, p.reshape(-1, 3))
        for g in self.rbfs:
            out = g(out)
        return out.reshape(p.shape)


# ----------------------------------------------------------------------------- queries


def worst_first_sample(points: np.ndarray, badness: np.ndarray, k: int, existing: np.ndarray,
                       min_distance: float) -> np.ndarray:
    """Indices (<= k,) of ``points`` (n, 3), worst (largest ``badness`` (n,)) first, each at
    least ``min_distance`` from ``existing`` (e, 3) and from the ones already taken.
    Deterministic (ties by index)."""
    if len(points) == 0 or k <= 0:
        return np.zeros(0, dtype=np.int64)
    if len(existing):
        from scipy.spatial import cKDTree

        free = cKDTree(existing).query(points)[0] >= min_distance
    else:
        free = np.ones(len(points), bool)
    chosen = []
    for i in np.argsort(-badness, kind="stable"):
        if not free[i]:
            continue
        chosen.append(int(i))
        if len(chosen) == k:
            break
        free &= np.linalg.norm(points - points[i], axis=1) >= min_distance
    return np.asarray(chosen, dtype=np.int64)


def grid_subsample(points: np.ndarray, cell: float) -> np.ndarray:
    """Bool (n,): the first point (by index) of every occupied cubic cell of size ``cell``."""
    keys = np.floor((points - points.min(axis=0)) / cell).astype(np.int64)
    _, first = np.unique(keys, axis=0, return_index=True)
    mask = np.zeros(len(points), bool)
    mask[first] = True
    return mask


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


# ----------------------------------------------------------------------------- the skull fit


#: unused template landmarks farther than this fraction of the landmarks' box diagonal from
#: every target are anchored to the similarity transform
ANCHOR_DISTANCE = 0.2


@dataclass
class SkullTargets:
    """Skull landmark -> skin target pairs of one fit.

    fdps : tuple of n FDP ids; source (n, 3) template skull points; skin (n, 3) skin
    landmarks; normal (n, 3) unit skin normals; depth (n,) tissue depth (head units);
    target (n, 3) = skin - depth * normal.
    """

    fdps: tuple
    source: np.ndarray
    skin: np.ndarray
    normal: np.ndarray
    depth: np.ndarray
    anchors: np.ndarray = None    # (a, 3) template points held where the similarity puts them

    @property
    def target(self) -> np.ndarray:
        return self.skin - self.depth[:, None] * self.normal


def skull_targets(skull_landmarks: dict, skin: SkinSurface, skin_ids, skin_points,
                  scale_mm: float, use_depth: bool) -> SkullTargets:
    """Pair the template skull landmarks with the skin landmarks they fit to.

    Only FDPs on both sides with bone beneath (``fit_tissue.FDP_TISSUE_CODE``) are used,
    with depth 0 when ``use_depth`` is false.
    """
    index = {f: i for i, f in enumerate(skin_ids)}
    fdps = tuple(f for f in skull_landmarks if f in index and f in fit_tissue.FDP_TISSUE_CODE)
    if len(fdps) < 6:
        raise ValueError(f"only {len(fdps)} FDPs shared by skull template and skin ({', '.join(fdps)}); need >= 6")
    rows = np.array([index[f] for f in fdps])
    depth = fit_tissue.tissue_depths(fdps, scale_mm) if use_depth else np.zeros(len(fdps))
    source = np.array([skull_landmarks[f] for f in fdps], dtype=np.float64)
    # template landmarks the skin cannot place (a face mask has no skull top, back, ears or jaw
    # angles) and that lie far from every target: held by the similarity alone, so that the
    # RBF does not extrapolate the back of the skull into a cone
    rest = np.array([p for f, p in skull_landmarks.items() if f not in fdps], dtype=np.float64).reshape(-1, 3)
    skull_diag = float(np.linalg.norm(np.ptp(np.vstack([source, rest]), axis=0)))
    far = np.min(np.linalg.norm(rest[:, None] - source[None], axis=2), axis=1) > ANCHOR_DISTANCE * skull_diag \
        if len(rest) else np.zeros(0, bool)
    return SkullTargets(fdps, source, np.asarray(skin_points, dtype=np.float64)[rows],
                        skin.normal_near(np.asarray(skin_points, dtype=np.float64)[rows]), depth,
                        rest[far])


@dataclass
class SkullFit:
    """Result of :func:`fit_skull`.

    warp : Warp template -> head; sources (s, 3) aligned template points of every pair;
    targets (s, 3); n_landmarks : the first n rows are FDP pairs, then the anchors, then
    enhancement landmarks; rounds : pairs added per enhancement round; reached (s, 3):
    where the warp takes the sources (the targets, but for enhancement pairs met by a
    flow, which ends near its target rather than on it).
    """

    warp: Warp
    sources: np.ndarray
    targets: np.ndarray
    n_landmarks: int
    rounds: list
    epsilon: float = 1.0
    reached: np.ndarray = None


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


def skin_inside_bone_pairs(moved: np.ndarray, skull_faces: np.ndarray, aligned: np.ndarray, skin: SkinSurface,
                           taken: np.ndarray, spacing: float, clearance: float, k: int, region=None):
    """Enhancement pairs that push the bone off skin it swallowed (a deep eye socket, a nostril).

    Skin vertices (the skin's own, within ``region(points) -> bool``) inside the morphed
    skull ``(moved (n, 3), skull_faces)`` (:func:`inside_closed`) are taken deepest first,
    at least ``spacing`` from the ``taken`` (a, 3) sources and each other (template-aligned
    space); for each, the skull vertex nearest to its closest bone point moves along the
    bone normal until the skin lies ``clearance`` outside. Returns ``(sources (k, 3)
    aligned, targets (k, 3) head space)``.
    """
    from faceforge.geometry.surface_points import closest_points

    used = np.unique(skin.faces)
    sv = skin.vertices[used[used < skin.n_real]] if skin.n_real >= 0 else skin.vertices[used]
    if region is not None:
        sv = sv[region(sv)]
    inside = inside_closed(moved, skull_faces, sv)
    if not inside.any() or k <= 0:
        return np.zeros((0, 3)), np.zeros((0, 3))
    s = sv[inside]
    b, d, tri = closest_points(s, moved, skull_faces)
    corner = skull_faces[tri]
    j = corner[np.arange(len(s)), np.argmin(np.linalg.norm(moved[corner] - b[:, None], axis=2), axis=1)]
    n = vertex_normals(moved, skull_faces)[j]
    pick = worst_first_sample(aligned[j], d, k, taken, spacing)
    j, n, s, b = j[pick], n[pick], s[pick], b[pick]
    push = np.einsum("ij,ij->i", s - b, n) - clearance        # negative: move the bone inward
    return aligned[j], moved[j] + np.minimum(push, 0.0)[:, None] * n


def fit_skull(pairs: SkullTargets, skull_vertices: np.ndarray, skull_faces: np.ndarray, skin: SkinSurface,
              skin_landmarks: dict, settings: FitSettings, scale_mm: float = 1.0) -> SkullFit:
    """Steps 2-4 of the module docstring on the skull ``(vertices (n,3), faces (m,3))`` (template
    space); ``scale_mm``: head units per millimetre."""
    sim = similarity_transform(pairs.source, pairs.target)
    src = apply_affine(sim, pairs.source)
    dst = pairs.target.copy()
    if pairs.anchors is not None and len(pairs.anchors):
        held = apply_affine(sim, pairs.anchors)
        src, dst = np.vstack([src, held]), np.vstack([dst, held])
    # the shape parameter stays that of the FDP landmarks: adding sources must not make
    # every kernel narrower (Hardy's R shrinks with the mean source spacing)
    eps = hardy_epsilon(src)
    warp = Warp(sim, [hardy_rbf(src, dst, epsilon=eps)])
    rounds = []
    if not settings.enhancement_rays:
        return SkullFit(warp, src, dst, len(pairs.fdps), rounds, eps, dst.copy())
    aligned = apply_affine(sim, skull_vertices)
    outer = outer_vertices(aligned, skull_faces)
    outer &= grid_subsample(aligned, settings.enhancement_cell * skin.diagonal)
    depth_sites, site_depth = pairs.target, pairs.depth
    spacing = settings.enhancement_spacing * skin.diagonal
    flow = settings.enhancement_flow_steps > 0
    moved = warp.rbfs[0](aligned)            # the skull under the map so far (head space)
    reached = dst.copy()                     # where the map so far takes each source
    for _ in range(settings.enhancement_rounds):
        cand = np.flatnonzero(outer & front_mask(moved, skin_landmarks, settings.front_offset_es0))
        depth, closest, normal, covered, pocket = signed_skin_depth(moved[cand], skin)
        facing = np.einsum("ij,ij->i", vertex_normals(moved, skull_faces)[cand], normal) > 0.3
        expected = fit_tissue.depth_field(moved[cand], depth_sites, site_depth) if settings.tissue_depth \
            else np.zeros(len(cand))
        bad = np.flatnonzero(covered & facing & ~pocket
                             & (depth < settings.enhancement_min_ratio * expected + 1e-9 * skin.diagonal))
        badness = (settings.enhancement_min_ratio * expected[bad] - depth[bad]) / np.maximum(expected[bad], 1e-300)
        pick = bad[worst_first_sample(aligned[cand[bad]], badness, settings.enhancement_samples, src, spacing)]
        new_src = aligned[cand[pick]]
        new_dst = closest[pick] - expected[pick, None] * normal[pick]
        if settings.skin_clearance_mm > 0:
            s_src, s_dst = skin_inside_bone_pairs(
                moved, skull_faces, aligned, skin, np.vstack([src, new_src]), 0.5 * spacing,
                settings.skin_clearance_mm * scale_mm, settings.skin_clearance_samples,
                lambda p: front_mask(p, skin_landmarks, settings.front_offset_es0))
            new_src, new_dst = np.vstack([new_src, s_src]), np.vstack([new_dst, s_dst])
        if len(new_src) == 0:
            rounds.append(0)
            break
        if flow:
            # the new sources are skull vertices: where the map so far takes them
            start = Warp(np.eye(4), warp.rbfs)(new_src)
            # zero at every earlier target: the FDP landmarks stay exactly where they are, and
            # bone that an earlier flow left short of its target is not pinned there
            g = Flow(enhancement_field(dst, start, new_dst - start, eps), settings.enhancement_flow_steps)
            warp = Warp(sim, warp.rbfs + [g])
            moved, reached = g(moved), np.vstack([g(reached), g(start)])
        else:
            g = hardy_rbf(np.vstack([src, new_src]), np.vstack([dst, new_dst]), epsilon=eps)
            warp = Warp(sim, [g])
            moved, reached = g(aligned), np.vstack([dst, new_dst])
        src, dst = np.vstack([src, new_src]), np.vstack([dst, new_dst])
        rounds.append(int(len(new_src)))
    return SkullFit(warp, src, dst, len(pairs.fdps), rounds, eps, reached)


# ----------------------------------------------------------------------------- the whole fit


@dataclass
class FitTemplate:
    """Template inputs of :func:`fit_head`, all in template (skull) space.

    cranium, mandible : (vertices (n, 3) float64, faces (m, 3) int64)
    landmarks : {fdp: (3,) float64} points on the bone
    jaw_axes : {name: (point (3,), direction (3,))} e.g. pitch, yaw, protrusion
    muscle_points : {muscle name: (k, 3) float64} every point of the muscle map
    muscle_weights : {muscle name: (k,) float64} how much of the mouth's shift each of those
        points takes (:func:`faceforge.anatomy.fit_mouth.point_weights`; missing: all)
    """

    cranium: tuple
    mandible: tuple
    landmarks: dict
    jaw_axes: dict = field(default_factory=dict)
    muscle_points: dict = field(default_factory=dict)
    muscle_weights: dict = field(default_factory=dict)


@dataclass
class FitResult:
    """Everything :func:`fit_head` produced, in head space (mesh units)."""

    cranium: np.ndarray                 # (n, 3) fitted cranium vertices (template faces)
    mandible: np.ndarray                # (n, 3) fitted mandible vertices
    landmarks: dict                     # {fdp: (3,)} fitted bone landmarks
    fdps: tuple                         # FDPs used as skull targets
    targets: np.ndarray                 # (n, 3) final bone-landmark targets (after the refit)
    reached: np.ndarray                 # (n, 3) where those landmarks ended up
    jaw_axes: dict                      # {name: (point (3,), unit direction (3,))}
    muscle_points: dict                 # {name: (k, 3)} morphed muscle map
    muscles: list                       # [(name, vertices, faces)] built on the fitted skull
    warp: Warp
    info: dict                          # counts for the report
    cranium_faces: np.ndarray = None    # (m, 3) template faces
    mandible_faces: np.ndarray = None
    tissue_targets: np.ndarray = None   # (n, 3) targets before the refit (skin - depth * normal)
    enhancement_targets: np.ndarray = None  # (e, 3) where the enhancement landmarks went


def fit_head(template: FitTemplate, skin: SkinSurface, skin_ids, skin_points,
             settings: FitSettings = FitSettings(), build_muscles: Callable | None = None,
             mirror=None) -> FitResult:
    """Fit the skull and muscle map into the skin (steps 1-5 of the module docstring).

    skin_ids (n,) FDP ids, skin_points (n, 3): the validated skin landmarks
    (:class:`faceforge.io.landmarks.Landmarks`); normals are taken where each lies on ``skin``.
    ``build_muscles(cranium (v, f), mandible (v, f), warp, shift) -> [(name, vertices, faces)]``
    builds the muscles on the fitted skull (Eq. 5 thickness), ``shift`` the mouth's
    (:class:`faceforge.anatomy.fit_mouth.MouthField` or None, weighted per muscle particle);
    without it the muscle map points are morphed only and there is no refit. ``mirror``
    (:class:`faceforge.anatomy.fit_symmetry.Mirror`, for a mirror-symmetric skin): the rig is
    made symmetric about it before the bone is cleared off the skin.
    """
    from faceforge.anatomy import fit_muscles

    skin_lm = {f: np.asarray(p, dtype=np.float64) for f, p in zip(skin_ids, skin_points)}
    scale_mm = fit_tissue.units_per_mm(skin_lm)
    pairs = skull_targets(template.landmarks, skin, skin_ids, skin_points,
                          scale_mm, settings.tissue_depth)
    (cv, cf), (mv, mf) = template.cranium, template.mandible
    skull_v = np.vstack([cv, mv])
    skull_f = np.vstack([cf, mf + len(cv)])
    sk = fit_skull(pairs, skull_v, skull_f, skin, skin_lm, settings, scale_mm)
    warp = sk.warp
    skull_fit = warp(skull_v)
    muscles = []
    targets = pairs.target
    info = {"units_per_mm": scale_mm, "landmark_pairs": len(pairs.fdps), "enhancement_rounds": sk.rounds,
            "anchors": int(len(pairs.anchors)),
            "enhancement_landmarks": int(len(sk.sources) - sk.n_landmarks - len(pairs.anchors)),
            "covered_landmarks": [],
            "refit": False}
    mouth = None
    if settings.mouth_follows_lips:
        from faceforge.anatomy.fit_mouth import mouth_field

        names = list(template.landmarks)
        placed = warp(np.array([template.landmarks[f] for f in names], dtype=np.float64).reshape(-1, 3))
        mouth = mouth_field(dict(zip(names, placed)), skin_lm)
        if mouth is not None:
            info["mouth_shift_max_rel"] = float(np.linalg.norm(mouth.shifts, axis=1).max() / skin.diagonal)

    if build_muscles is not None:
        muscles = build_muscles((skull_fit[:len(cv)], cf), (skull_fit[len(cv):], mf), warp, mouth)
        if settings.refit and muscles:
            diag = float(np.linalg.norm(np.ptp(skull_fit, axis=0)))
            fitted = warp(pairs.source)
            rf = fit_muscles.refit_pairs(fitted, skin, fit_muscles.vertical_axis(skull_fit[:len(cv)]),
                                         [(v, f) for _, v, f in muscles], settings.muscle_gap_mm * scale_mm,
                                         skin.diagonal, 0.05 * diag)
            g2 = fit_muscles.refit_rbf(rf, fitted, sk.reached[sk.n_landmarks:], sk.epsilon)
            info["covered_landmarks"] = [f for f, c in zip(pairs.fdps, rf.covered) if c]
            if g2 is not None:
                warp = Warp(warp.similarity, warp.rbfs + [g2])
                skull_fit = g2(skull_fit)
                muscles = [(n, g2(v), f) for n, v, f in muscles]
                targets = rf.skull_targets
                info["refit"] = True
                info["refit_moved"] = [f for f, d in zip(pairs.fdps, rf.delta) if np.any(d)]
    if mirror is not None:   # a symmetric skin gets a symmetric rig (the template skull is lopsided)
        from faceforge.anatomy.fit_symmetry import symmetrize_bones

        skull_fit, muscles = symmetrize_bones(skull_fit, len(cv), cf, mf, muscles, mirror)
    # 6a. a modelled eye socket is hollow (fit_orbits): bone inside it moves out along rays from
    # the socket's centre, by a one-to-one map that cannot fold the orbital walls
    if settings.skin_clearance_mm > 0 and settings.orbit_hollow:
        from faceforge.anatomy.fit_orbits import find_orbit_hollows, fit_hollow

        hollows, shift = [], 0.0
        for h in find_orbit_hollows(skin, skin_lm, settings.skin_clearance_mm * scale_mm, settings.orbit_blend):
            h = fit_hollow(h, skull_fit, skull_f)
            if h.lam >= 1.0:
                continue
            moved = h(skull_fit)
            shift = max(shift, float(np.linalg.norm(moved - skull_fit, axis=1).max()))
            skull_fit = moved
            muscles = [(n, h(v), f) for n, v, f in muscles]
            targets = h(targets)
            hollows.append(h)
        warp = Warp(warp.similarity, warp.rbfs + hollows)
        info["orbit_hollows"] = len(hollows)
        info["orbit_clearance"] = [h.clearance for h in hollows]
        info["orbit_max_shift_rel"] = shift / skin.diagonal
    # 6b. bone that still swallows skin gives way locally (fit_clearance); the same fields move
    # the muscles, landmarks and axes, so everything lying on the bone stays on it
    if settings.skin_clearance_mm > 0 and settings.clearance_rounds > 0:
        from faceforge.anatomy.fit_clearance import clearance_fields

        used = np.unique(skin.faces)
        own = skin.vertices[used[used < skin.n_real]] if skin.n_real >= 0 else skin.vertices[used]
        fields = clearance_fields([(skull_fit[:len(cv)], cf), (skull_fit[len(cv):], mf)], own,
                                  settings.skin_clearance_mm * scale_mm,
                                  settings.clearance_radius * skin.diagonal, settings.clearance_rounds)
        for g in fields:
            skull_fit = g(skull_fit)
            muscles = [(n, g(v), f) for n, v, f in muscles]
            targets = g(targets)
        warp = Warp(warp.similarity, warp.rbfs + fields)
        info["clearance_fields"] = len(fields)
        info["clearance_points"] = int(sum(len(g.centres) for g in fields))
    # axes: points by the fit's similarity (the least-squares scale, turn and shift of all the
    # landmarks), not by the full map: the condyles lie far behind the face's landmarks, where the
    # RBFs extrapolate (MakeHuman: the map put the pitch axis 0.2 cm above the pupils, the
    # similarity 1.3 cm below them, in front of the ear); directions turned by the rotation that
    # best carries the template mandible onto the fitted one (least squares over all its
    # vertices): the jaw is one rigid body, so its axes follow the mandible as a whole
    jaw = {}
    if len(mv) >= 3:
        m = similarity_transform(np.asarray(mv, dtype=np.float64), skull_fit[len(cv):])
        rot = m[:3, :3] / np.cbrt(abs(np.linalg.det(m[:3, :3])))
    else:
        rot = warp.similarity[:3, :3] / np.cbrt(abs(np.linalg.det(warp.similarity[:3, :3])))
    for name, (point, direction) in template.jaw_axes.items():
        d = rot @ np.asarray(direction, dtype=np.float64)
        jaw[name] = (apply_affine(warp.similarity, np.asarray(point, dtype=np.float64)[None])[0],
                     d / np.linalg.norm(d))
    fitted_lm = {f: warp(np.asarray(p, dtype=np.float64)[None])[0] for f, p in template.landmarks.items()}
    enhancement = sk.reached[sk.n_landmarks + len(pairs.anchors):]
    later = warp.rbfs[len(sk.warp.rbfs):]   # the refit, orbit and clearance maps carry them on
    for g in later:
        enhancement = g(enhancement)
    reached = np.array([fitted_lm[f] for f in pairs.fdps])

    def muscle_map(name, points):   # the skull's map, the mouth's shift (muscles only), the rest
        out = sk.warp(points)
        if mouth is not None:
            out = mouth(out, template.muscle_weights.get(name))
        for g in later:
            out = g(out)
        return out

    result = FitResult(skull_fit[:len(cv)], skull_fit[len(cv):], fitted_lm, pairs.fdps, targets, reached, jaw,
                       {n: muscle_map(n, p) for n, p in template.muscle_points.items()}, muscles, warp, info,
                       np.asarray(cf), np.asarray(mf), pairs.target, enhancement)
    if mirror is not None:
        from faceforge.anatomy.fit_symmetry import symmetrize_fit

        result = symmetrize_fit(result, mirror)
    return result
