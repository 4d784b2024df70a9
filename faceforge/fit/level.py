"""Muscles whose origin is soft tissue keep the template's line of pull (beyond §7).

The muscle map is morphed with the skull, and the mouth's shift (:mod:`faceforge.fit.mouth`)
moves a linear muscle's insertion with the lips while its origin stays where the warp put it.
For a muscle that runs back from the mouth corner to the side of the face, the risorius (from
the masseteric fascia, soft tissue, to the modiolus), that tilts the whole line: the template's
risorius pulls the corner out and 4° down, the fitted ones up by 42° (MakeHuman), 24° (ICT)
and 49° (MediaPipe) (docs/notes/recog22.md): the stretch FAP became a second smile. A fixed
template offset cannot level three fits that tilt it by 28-53°.

:func:`level_origins` turns such a muscle's origin up or down (a shear along the face's up axis,
growing from nothing at the insertion to the whole step at the origin) until its line, seen from
the front, makes the template's angle with the horizontal again. The points stay where the
other axes put them; the muscles are then built on the bone from these points as everywhere
(:func:`faceforge.anatomy.muscles.build.build_muscles_on` projects them onto what they lie on).

Functions on arrays; the frame is the fit's (+Y up, +X the subject's left).
"""

from __future__ import annotations

import numpy as np

from faceforge.anatomy.muscles.muscle_map import POINTS_ORDER

__all__ = ["frontal_angle", "level_map", "level_origins", "point_rows"]


def point_rows(spec) -> dict:
    """``{key: slice}`` of ``spec.points()`` (:data:`POINTS_ORDER`: origin, fibre_a, fibre_b,
    insertion, ...) for a :class:`~faceforge.anatomy.muscles.muscle_map.MuscleSpec`."""
    out, start = {}, 0
    for key in POINTS_ORDER:
        value = getattr(spec, key, None)
        n = 0 if value is None else len(value)
        out[key] = slice(start, start + n)
        start += n
    return out


def frontal_angle(origin: np.ndarray, insertion: np.ndarray, up=(0.0, 1.0, 0.0),
                  lateral=(1.0, 0.0, 0.0)) -> float:
    """The line from the insertion's centre to the origin's (points (k, 3)) seen from the front:
    its angle above the horizontal in radians, ``atan2(rise along up, |run along lateral|)``."""
    d = np.asarray(origin, float).reshape(-1, 3).mean(axis=0) - np.asarray(insertion, float).reshape(-1, 3).mean(axis=0)
    return float(np.arctan2(d @ np.asarray(up, float), abs(d @ np.asarray(lateral, float))))


def level_origins(points: np.ndarray, template_points: np.ndarray, rows: dict, up=(0.0, 1.0, 0.0),
                  lateral=(1.0, 0.0, 0.0)) -> np.ndarray:
    """A linear muscle's fitted ``points (k, 3)`` (``spec.points()`` order; ``rows``:
    :func:`point_rows`) with its origin moved along ``up`` (unit) so that
    :func:`frontal_angle` of the fitted line equals the template's (``template_points (k, 3)``,
    the template frame's +Y up and +X lateral). The origin points move by the whole step, the
    fibre lines' inner points (``fibre_a`` / ``fibre_b``) by the fraction of the way from the
    insertion to the origin at which they lie, the insertion not at all. Returns a new (k, 3)."""
    p = np.array(points, dtype=np.float64).reshape(-1, 3)
    t = np.asarray(template_points, dtype=np.float64).reshape(-1, 3)
    u, x = np.asarray(up, float), np.asarray(lateral, float)
    o, i = p[rows["origin"]], p[rows["insertion"]]
    d = o.mean(axis=0) - i.mean(axis=0)
    want = abs(d @ x) * np.tan(frontal_angle(t[rows["origin"]], t[rows["insertion"]]))
    step = (want - d @ u) * u                                 # the origin's move along up
    i_mid, o_mid = i.mean(axis=0), o.mean(axis=0)
    span = float((o_mid - i_mid) @ (o_mid - i_mid))
    p[rows["origin"]] += step
    for key in ("fibre_a", "fibre_b"):
        inner = p[rows[key]]
        if len(inner) and span > 0:
            share = np.clip(((inner - i_mid) @ (o_mid - i_mid)) / span, 0.0, 1.0)
            p[rows[key]] = inner + share[:, None] * step
    return p


def level_map(result, specs, names) -> object:
    """The :class:`~faceforge.fit.head.FitResult` ``result`` with the linear muscles named in
    ``names`` (``fit.level_muscles``: a name, or a prefix before ``_L`` / ``_R``) levelled by
    :func:`level_origins` against the template ``specs`` ([MuscleSpec]); on a symmetric fit
    (``result.mirror``) the right muscle is the mirror image of the left again. Its muscles
    are not rebuilt here (:func:`faceforge.fit.symmetry.rebuild_muscles`)."""
    from dataclasses import replace

    from faceforge.fit.symmetry import _twins

    mirror = result.mirror
    lateral = np.array([1.0, 0.0, 0.0]) if mirror is None else np.asarray(mirror.normal, float)
    up = np.array([0.0, 1.0, 0.0]) - lateral[1] * lateral
    up /= np.linalg.norm(up)
    points, done = dict(result.muscle_points), {}
    for spec in specs:
        base = spec.name[:-2] if spec.name[-2:] in ("_L", "_R") else spec.name
        if spec.type == "linear" and (spec.name in names or base in names) and spec.name in points:
            done[spec.name] = level_origins(points[spec.name], spec.points(), point_rows(spec), up, lateral)
    if mirror is not None and done:
        done = _twins(done, mirror)
    points.update(done)
    return replace(result, muscle_points=points, info=dict(result.info, levelled=sorted(done)))
