"""Ray casting and closest-point binding onto the bodies of :func:`faceforge.skin.binding.bind_skin`.

The per-ray and per-vertex searches the binding's passes (:mod:`faceforge.skin.bind_passes`)
are made of: :func:`_cast` (the best hit per ray), :func:`_closest_fallback` (the closest skull
or lip-ring point for vertices whose rays missed) and :func:`_modiolus_anchors` (the mouth
corners); see the module docstring of :mod:`faceforge.skin.binding`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from faceforge.constants import INT
from faceforge.geometry.rays import RayCaster

if TYPE_CHECKING:
    from faceforge.skin.binding import Body

#: kinds of body (and the per-vertex status codes of :attr:`faceforge.skin.binding.Binding.status`)
UNBOUND, MUSCLE, CRANIUM, MANDIBLE = 0, 1, 2, 3
_KIND_CODES = {"muscle": MUSCLE, "cranium": CRANIUM, "mandible": MANDIBLE}


def _merge(bodies: list[Body], ids: list[int]):
    verts, faces, owner, off = [], [], [], 0
    for i in ids:
        b = bodies[i]
        verts.append(b.vertices)
        faces.append(b.faces + off)
        owner.append(np.full(len(b.faces), i, INT))
        off += len(b.vertices)
    return np.concatenate(verts), np.concatenate(faces), np.concatenate(owner)


def _cast(bodies, ids, rank, origins, dirs, max_distance, allowed, ray_side=None, side_of=None,
          strict=None, face_sides=None):
    """Best hit per ray among ``bodies[ids]``: smallest ``rank`` then distance.

    ``allowed (k, n_bodies) bool`` filters bodies per ray; with ``side_of`` a hit
    on the other side of the lip line than its ray's ``ray_side`` is dropped, and on the
    bodies marked ``strict (n_bodies,) bool`` also a hit far from the lips (side 0); on a body
    with ``face_sides[i] (f_i,)`` (a ring around the mouth, :func:`mouth.ring_face_sides`) the
    hit face's side is used instead of the hit point's. Returns
    ``(body (k,), local_face (k,), points (k, 3), dist (k,))``, body -1 on a miss.
    """
    k = len(origins)
    body = np.full(k, -1, INT)
    face = np.full(k, -1, INT)
    pts = np.full((k, 3), np.nan)
    dist = np.full(k, np.inf)
    if k == 0 or not ids:
        return body, face, pts, dist
    v, f, owner = _merge(bodies, ids)
    first_face = {}
    start = 0
    for i in ids:
        first_face[i] = start
        start += len(bodies[i].faces)
    ray, tri, loc, t = RayCaster(v, f).all_hits(origins, dirs)
    b = owner[tri]
    keep = (t >= 0) & (t <= max_distance) & allowed[ray, b]
    ray, tri, loc, t, b = ray[keep], tri[keep], loc[keep], t[keep], b[keep]
    if side_of is not None and len(ray):
        rs = np.asarray(ray_side)[ray]
        check = rs != 0
        ok = np.ones(len(ray), bool)
        side = np.asarray(side_of(loc[check]))
        if face_sides is not None:   # rings around the mouth: the side of the face's rows
            label = np.zeros(len(f), np.int8)
            labelled = np.zeros(len(f), bool)
            for i in ids:
                if face_sides[i] is not None:
                    label[first_face[i]:first_face[i] + len(bodies[i].faces)] = face_sides[i]
                    labelled[first_face[i]:first_face[i] + len(bodies[i].faces)] = True
            t_check = tri[check]
            side = np.where(labelled[t_check], label[t_check], side)
        agree = side * rs[check]
        ok[check] = agree >= 0
        if strict is not None:
            ok[check] &= ~np.asarray(strict, bool)[b[check]] | (agree > 0)
        ray, tri, loc, t, b = ray[ok], tri[ok], loc[ok], t[ok], b[ok]
    if len(ray) == 0:
        return body, face, pts, dist
    order = np.lexsort((tri, t, rank[b], ray))  # face id breaks ties: deterministic
    ray, tri, loc, t, b = ray[order], tri[order], loc[order], t[order], b[order]
    first = np.r_[True, ray[1:] != ray[:-1]]
    r = ray[first]
    body[r] = b[first]
    offsets = np.array([first_face[i] for i in b[first]], INT)
    face[r] = tri[first] - offsets
    pts[r] = loc[first]
    dist[r] = t[first]
    return body, face, pts, dist


def _own_arc(body: Body, side: int, face_sides, i: int, side_of) -> np.ndarray:
    """Faces ``(k,) int`` of a muscle around the mouth (``bodies[i]``) on lip side ``side``:
    by the ring's rows (``face_sides[i]``) where given, else by where their centroids lie;
    every face for ``side`` 0 (the mouth corners, where the two arcs meet)."""
    if side == 0:
        return np.arange(len(body.faces))
    rows = None if face_sides is None else face_sides[i]
    if rows is None:
        rows = side_of(body.vertices[body.faces].mean(axis=1))
    return np.flatnonzero(np.asarray(rows) == side)


def _modiolus_anchors(v, bodies, around, sides, mask, max_distance, allowed, body, face, pts, dist,
                      side_of=None, face_sides=None) -> np.ndarray:
    """Rebind the skin at the mouth corners (``mask (n,) bool``) to the closest point of the
    muscles around the mouth (``around (n_bodies,) bool``) within ``max_distance``: a lip
    vertex (``sides`` +1 / -1) on its own arc (:func:`_own_arc`), a vertex of neither lip
    anywhere on them. Updates the arrays in place (a vertex with nothing in reach keeps its
    anchor) and returns the ``(n,) bool`` mask of the vertices rebound. See the module
    docstring, the modiolus."""
    from faceforge.geometry.surface_points import closest_points

    done = np.zeros(len(v), bool)
    for side in (1, -1, 0):
        todo = np.flatnonzero(mask & (sides == side))
        best = np.full(len(todo), np.inf)
        for i in np.flatnonzero(around) if len(todo) else ():
            sub = _own_arc(bodies[i], side, face_sides, i, side_of)
            if len(sub) == 0:
                continue
            p, d, tri = closest_points(v[todo], bodies[i].vertices, bodies[i].faces[sub])
            take = (d < best) & (d <= max_distance) & allowed[todo, i]
            best[take] = d[take]
            t = todo[take]
            body[t], face[t], pts[t], dist[t] = i, sub[tri[take]], p[take], d[take]
            done[t] = True
    return done


def _closest_fallback(v, bodies, kinds, sides, max_distance, body, face, pts, dist, mask,
                      side_of=None, allowed=None, around=None, face_sides=None,
                      lips_to_ring=False) -> np.ndarray:
    """Vertices whose two rays found nothing: the closest skull point, if near enough.

    Rays miss where the skin looks into a hole of the skull (eyelids and eye
    sockets into the orbits, nostrils into the nasal aperture) or along the lip
    line when they meet only the other jaw's bone. Such a vertex binds to the
    closest point of the skull within ``max_distance``: of the cranium above the
    lip line, of the mandible below it, of either elsewhere. A lip vertex (``sides``
    +1 / -1, given ``side_of``) may also bind to the closest point of a muscle on its
    own side of the lip line (the orbicularis oris), whichever is nearer: the lips are
    muscle, and bound to the teeth they did not follow the muscles that move them.
    ``allowed (n, n_bodies) bool`` (optional) filters bodies per vertex as for the rays
    (a lip never binds to the other lip's muscles).

    With ``around (n_bodies,) bool`` (the muscles around the mouth, ``body_sides``)
    a lip vertex first looks at the own half of those only -- their faces on its side
    (``face_sides[i]``, a ring's rows, where given; else the faces whose centroid lies on its
    side): at the inner lips the two halves of the sphincter come within a few
    mm of each other and the closest point of the whole muscle is often on the other lip
    (MakeHuman FDPs 2.6 and 2.3), which used to leave the inner lips on the teeth. With
    ``lips_to_ring`` a lip vertex takes its own half of those muscles whenever one lies
    within ``max_distance``, nearer than the bone or not: on ICT the upper lip's outer
    contour lies over the ring's lower arc, its own arc 1.66 cm away and the teeth 1.59, and
    bound to the teeth FDP 8.1 followed no muscle. A lip vertex still unbound then takes the
    closest point, on its own side, of any other muscle it may bind to. Updates the arrays in
    place; returns the ``(n,) bool`` mask of the vertices bound this way.
    """
    from faceforge.geometry.surface_points import closest_points
    from faceforge.skin.arc_points import arc_closest

    done = np.zeros(len(v), bool)
    lip = (MUSCLE,) if side_of is not None else ()
    ring = around is not None and side_of is not None
    # (plan, ring): a plan lists (lip side, body kinds); on a ring tier the muscles around the
    # mouth (their own half) are the only muscles taken, on the others every other muscle
    tiers = [(((1, (CRANIUM,) + lip), (-1, (MANDIBLE,) + lip), (0, (CRANIUM, MANDIBLE))), True)]
    if ring:
        tiers.append((((1, (MUSCLE,)), (-1, (MUSCLE,))), False))
        if lips_to_ring:
            tiers.insert(0, (((1, (MUSCLE,)), (-1, (MUSCLE,))), True))
    for plan, ring_tier in tiers:
        for side, allowed_kinds in plan:
            todo = np.flatnonzero((body < 0) & (sides == side) & mask)
            own = [i for i in range(len(bodies)) if kinds[i] in allowed_kinds]
            if len(todo) == 0 or not own:
                continue
            best = np.full(len(todo), np.inf)
            for i in own:
                half = kinds[i] == MUSCLE and around is not None and bool(around[i])
                if kinds[i] == MUSCLE and around is not None and half != ring_tier:
                    continue
                bv, bf = bodies[i].vertices, bodies[i].faces
                sub = _own_arc(bodies[i], side, face_sides, i, side_of) if half else np.arange(len(bf))
                if len(sub) == 0:
                    continue
                # the own arc at the vertex's place along the lip (skin.arc_points)
                p, d, tri = (arc_closest if half else closest_points)(v[todo], bv, bf[sub])
                tri = sub[tri]
                take = (d < best) & (d <= max_distance)
                if allowed is not None:
                    take &= allowed[todo, i]
                if kinds[i] == MUSCLE and not half:   # a muscle's part on the vertex's side only
                    take &= side_of(p) == side
                best[take] = d[take]
                t = todo[take]
                body[t], face[t], pts[t], dist[t] = i, tri[take], p[take], d[take]
                done[t] = True
    return done
