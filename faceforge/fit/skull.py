"""The skull fit (§7): bone landmarks to their targets beneath the skin (tissue depth), then
enhancement rounds where the bone lies too close to the skin or swallows it."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from faceforge.anatomy import tissue as fit_tissue
from faceforge.fit.align import Flow, Warp, apply_affine, enhancement_field, grid_subsample, worst_first_sample
from faceforge.geometry.rigid import similarity_transform
from faceforge.fit.surface import SkinSurface, front_mask, inside_closed, outer_vertices, signed_skin_depth
from faceforge.geometry.rbf import hardy_epsilon, hardy_rbf
from faceforge.geometry.triangles import vertex_normals


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


#: a landmark whose own skin normal is more than this many degrees from the normal of the
#: skin around it sits on a fold: its tissue depth is taken along the latter
FOLD_DEG = 40.0


def smoothed_normals(skin: SkinSurface, points: np.ndarray, radius: float) -> np.ndarray:
    """Unit skin normals (k, 3) at the closest skin points of ``points`` (k, 3): the smooth
    normal at the point (:meth:`SkinSurface.normal_near`), or, where that is more than
    :data:`FOLD_DEG` from the normal of the skin around it (area-weighted face normals,
    fans included, whose centroids lie within ``radius`` head units, Gaussian weights of
    sigma ``radius / 2``), the latter. ``radius`` <= 0: the point's own everywhere.

    The tissue depth is measured across the face, not across a lid fold: an eye corner
    placed on the lid margin of a modelled eye socket has a normal pointing into the socket
    (MakeHuman, detected outer corner: (-0.97, -0.16, 0.17), 60 degrees from the skin around it; a
    hand-placed corner: 22 degrees), and its bone target, that far
    sideways, pushed the lateral orbital rim 16 mm out of the skin."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    own = skin.normal_near(p)
    if radius <= 0 or len(p) == 0:
        return own
    from scipy.spatial import cKDTree

    tri = skin.vertices[skin.faces]
    area_normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    centroid = tri.mean(axis=1)
    closest, _, _ = skin.closest(p)
    out = own.copy()
    for i, near in enumerate(cKDTree(centroid).query_ball_point(closest, radius)):
        if not near:
            continue
        d2 = np.sum((centroid[near] - closest[i]) ** 2, axis=1)
        n = (np.exp(-2.0 * d2 / radius ** 2)[:, None] * area_normal[near]).sum(axis=0)
        if np.linalg.norm(n) > 0 and float(own[i] @ n) < np.cos(np.radians(FOLD_DEG)) * np.linalg.norm(n):
            out[i] = n / np.linalg.norm(n)
    return out


def skull_targets(skull_landmarks: dict, skin: SkinSurface, skin_ids, skin_points,
                  scale_mm: float, use_depth: bool, normal_radius: float = 0.0) -> SkullTargets:
    """Pair the template skull landmarks with the skin landmarks they fit to.

    Only FDPs on both sides with bone beneath (``fit_tissue.FDP_TISSUE_CODE``) are used,
    with depth 0 when ``use_depth`` is false; the depth is taken along the skin normal
    averaged over ``normal_radius`` (head units, :func:`smoothed_normals`).
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
                        smoothed_normals(skin, np.asarray(skin_points, dtype=np.float64)[rows], normal_radius),
                        depth,
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


def limit_steps(start: np.ndarray, target: np.ndarray, held: np.ndarray, ratio: float) -> np.ndarray:
    """Targets (k, 3) of new enhancement pairs pulled back towards their ``start`` (k, 3) so
    that no pair moves more than ``ratio`` times its distance to the nearest ``held`` (h, 3)
    point, where the round's field is zero (``ratio`` <= 0: unchanged).

    The field of a flow goes from zero at a held target to the full correction at the new
    pair, so its gradient there is about correction / distance, and the bone between them
    stretches by that much: skin that a modelled eye socket pushes deep into the bone asked
    for 1-4 cm of push beside the eye-corner targets, and the flows stretched the bone's edges
    up to 17-fold, out through the lids and brows (MakeHuman ``caucasian_female_young``,
    skull 96 % inside, issue 28). A shortened pair is met over the next rounds, which test
    again."""
    start, target = np.asarray(start, dtype=np.float64), np.asarray(target, dtype=np.float64)
    if ratio <= 0 or len(start) == 0 or len(held) == 0:
        return target
    from scipy.spatial import cKDTree

    near, _ = cKDTree(np.asarray(held, dtype=np.float64)).query(start)
    step = np.linalg.norm(target - start, axis=1)
    keep = np.minimum(1.0, ratio * near / np.maximum(step, 1e-300))
    return start + keep[:, None] * (target - start)


def fit_skull(pairs: SkullTargets, skull_vertices: np.ndarray, skull_faces: np.ndarray, skin: SkinSurface,
              skin_landmarks: dict, settings, scale_mm: float = 1.0) -> SkullFit:
    """Steps 2-4 of the module docstring on the skull ``(vertices (n,3), faces (m,3))`` (template
    space); ``settings``: :class:`faceforge.fit.head.FitSettings`; ``scale_mm``: head units per
    millimetre."""
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
            new_dst = limit_steps(start, new_dst, dst, settings.enhancement_max_step)
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
