"""Muscles in the fit: Eq. 5 thickness, cylindrical projection and the refit (§7).

After the skull fit the muscle map is morphed by the same map and the muscles are
rebuilt on the fitted skull with thickness ``t = (d_head / d_skull) t`` (Eq. 5).
The template stores thickness as a fraction of the template skull's diagonal, so
Eq. 5 reads ``t_head = fraction * d``; ``d`` is the diagonal of the *fitted* skull
(cranium + mandible) rather than of the skin, because a skin may be a face mask whose
box is much smaller than the head it belongs to.

Cylindrical projection: a ray is cast from outside the head toward a vertical axis
(+Y) through the centre of the fitted cranium, through each skull landmark; if it hits
a muscle before reaching the landmark, the landmark is *covered* and the first hit on
the outermost muscle surface is its muscle point. Where a muscle point lies less than
``gap`` beneath the skin, the landmark and its muscle point are moved inward along the
skin normal until it does; the refit is a second Hardy RBF in head space carrying those
pairs, with every other source (enhancement landmarks, anchors) held fixed, so the
muscle map ends up just beneath the skin. The landmark's target becomes the moved point.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from faceforge.anatomy.muscles.build import eq5_thickness
from faceforge.geometry.rays import RayCaster
from faceforge.geometry.rbf import hardy_rbf


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
    """The refit of §7 for the n bone landmarks (head space).

    covered (n,) bool, muscle (n,) int64 (-1: none), lift (n,) muscle point height above
    the landmark, hits (n, 3) muscle points (NaN where uncovered), delta (n, 3) the move
    that keeps each covered muscle point ``gap`` beneath the skin (0 elsewhere),
    skull_targets (n, 3) = landmark + delta.
    """

    covered: np.ndarray
    muscle: np.ndarray
    lift: np.ndarray
    hits: np.ndarray
    delta: np.ndarray
    skull_targets: np.ndarray


def refit_pairs(landmarks_fitted: np.ndarray, skin, axis_point: np.ndarray, muscle_meshes: list, gap: float,
                reach: float, max_lift: float) -> Refit:
    """Cylindrical projection of the fitted bone landmarks (n, 3) onto the muscles, and the
    move each needs so that its muscle point lies at least ``gap`` beneath the skin
    (depth by the closest skin point, :func:`faceforge.fit.surface.signed_skin_depth`).
    A hit more than ``max_lift`` above the landmark belongs to another part of the face
    (the ray grazed a muscle in front) and does not count as covering it.
    """
    from faceforge.fit.surface import signed_skin_depth

    covered, hits, which, lift = cylindrical_projection(landmarks_fitted, axis_point, muscle_meshes, reach)
    covered &= lift <= max_lift
    which = np.where(covered, which, -1)
    lift = np.where(covered, lift, 0.0)
    delta = np.zeros_like(landmarks_fitted)
    idx = np.flatnonzero(covered)
    if len(idx):
        depth, _, normal, _, _ = signed_skin_depth(hits[idx], skin)
        delta[idx] = -np.maximum(gap - depth, 0.0)[:, None] * normal
    return Refit(covered, which, lift, np.where(covered[:, None], hits, np.nan), delta,
                 landmarks_fitted + delta)


def refit_rbf(refit: Refit, landmarks_fitted: np.ndarray, fixed_points: np.ndarray, epsilon: float):
    """Second Hardy RBF (head space -> head space) of §7.

    Each bone landmark and its muscle point move by the landmark's ``delta``; ``fixed_points``
    (e, 3) (enhancement landmarks, anchors) stay. Returns None when nothing needs to move.
    """
    moving = np.flatnonzero(np.linalg.norm(refit.delta, axis=1) > 0)
    if len(moving) == 0:
        return None
    src = np.vstack([landmarks_fitted, refit.hits[moving], fixed_points])
    dst = np.vstack([refit.skull_targets, refit.hits[moving] + refit.delta[moving], fixed_points])
    return hardy_rbf(src, dst, epsilon=epsilon)


def morph_muscle_meshes(template_muscles, warp, skull_diagonal: float, shift=None, weights=None) -> list:
    """Muscles built on the template skull, carried into the head by ``warp`` (Eq. 5).

    The bottom sheet of each muscle (first ``h w`` particles) is mapped by ``warp``; the
    top sheet is put back at the rescaled thickness ``t = fraction * skull_diagonal``
    along the mapped bottom -> top direction, so the muscle keeps its shape while its
    thickness follows the fitted skull (Eq. 5) rather than the local stretch of the map.

    template_muscles : [(name, rest_positions (2hw, 3), faces, hw, thickness fraction)]
    shift, weights : optional ``(points, weights) -> points`` applied after ``warp`` (the mouth's
    :class:`faceforge.fit.mouth.MouthField`) with ``weights[name] (2hw,)``
    Returns ``[(name, vertices (2hw, 3), faces)]``.
    """
    out = []
    for name, rest, faces, hw, fraction in template_muscles:
        p = warp(rest)
        if shift is not None:
            p = shift(p, weights[name])
        bottom = p[:hw]
        up = p[hw:] - bottom
        up /= np.maximum(np.linalg.norm(up, axis=1, keepdims=True), 1e-300)
        out.append((name, np.vstack([bottom, bottom + eq5_thickness(fraction, skull_diagonal) * up]), faces))
    return out


def fitted_muscle_map(specs, points: dict) -> dict:
    """The muscle map carried into the head, in the muscle-map YAML structure.

    Every point of every :class:`~faceforge.anatomy.muscles.muscle_map.MuscleSpec` is taken from
    ``points`` (``{name: (k, 3)}`` in ``spec.points()`` order:
    :attr:`faceforge.fit.head.FitResult.muscle_points`, the map as the fit carried it);
    mirrored muscles are written out in full. Thickness stays a fraction of the skull
    diagonal (Eq. 5 then applies with the fitted skull). Loadable with
    ``load_muscle_map(path, fitted_skull)`` (its ``units: template`` means "the skull it
    is loaded with").
    """
    fields_linear = ("origin", "insertion", "fibre_a", "fibre_b")
    fields_sphincter = ("inner", "outer")
    muscles = []
    for spec in specs:
        m = spec.with_points(points[spec.name])
        entry = {"name": m.name, "type": m.type, "layer": int(m.layer), "lies_on": list(m.lies_on),
                 "active": bool(m.active), "h": int(m.h), "w": int(m.w), "thickness": float(m.thickness)}
        for key in (fields_linear if m.type == "linear" else fields_sphincter):
            pts = np.asarray(getattr(m, key))
            if len(pts):
                entry[key] = [[round(float(c), 9) for c in p] for p in pts]
        muscles.append(entry)
    return {"units": "template", "muscles": muscles}
