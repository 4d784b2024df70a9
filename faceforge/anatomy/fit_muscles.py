"""Muscles in the fit: Eq. 5 thickness, cylindrical projection and the refit (§7).

After the skull fit the muscle map is morphed by the same map and the muscles are
rebuilt on the fitted skull with thickness ``t = (d_head / d_skull) t`` (Eq. 5).
The template stores thickness as a fraction of the template skull's diagonal, so
Eq. 5 reads ``t_head = fraction * d``; ``d`` is the diagonal of the *fitted* skull
(cranium + mandible) rather than of the skin, because a skin may be a face mask whose
box is much smaller than the head it belongs to.

Cylindrical projection: a ray is cast from outside the head toward a vertical axis
(+Y) through the centre of the fitted cranium, through each skull landmark; if it hits
a muscle before reaching the landmark, the landmark is *covered* and is replaced by the
first hit on the outermost muscle surface. The refit is a second Hardy RBF in head
space taking those muscle points to the skin targets (the muscle top is kept at least
``gap`` beneath the skin, and keeps the tissue depth to the bone where it is thick
enough), with every other source (uncovered landmarks, enhancement landmarks) held
fixed, so the muscle map ends up just beneath the skin.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from faceforge.geometry.rbf import hardy_rbf
from faceforge.geometry.rays import RayCaster


def eq5_thickness(fraction: float, skull_diagonal: float) -> float:
    """Muscle thickness in head units from the template's fraction of the skull diagonal (Eq. 5)."""
    return float(fraction) * float(skull_diagonal)


def vertical_axis(cranium_vertices: np.ndarray) -> np.ndarray:
    """Point (3,) on the vertical projection axis: the centre of the cranium's box in x and z."""
    lo, hi = cranium_vertices.min(0), cranium_vertices.max(0)
    return 0.5 * (lo + hi)


def cylindrical_projection(points: np.ndarray, axis_point: np.ndarray, muscle_meshes: list,
                           reach: float):
    """Bring points (k, 3) onto the outermost muscle covering them.

    Rays start ``reach`` outside each point on the horizontal line through the vertical
    axis and travel toward the axis. Returns ``(covered (k,) bool, hits (k, 3), muscle
    (k,) int64 index into muscle_meshes or -1, lift (k,) distance point -> hit)``.
    ``muscle_meshes``: list of ``(vertices (n,3), faces (m,3))``.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    k = len(pts)
    radial = pts - axis_point
    radial[:, 1] = 0.0
    norm = np.linalg.norm(radial, axis=1, keepdims=True)
    radial = np.where(norm > 0, radial / np.maximum(norm, 1e-300), [[0.0, 0.0, 1.0]])
    origins = pts + reach * radial
    best = np.full(k, np.inf)
    hits = np.full((k, 3), np.nan)
    which = np.full(k, -1, dtype=np.int64)
    for i, (v, f) in enumerate(muscle_meshes):
        if len(f) == 0:
            continue
        face, loc, dist = RayCaster(v, f).first_hit(origins, -radial, max_distance=reach)
        better = (face >= 0) & (dist < best)
        best[better], hits[better], which[better] = dist[better], loc[better], i
    covered = which >= 0
    lift = np.where(covered, reach - best, 0.0)
    return covered, hits, which, lift


@dataclass
class Refit:
    """The refit's pairs: muscle points -> skin targets (head space)."""

    covered: np.ndarray          # (n,) bool per skull landmark
    muscle: np.ndarray           # (n,) int64
    lift: np.ndarray             # (n,) muscle-top height above the bone landmark
    sources: np.ndarray          # (n, 3) muscle point or the fitted landmark
    targets: np.ndarray          # (n, 3)
    skull_targets: np.ndarray    # (n, 3) final targets of the bone landmarks


def refit_pairs(landmarks_fitted: np.ndarray, skin_points: np.ndarray, skin_normals: np.ndarray,
                depth: np.ndarray, axis_point: np.ndarray, muscle_meshes: list, gap: float,
                reach: float, max_lift: float) -> Refit:
    """Pairs for the second fit of §7.

    landmarks_fitted (n, 3) bone landmarks after the first fit; skin_points, skin_normals
    (n, 3) skin landmarks and unit normals; depth (n,) tissue depth; gap: least skin
    tissue above a muscle (head units).

    A covered landmark's muscle point goes to ``skin - max(depth - lift, gap) * normal``;
    the bone landmark's own target becomes ``skin - max(depth, lift + gap) * normal``.
    A hit more than ``max_lift`` above the landmark belongs to another part of the face
    (the ray grazed a muscle in front) and does not count as covering it.
    """
    covered, hits, which, lift = cylindrical_projection(landmarks_fitted, axis_point, muscle_meshes, reach)
    covered &= lift <= max_lift
    which = np.where(covered, which, -1)
    lift = np.where(covered, lift, 0.0)
    top_depth = np.maximum(depth - lift, gap)
    src = np.where(covered[:, None], hits, landmarks_fitted)
    dst = np.where(covered[:, None], skin_points - top_depth[:, None] * skin_normals, landmarks_fitted)
    bone_depth = np.where(covered, np.maximum(depth, lift + gap), depth)
    return Refit(covered, which, lift, src, dst, skin_points - bone_depth[:, None] * skin_normals)


