"""Muscles built as mirror images: a symmetric rig for a symmetric head (issue 25).

On a head that is its own mirror image, a right muscle built from its own (mirrored) action
lines still differs from its left twin: each line is projected onto the *outermost* surface
beneath it, and a 1-2 mm difference in the bone or the deeper muscles picks another layer, so
the twins move the skin differently (MakeHuman's zygomatici moved the two mouth corners 155 /
66 MW). :func:`mirror_muscle` builds the right twin as the exact mirror image of the left one
instead: mirrored rest particles, the left's faces with their winding reversed (a reflection
turns a surface inside out), and each action-line point on the mirror image of the left's:

* on a deeper muscle that has a mirrored twin (``X_L`` -> ``X_R``, itself built by this
  function): the same face with reversed barycentric coordinates, exactly;
* on the bone or a midline muscle (the orbicularis oris, the mentalis): the closest point of
  that body to the mirrored point (as symmetric as the body is).

:func:`symmetric_loop` makes a sphincter's loop (the orbicularis oris is its own mirror image)
symmetric: its right half is the mirror image of its left half.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from faceforge.constants import FLOAT, INT
from faceforge.geometry.surface_points import SurfacePoints, project_to_surface


def twin_name(name: str) -> str:
    """``X_L`` <-> ``X_R``; other names are their own twins."""
    if name.endswith("_L"):
        return name[:-2] + "_R"
    if name.endswith("_R"):
        return name[:-2] + "_L"
    return name


def _mirror_points(points: SurfacePoints, left_parts, right_parts, mirror, exact: set) -> SurfacePoints:
    """Surface points on the concatenated ``left_parts`` [(name, (v, f))] -> their mirror images
    on the concatenated ``right_parts``; a part named in ``exact`` (a mirrored twin) maps face by
    face."""
    lstart = np.cumsum([0] + [len(f) for _, (_, f) in left_parts])
    rstart = {name: int(s) for (name, _), s in zip(right_parts, np.cumsum([0] + [len(f) for _, (_, f) in right_parts]))}
    rmesh = {name: mesh for name, mesh in right_parts}
    fid, bary = points.face_ids.copy(), points.bary.copy()
    part = np.searchsorted(lstart, points.face_ids, side="right") - 1
    for k, (lname, (lv, lf)) in enumerate(left_parts):
        sel = np.flatnonzero(part == k)
        if not len(sel):
            continue
        rname = twin_name(lname)
        if rname not in rstart:
            raise ValueError(f"the mirror image of {lname!r} is not among the bodies the twin lies on")
        local = points.face_ids[sel] - lstart[k]
        if lname in exact and rname != lname:
            fid[sel] = local + rstart[rname]
            bary[sel] = points.bary[sel][:, ::-1]
            continue
        p = np.einsum("ij,ijk->ik", points.bary[sel], np.asarray(lv, FLOAT)[np.asarray(lf)[local]])
        sp = project_to_surface(mirror(p), *rmesh[rname])
        fid[sel] = sp.face_ids + rstart[rname]
        bary[sel] = sp.bary
    return SurfacePoints(fid.astype(INT), bary)


def mirror_muscle(left, name: str, lies_on: tuple, left_parts, right_parts, mirror, exact: set):
    """The mirror image of the built linear Muscle ``left`` as the muscle ``name`` lying on
    ``lies_on``.

    Its action lines are the mirror images of the left's (module docstring) and its rest mesh
    is built on them as any muscle's is, so the rest state stays an exact fixed point of its
    constraints; it then differs from the mirrored left mesh only as much as the bodies beneath
    differ from their mirror images (the fitted bone). Its faces are the left's, turned, so the
    twins' surfaces correspond face by face.

    left_parts, right_parts : [(body name, (vertices (n, 3), faces (m, 3)))]
        The bodies each lies on, in ``expand_lies_on`` order (the concatenation its action
        lines' surface points refer to).
    mirror : :class:`faceforge.geometry.mirror.Mirror`
    exact : set of str
        Bodies already built as mirror images of their twins (face-by-face mapping).
    """
    from faceforge.anatomy.muscles.muscle import _build

    if left.kind != "linear":
        raise ValueError(f"muscle {left.name!r}: only linear muscles are mirrored, not a {left.kind}")
    lines = {k: replace(line, points=_mirror_points(line.points, left_parts, right_parts, mirror, exact))
             for k, line in left.lines.items()}
    v = np.vstack([m[0] for _, m in right_parts])
    f = np.vstack([m[1] + o for (_, m), o in zip(right_parts, np.cumsum([0] + [len(m[0]) for _, m in right_parts]))])
    m = _build(name, "linear", left.topology, lines, v, f, left.thickness, dict(left.stiffness),
               lies_on=tuple(lies_on), layer=left.layer, active=left.active, max_contraction=left.max_contraction)
    return replace(m, faces=np.ascontiguousarray(left.faces[:, ::-1]))


def symmetric_loop(line, parts, mirror, exact: set):
    """A closed action line (a sphincter's loop) of a muscle that is its own mirror image, made
    symmetric: its run of surface points on the left of the plane (``mirror.normal``'s side) is
    kept, the right run is replaced by the left run's mirror images in reverse order
    (:func:`_mirror_points`), a point on the plane is put at each crossing (the closest point of
    the body beneath to the crossing), and the loop starts at the crossing it passes after its
    old start. Sampled at regular arc length from there (Eq. 3), sample ``k`` and sample ``-k``
    are then mirror images. A loop that does not cross the plane exactly twice is returned as it
    is.

    line : ActionLine (closed) on the concatenated ``parts`` [(body name, (v, f))], which hold
    both twins of every body pair it lies on.
    """
    v = np.vstack([m[0] for _, m in parts])
    f = np.vstack([m[1] + o for (_, m), o in zip(parts, np.cumsum([0] + [len(m[0]) for _, m in parts]))])
    pos = line.positions(v, f)
    left = mirror.side(pos) >= 0.0
    ups = np.flatnonzero(left & ~np.roll(left, 1))     # first left point after a right one
    if len(ups) != 1 or left.all():
        return line
    order = np.roll(np.arange(len(pos)), -int(ups[0]))
    run = order[:int(left.sum())]
    if not left[run].all():
        return line
    kept = line.points.take(run)
    image = _mirror_points(kept.take(np.arange(len(run))[::-1]), parts, parts, mirror, exact)
    cross = [_on_plane(kept.take([i]), v, f, mirror) for i in (len(run) - 1, 0)]
    # the loop passes the old start (inside ``kept`` when it lies on the left) before ``cross[0]``
    loop = [cross[0], image, cross[1], kept]
    if not left[0]:   # the old start was on the right: start at the crossing after it
        loop = [cross[1], kept, cross[0], image]
    return replace(line, points=SurfacePoints.concatenate(loop))


def _on_plane(point: SurfacePoints, v, f, mirror) -> SurfacePoints:
    """The closest point of the surface (v, f) to the foot on the plane of one surface point."""
    p = mirror.onto_plane(point.positions(v, f))
    return project_to_surface(p, v, f)
