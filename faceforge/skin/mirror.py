"""A symmetric head's binding made symmetric (issue 25): each right skin vertex is bound as the
mirror image of its left partner.

Ray casting binds every vertex on its own, and on a symmetric head a mirror pair of skin
vertices can meet different bodies (52 of MakeHuman's 4,295 vertices did, all near the mouth:
a ray grazing the edge of a muscle on one side misses it on the other). When the fit made the
rig symmetric (fit.npz's mirror), :func:`mirror_binding` replaces the anchors of every vertex on
the right of the plane by the mirror images of its partner's: on a muscle's mirrored twin
(``X_L`` -> ``X_R``, built face by face as its mirror image,
:func:`faceforge.fit.symmetry.symmetrize_bones`) the same face with the barycentric coordinates
reversed (the twin's faces are the left's, turned); on a body that is its own mirror image (the
skull, the orbicularis oris, the mentalis) the closest point of that body to the mirrored anchor.
Vertices on the plane keep their own anchors; one bound to a muscle with a twin gets the mirror
image of that anchor on the twin as well (it then follows both, as a midline vertex should).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from faceforge.anatomy.muscles.muscle_map import mirrored_name
from faceforge.constants import FLOAT, INT

#: skin vertices pair up when a mirror image lies within this fraction of the skin's diagonal
#: of a vertex (MakeHuman: 0; ICT 1.6e-4); vertices this close to the plane keep their anchors
MIRROR_TOLERANCE = 5e-4


def skin_partners(vertices: np.ndarray, mirror, tolerance: float) -> np.ndarray | None:
    """(n,) the vertex nearest each vertex's mirror image, or None when one lies farther than
    ``tolerance`` (mesh units): the skin is not its own mirror image."""
    j, d = mirror.partners(vertices)
    return None if d.max() > tolerance else j.astype(INT)


def mirror_binding(binding, vertices: np.ndarray, bodies, mirror, tolerance: float):
    """The :class:`faceforge.skin.binding.Binding` with each right vertex's anchors replaced by
    the mirror images of its partner's (module docstring); ``binding`` itself when the skin
    ``vertices (n, 3)`` is not its own mirror image within ``tolerance`` (mesh units).

    bodies : sequence of :class:`faceforge.skin.binding.Body` in ``binding.body_names`` order.
    Returns ``(Binding, count of right vertices rebound)``.
    """
    from faceforge.geometry.surface_points import project_to_surface

    v = np.asarray(vertices, dtype=FLOAT)
    partner = skin_partners(v, mirror, tolerance)
    if partner is None:
        return binding, 0
    side = mirror.side(v)
    right = (side < -tolerance) & (side[partner] > tolerance)
    names = list(binding.body_names)
    index = {n: i for i, n in enumerate(names)}
    twin = np.array([index.get(mirrored_name(n), i) for i, n in enumerate(names)], dtype=INT)
    exact = np.array([twin[i] != i and len(bodies[i].faces) == len(bodies[twin[i]].faces)
                      for i in range(len(names))])
    keep = ~right[binding.vertex_ids]
    rv = np.flatnonzero(right)
    lo = np.searchsorted(binding.vertex_ids, partner[rv], side="left")
    hi = np.searchsorted(binding.vertex_ids, partner[rv], side="right")
    src = np.concatenate([np.arange(a, b) for a, b in zip(lo, hi)] + [np.zeros(0, INT)]).astype(INT)
    new_vid = np.repeat(rv, hi - lo).astype(INT)
    body = twin[binding.body[src]]
    face, bary = binding.face_ids[src].copy(), binding.bary[src].copy()
    on_twin = exact[binding.body[src]]
    bary[on_twin] = bary[on_twin][:, ::-1]
    points = np.zeros((len(src), 3))
    for b in np.unique(body):
        sel = np.flatnonzero(body == b)
        bv, bf = bodies[b].vertices, bodies[b].faces
        t = sel[on_twin[sel]]
        points[t] = np.einsum("ij,ijk->ik", bary[t], bv[bf[face[t]]])
        o = sel[~on_twin[sel]]
        if len(o):
            sp = project_to_surface(mirror(binding.points[src[o]]), bv, bf)
            face[o], bary[o] = sp.face_ids, sp.bary
            points[o] = sp.positions(bv, bf)
    # a vertex on the plane bound to one of two twins follows that twin only: it gets the
    # mirror image of that anchor on the other twin as well, and follows both
    mid = np.flatnonzero(~right[binding.vertex_ids] & (np.abs(side[binding.vertex_ids]) <= tolerance)
                         & exact[binding.body])
    new_vid = np.concatenate([new_vid, binding.vertex_ids[mid]])
    body = np.concatenate([body, twin[binding.body[mid]]])
    face = np.concatenate([face, binding.face_ids[mid]])
    bary = np.concatenate([bary, binding.bary[mid][:, ::-1]])
    points = np.concatenate([points, mirror(binding.points[mid])])
    src = np.concatenate([src, mid])
    # one bound off the plane on a body that is its own mirror image (a closest point on the
    # orbicularis oris, which has two at equal distance) follows one side of that body: it gets
    # the closest point of the body to the mirrored anchor as well (MakeHuman's FDP 8.1 was
    # bound 6 mm right of the plane, and the right levator labii inner moved it 15 % more)
    own = np.flatnonzero(~right[binding.vertex_ids] & (np.abs(side[binding.vertex_ids]) <= tolerance)
                         & (twin[binding.body] == np.arange(len(names))[binding.body])
                         & (np.abs(mirror.side(binding.points)) > tolerance))
    for b in np.unique(binding.body[own]):
        sel = own[binding.body[own] == b]
        sp = project_to_surface(mirror(binding.points[sel]), bodies[b].vertices, bodies[b].faces)
        new_vid = np.concatenate([new_vid, binding.vertex_ids[sel]])
        body = np.concatenate([body, binding.body[sel]])
        face = np.concatenate([face, sp.face_ids])
        bary = np.concatenate([bary, sp.bary])
        points = np.concatenate([points, sp.positions(bodies[b].vertices, bodies[b].faces)])
        src = np.concatenate([src, sel])
    cat = {k: np.concatenate([a[keep], b]) for k, (a, b) in {
        "vertex_ids": (binding.vertex_ids, new_vid), "body": (binding.body, body),
        "face_ids": (binding.face_ids, face), "bary": (binding.bary, bary),
        "points": (binding.points, points), "distance": (binding.distance, binding.distance[src]),
        "outward": (binding.outward, binding.outward[src]), "closest": (binding.closest, binding.closest[src])}.items()}
    order = np.argsort(cat["vertex_ids"], kind="stable")
    status = binding.status.copy()
    status[rv] = binding.status[partner[rv]]
    normals = binding.normals.copy()
    normals[rv] = mirror.direction(binding.normals[partner[rv]])
    out = replace(binding, status=status, normals=normals, **{k: a[order] for k, a in cat.items()})
    return out, int(right.sum())