def refit_rbf(refit: Refit, fixed_points: np.ndarray):
    """Second RBF (head space -> head space): muscle points to their targets, ``fixed_points``
    (e, 3) (uncovered and enhancement sources, already at their targets) held in place.
    Returns None when no landmark is covered."""
    if not np.any(refit.covered):
        return None
    src = np.vstack([refit.sources, fixed_points])
    dst = np.vstack([refit.targets, fixed_points])
    _, keep = np.unique(np.round(src, 12), axis=0, return_index=True)
    keep = np.sort(keep)
    return hardy_rbf(src[keep], dst[keep])


def morph_spec(spec, warp):
    """A :class:`faceforge.anatomy.muscle_map.MuscleSpec` with every point mapped by ``warp``
    ((k, 3) -> (k, 3)); thickness stays a fraction (Eq. 5 applies when building)."""
    from dataclasses import replace

    fields = ("origin", "insertion", "fibre_a", "fibre_b", "inner", "outer")
    return replace(spec, **{k: (warp(getattr(spec, k)) if len(getattr(spec, k)) else getattr(spec, k))
                            for k in fields})


def build_muscles_on(specs, cranium, mandible, skull_diagonal: float, stiffness: dict | None = None) -> list:
    """Build every muscle of ``specs`` on the given skull, deepest layer first.

    Each muscle's action lines are projected (outermost surface) onto the concatenation of
    the bodies it lies on (cranium, mandible, deeper muscles); thickness is Eq. 5:
    ``spec.thickness * skull_diagonal``. ``stiffness``: ``{"linear": {...}, "sphincter":
    {...}}`` of the config (empty: geometry only). Returns ``[Muscle]`` in build order.
    """
    from faceforge.anatomy.action_line import ActionLine
    from faceforge.anatomy.layers import expand_lies_on
    from faceforge.anatomy.muscle import align_loops, build_linear_muscle, build_sphincter_muscle
    from faceforge.exceptions import TemplateError

    stiffness = stiffness or {}
    bodies = {"cranium": cranium, "mandible": mandible}
    built = []
    for spec in sorted(specs, key=lambda s: s.layer):
        parts = []
        for name in expand_lies_on(spec.lies_on):
            if name not in bodies:
                raise TemplateError(f"muscle {spec.name!r} lies on {name!r}, which is not built before it")
            parts.append(bodies[name])
        offsets = np.cumsum([0] + [len(v) for v, _ in parts])
        v = np.vstack([p[0] for p in parts])
        f = np.vstack([p[1] + o for p, o in zip(parts, offsets)])
        t = eq5_thickness(spec.thickness, skull_diagonal)
        kw = dict(lies_on=tuple(spec.lies_on), layer=spec.layer, active=spec.active)
        lines = spec.action_lines()

        def line(points, closed=False):
            return ActionLine.from_points(points, v, f, closed=closed, project="outermost")

        if spec.type == "linear":
            m = build_linear_muscle(spec.name, line(lines["A3"]), line(lines["A1"]), line(lines["A0"]),
                                    line(lines["A2"]), v, f, spec.h, spec.w, t,
                                    stiffness.get("linear", {}), **kw)
        else:
            inner, outer = align_loops(spec.inner, spec.outer)
            m = build_sphincter_muscle(spec.name, line(inner, True), line(outer, True), v, f, spec.h, spec.w,
                                       t, stiffness.get("sphincter", {}), **kw)
        bodies[spec.name] = (m.rest_positions, m.faces)
        built.append(m)
    return built


def morph_muscle_meshes(template_muscles, warp, skull_diagonal: float) -> list:
    """Muscles built on the template skull, carried into the head by ``warp`` (Eq. 5).

    The bottom sheet of each muscle (first ``h w`` particles) is mapped by ``warp``; the
    top sheet is put back at the rescaled thickness ``t = fraction * skull_diagonal``
    along the mapped bottom -> top direction, so the muscle keeps its shape while its
    thickness follows the fitted skull (Eq. 5) rather than the local stretch of the map.

    template_muscles : [(name, rest_positions (2hw, 3), faces, hw, thickness fraction)]
    Returns ``[(name, vertices (2hw, 3), faces)]``.
    """
    out = []
    for name, rest, faces, hw, fraction in template_muscles:
        p = warp(rest)
        bottom = p[:hw]
        up = p[hw:] - bottom
        up /= np.maximum(np.linalg.norm(up, axis=1, keepdims=True), 1e-300)
        out.append((name, np.vstack([bottom, bottom + eq5_thickness(fraction, skull_diagonal) * up]), faces))
    return out
