"""Building a muscle map on a skull, deepest layer first, thickness by Eq. 5 (§6, §7).

The template stores a muscle's thickness as a fraction of the template skull's diagonal, so
Eq. 5 (``t_head = (d_head / d_skull) t``) reads ``t_head = fraction * d``, ``d`` the diagonal of
the skull the muscles are built on.
"""

from __future__ import annotations

import numpy as np


def eq5_thickness(fraction: float, skull_diagonal: float) -> float:
    """Muscle thickness in head units from the template's fraction of the skull diagonal (Eq. 5)."""
    return float(fraction) * float(skull_diagonal)


def build_muscles_on(specs, cranium, mandible, skull_diagonal: float, stiffness: dict | None = None,
                     carry_inner: float = 0.0, protrusion: float = 0.0, mirror=None,
                     inner_on_bone: bool = False, closure_centre: float = 0.0, **shape) -> list:
    """Build every muscle of ``specs`` on the given skull, deepest layer first.

    Each muscle's action lines are projected (outermost surface) onto the concatenation of
    the bodies it lies on (cranium, mandible, deeper muscles); thickness is Eq. 5:
    ``spec.thickness * skull_diagonal``. ``stiffness``: ``{"linear": {...}, "sphincter":
    {...}}`` of the config (empty: geometry only); ``carry_inner``: the sphincter's
    ``carry_inner`` of :func:`build_sphincter_muscle` (``muscle.sphincter.carry_inner``, on
    the skull's faces; it does not change the rest geometry); ``protrusion``: the sphincter's
    ``protrusion`` (``muscle.sphincter.protrusion``); ``mirror``
    (:class:`faceforge.geometry.mirror.Mirror`, a symmetric head): a muscle that is
    ``mirror_of`` a muscle built before it is built as that muscle's mirror image;
    ``inner_on_bone`` (``muscle.sphincter.inner_on_bone``): a sphincter's inner loop (A1, the
    lips' contact line) lies on the bones it lies on only (:func:`_inner_on_bone`);
    ``closure_centre``: the sphincter's ``closure_centre`` (``muscle.sphincter.closure_centre``);
    ``shape``: its ``closure_vertical``, ``eversion_up`` and ``bulge`` (:func:`build_sphincter_muscle`)
    (:func:`faceforge.anatomy.muscles.mirror.mirror_muscle`). Returns ``[Muscle]`` in build order.
    Raises :class:`~faceforge.exceptions.TemplateError` naming the muscle that cannot be built.
    """
    from faceforge.anatomy.muscles.action_line import ActionLine
    from faceforge.anatomy.layers import expand_lies_on
    from faceforge.anatomy.muscles.muscle import build_linear_muscle, build_sphincter_muscle
    from faceforge.anatomy.muscles.muscle_map import mirrored_name
    from faceforge.anatomy.muscles.sphincter import align_loops
    from faceforge.exceptions import TemplateError

    stiffness = stiffness or {}
    bodies = {"cranium": cranium, "mandible": mandible}
    built, by_name, exact = [], {}, set()
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

        try:
            twin = by_name.get(spec.mirror_of) if mirror is not None and spec.mirror_of else None
            if twin is not None:
                from faceforge.anatomy.muscles.mirror import mirror_muscle

                left_parts = [(n, bodies[n]) for n in expand_lies_on(twin.lies_on)]
                right_parts = list(zip(expand_lies_on(spec.lies_on), parts))
                m = mirror_muscle(twin, spec.name, tuple(spec.lies_on), left_parts, right_parts, mirror, exact)
                exact.update((twin.name, spec.name))
            elif spec.type == "linear":
                al = {k: line(p) for k, p in lines.items()}
                if mirror is not None and mirrored_name(spec.name) == spec.name:   # a midline muscle
                    from faceforge.anatomy.muscles.mirror import symmetric_sheet_lines

                    al = symmetric_sheet_lines(al, list(zip(expand_lies_on(spec.lies_on), parts)), mirror, exact)
                if getattr(spec, "max_contraction", None) is not None:
                    kw["max_contraction"] = spec.max_contraction
                m = build_linear_muscle(spec.name, al["A3"], al["A1"], al["A0"], al["A2"], v, f, spec.h, spec.w, t,
                                        stiffness.get("linear", {}), **kw)
            else:
                inner, outer = align_loops(spec.inner, spec.outer)
                bone = np.concatenate([np.full(len(p[1]), n in ("cranium", "mandible"))
                                       for n, p in zip(expand_lies_on(spec.lies_on), parts)])
                loops = [_inner_on_bone(inner, v, f, bone) if inner_on_bone and bone.any() else line(inner, True),
                         line(outer, True)]
                if mirror is not None:   # its right half the mirror image of its left half
                    from faceforge.anatomy.muscles.mirror import symmetric_loop

                    named = list(zip(expand_lies_on(spec.lies_on), parts))
                    loops = [symmetric_loop(x, named, mirror, exact) for x in loops]
                m = build_sphincter_muscle(spec.name, loops[0], loops[1], v, f, spec.h,
                                           spec.w, t, stiffness.get("sphincter", {}), carry_inner=carry_inner,
                                           carry_faces=bone, protrusion=protrusion,
                                           closure_centre=closure_centre, **shape, **kw)
                if mirror is not None:   # its cells split as mirror images too
                    from dataclasses import replace

                    from faceforge.anatomy.muscles.mirror import symmetric_ring_faces

                    m = replace(m, faces=symmetric_ring_faces(m))
        except ValueError as exc:   # e.g. an action line collapsing to one point on these surfaces
            raise TemplateError(f"muscle {spec.name!r} cannot be built on this skull: {exc}") from exc
        bodies[spec.name] = (m.rest_positions, m.faces)
        by_name[spec.name] = m
        built.append(m)
    return built


def _inner_on_bone(points, vertices, faces, bone):
    """A sphincter's closed inner loop through ``points (p, 3)``, projected (outermost) onto the
    faces ``faces[bone]`` (``bone`` (m,) bool: the skull's faces among the bodies it lies on) of
    the concatenated ``(vertices, faces)``; face ids in the concatenation's numbering.

    The lips' contact line rests on the teeth and gums (the mucosa slides over them,
    ``carry_inner``); the lip muscles insert into the ring from outside, through its outer loop.
    Projected onto every body, the contact line's middle samples lay on the levator labii
    insertions wherever the fitted front teeth sit behind them, and a levator then dragged the
    contact line back into the head and sideways (its fibres run up, back and out to the frontal
    process of the maxilla): on MakeHuman's symmetric fit, whose front teeth the clearance moves
    6 mm back, levator_labii_inner_R at c = 0.5 moved FDP 8.1 52 MNS sideways, 57 back and 2
    down instead of up (teeth in front: 25 up)."""
    from faceforge.anatomy.muscles.action_line import ActionLine
    from faceforge.geometry.surface_points import SurfacePoints

    ids = np.flatnonzero(bone)
    line = ActionLine.from_points(points, vertices, faces[ids], closed=True, project="outermost")
    return ActionLine(SurfacePoints(ids[line.points.face_ids], line.points.bary), True)
