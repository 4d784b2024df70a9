"""The passes of :func:`faceforge.skin.binding.bind_skin` (§8), over one shared state.

:func:`bind_rules` fixes what each skin vertex may bind to (:class:`Rules`); :func:`ray_passes`
casts the paper's rays (outward onto the muscles, inward onto the muscles, inward onto the
skull); :func:`fallbacks` binds the vertices whose rays missed to the closest point and moves
the modiolus skin to the muscles around the mouth; :func:`commissure_anchors` binds the lip skin
at the inner lip corners to the whole ring; :func:`second_anchors` adds the anchors on
the muscles that insert into the skin through those above them. See the module docstring of
:mod:`faceforge.skin.binding`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from faceforge.constants import INT
from faceforge.skin.casting import (
    _KIND_CODES, CRANIUM, MANDIBLE, MUSCLE, _cast, _closest_fallback, _modiolus_anchors)
from faceforge.skin.mouth import AROUND_MOUTH


@dataclass(frozen=True, eq=False)
class Rules:
    """What each skin vertex may bind to, fixed for one :func:`faceforge.skin.binding.bind_skin` call.

    bodies : list of Body (nb); kinds : (nb,) int (``MUSCLE``, ``CRANIUM``, ``MANDIBLE``);
    rank : (nb,) int superficiality (smaller first); sides : (n,) int lip side per vertex;
    allowed : (n, max(nb, 1)) bool, the bodies each vertex may bind to; max_distance : float,
    skin units; side_of : callable or None; strict : (nb,) bool or None, the bodies whose hits
    must lie on a lip vertex's side of the lip line (the muscles, with ``side_of``); around :
    (nb,) bool or None, the muscles around the mouth (with ``side_of`` and ``body_sides``);
    face_sides : per body None or (f_i,) int8 (see :func:`faceforge.skin.binding.bind_skin`).
    """

    bodies: list
    kinds: np.ndarray
    rank: np.ndarray
    sides: np.ndarray
    allowed: np.ndarray
    max_distance: float
    side_of: object = None
    strict: np.ndarray | None = None
    around: np.ndarray | None = None
    face_sides: object = None

    def cast(self, ids, rank, rows, origins, dirs):
        """``casting._cast`` of the vertices ``rows`` ((k,) int) from ``origins`` (k, 3) along
        ``dirs`` (k, 3) onto the bodies ``ids`` ranked by ``rank`` ((nb,) int)."""
        return _cast(self.bodies, ids, rank, origins, dirs, self.max_distance, self.allowed[rows],
                     self.sides[rows], self.side_of, self.strict, self.face_sides)


def bind_rules(bodies, sides, max_distance, depth_rank, side_of, body_sides, face_sides) -> Rules:
    """The :class:`Rules` of :func:`faceforge.skin.binding.bind_skin`'s arguments of the same names.

    Default rank: the muscles' order in ``bodies`` (superficial first), the skull parts all 0.
    ``allowed``: an upper-lip vertex (``sides > 0``) never binds to the mandible, a lower-lip
    one never to the cranium; with ``side_of`` and ``body_sides``, never to the other lip's
    muscles either. ValueError when ``depth_rank`` or ``body_sides`` has not one entry per body.
    """
    n, nb = len(sides), len(bodies)
    kinds = np.array([_KIND_CODES[b.kind] for b in bodies], INT)
    muscles = [i for i in range(nb) if kinds[i] == MUSCLE]
    rank = np.zeros(nb, INT)
    rank[muscles] = np.arange(len(muscles))  # superficial first; skull parts all rank 0
    if depth_rank is not None:
        rank = np.asarray(depth_rank, INT).reshape(-1)
        if len(rank) != nb:
            raise ValueError(f"depth_rank {rank.shape} must have one entry per body ({nb})")
    allowed = np.ones((n, max(nb, 1)), bool)
    allowed[np.ix_(sides > 0, kinds == MANDIBLE)] = False
    allowed[np.ix_(sides < 0, kinds == CRANIUM)] = False
    strict = around = None
    if side_of is not None:
        strict = kinds == MUSCLE
    if side_of is not None and body_sides is not None:
        own = np.asarray(body_sides, INT).reshape(-1)
        if len(own) != nb:
            raise ValueError(f"body_sides {own.shape} must have one entry per body ({nb})")
        allowed[np.ix_(sides > 0, own == -1)] = False
        allowed[np.ix_(sides < 0, own == 1)] = False
        around = own == AROUND_MOUTH
    return Rules(bodies, kinds, rank, sides, allowed, max_distance, side_of, strict, around,
                 face_sides)


def ray_passes(v, nrm, rules: Rules) -> tuple:
    """The paper's rays (§8): along the normal onto the muscles, then inward onto the
    muscles, then inward onto the skull, each pass for the vertices still unbound.

    v, nrm : (n, 3) float, rest positions and normals (zero normals cast no ray). Returns
    ``(body (n,) int, -1 unbound; face (n,) int; point (n, 3) float, NaN unbound; distance
    (n,) float, inf unbound, skin units; outward (n,) bool)``.
    """
    n, nb = len(v), len(rules.bodies)
    muscles = [i for i in range(nb) if rules.kinds[i] == MUSCLE]
    skull = [i for i in range(nb) if rules.kinds[i] != MUSCLE]
    body = np.full(n, -1, INT)
    face = np.full(n, -1, INT)
    pts = np.full((n, 3), np.nan)
    dist = np.full(n, np.inf)
    outward = np.zeros(n, bool)
    has_dir = np.linalg.norm(nrm, axis=1) > 0
    for ids, sign in ((muscles, +1.0), (muscles, -1.0), (skull, -1.0)):
        todo = np.flatnonzero((body < 0) & has_dir)
        res = rules.cast(ids, rules.rank, todo, v[todo], sign * nrm[todo])
        hit = res[0] >= 0
        t = todo[hit]
        body[t], face[t], pts[t], dist[t] = (r[hit] for r in res)
        outward[t] = sign > 0
    return body, face, pts, dist, outward


def fallbacks(v, rules: Rules, hits: tuple, mask, lips_to_ring: bool, corner) -> np.ndarray:
    """After the rays: the closest-point fallback (``casting._closest_fallback``, for the
    vertices of ``mask`` (n,) bool), then the modiolus (``casting._modiolus_anchors``).

    Updates ``hits`` (the arrays of :func:`ray_passes`) and ``corner`` ((n,) bool, the
    modiolus skin) in place: ``corner`` ends marking the vertices moved to the muscles around
    the mouth (none without ``around``). Returns ``closest`` (n,) bool, the fallback's anchors.
    """
    body, face, pts, dist, outward = hits
    closest = _closest_fallback(v, rules.bodies, rules.kinds, rules.sides, rules.max_distance, body,
                                face, pts, dist, mask, rules.side_of, rules.allowed, rules.around,
                                rules.face_sides, lips_to_ring)
    around, kinds = rules.around, rules.kinds
    if around is not None:   # the modiolus: corner skin on another muscle moves to the ring
        corner &= (body >= 0) & (kinds[np.maximum(body, 0)] == MUSCLE) & ~around[np.maximum(body, 0)]
        corner[:] = _modiolus_anchors(v, rules.bodies, around, rules.sides, corner, rules.max_distance,
                                      rules.allowed, body, face, pts, dist, rules.side_of,
                                      rules.face_sides)
        outward[corner] = closest[corner] = False
    else:
        corner[:] = False
    return closest


def second_anchors(v, nrm, rules: Rules, anchors: tuple, insertions, outward, corner) -> tuple:
    """Add the second anchors on the muscles of ``insertions`` (indices into the bodies).

    anchors : ``(vertex ids, body, face, point, distance, outward, closest)``, one row per
    bound vertex (k,); outward, corner : (n,) bool (:func:`ray_passes`, :func:`fallbacks`). A
    vertex bound by its ray (not by the fallback nor the modiolus) to another muscle casts its
    same ray on, onto those muscles (nearest hit); a hit adds a row right after the vertex's
    first. Returns the anchors.
    """
    nb = len(rules.bodies)
    ins = [int(i) for i in (insertions or ()) if rules.kinds[i] == MUSCLE]
    if not ins:
        return anchors
    ids, a_body, _, _, _, _, a_closest = anchors
    cand = ids[(rules.kinds[a_body] == MUSCLE) & ~np.isin(a_body, ins) & ~a_closest & ~corner[ids]]
    res = rules.cast(ins, np.zeros(nb, INT), cand, v[cand],    # nearest hit, along the same ray
                     np.where(outward[cand, None], 1.0, -1.0) * nrm[cand])
    hit = res[0] >= 0
    extra = cand[hit]
    order = np.argsort(np.concatenate([ids, extra]), kind="stable")   # each right after its first
    second = (extra,) + tuple(r[hit] for r in res) + (outward[extra], np.zeros(len(extra), bool))
    return tuple(np.concatenate([a, b])[order] for a, b in zip(anchors, second))


def commissure_anchors(v, rules: Rules, hits: tuple, mask) -> np.ndarray:
    """The commissure: lip skin at the inner lip corners (``mask`` (n,) bool) that the passes
    before bound to the muscles around the mouth binds to the closest point of those muscles,
    either arc (``casting._modiolus_anchors`` with every vertex of it on side 0).

    There the upper lip's skin and the lower lip's meet in triangles a fraction of a millimetre
    across, each lip on its own arc of the ring; the two arcs' points under vertices 0.3-0.8 mm
    apart move 0.5-0.8 mm differently (a smile carries the lower lip's corner down and forward
    of the upper's, a frown up through it), and the triangles spanning the lip line turn over
    (MakeHuman's mouthSmile, mouthLeft, jawLeft; ICT's sadness). On the whole ring the
    vertices of both lips take points where its arcs meet, a few tenths of a mm apart. Updates
    ``hits`` (the arrays of :func:`ray_passes`) in place; returns the (n,) bool mask moved.
    """
    body, face, pts, dist, outward = hits
    if rules.around is None:
        return np.zeros(len(v), bool)
    b = np.maximum(body, 0)
    todo = np.asarray(mask, bool) & (body >= 0) & (rules.kinds[b] == MUSCLE) & rules.around[b]
    moved = _modiolus_anchors(v, rules.bodies, rules.around, np.zeros(len(v), INT), todo,
                              rules.max_distance, rules.allowed, body, face, pts, dist,
                              rules.side_of, rules.face_sides)
    outward[moved] = False
    return moved


def vermilion_anchors(v, rules: Rules, hits: tuple, mask) -> np.ndarray:
    """The vermilion (``mask`` (n,) bool, :func:`faceforge.skin.rules.vermilion_mask`): a lip
    vertex of it that the passes before bound to the skull binds to the closest point of its own
    lip's arc of the muscles around the mouth (``casting._modiolus_anchors``).

    On ICT the inward rays of the upper lip's midline meet the upper teeth (the cranium) while the
    lip round them rides the orbicularis oris; when the ring rounds and pushes the lips forward
    (visemes u, a) the skull-bound vermilion stays and its triangles turn over. Updates ``hits``
    (the arrays of :func:`ray_passes`) in place; returns the (n,) bool mask moved.
    """
    body, face, pts, dist, outward = hits
    if rules.around is None:
        return np.zeros(len(v), bool)
    b = np.maximum(body, 0)
    todo = np.asarray(mask, bool) & (body >= 0) & (rules.kinds[b] != MUSCLE) & (rules.sides != 0)
    moved = _modiolus_anchors(v, rules.bodies, rules.around, rules.sides, todo, rules.max_distance,
                              rules.allowed, body, face, pts, dist, rules.side_of, rules.face_sides)
    outward[moved] = False
    return moved


def deep_vermilion_anchors(v, rules: Rules, hits: tuple, mask, depth: float) -> np.ndarray:
    """The vermilion (``mask`` (n,) bool, :func:`faceforge.skin.rules.vermilion_mask`) that the
    passes before bound deeper than ``depth`` (skin units, > 0) to a muscle not around the mouth
    (ICT's lower lip near the corners: the depressor labii inferioris, 21-24 mm under it) binds to
    the closest point of its own lip's arc of the muscles around the mouth
    (``casting._modiolus_anchors``), as the red of the lips beside it does.

    The lip's red is the orbicularis oris' own skin; anchored under it to a muscle 2 cm deep, it
    stays back while its neighbours on the ring come forward with the pucker, and the lower lip
    folds at the corners (docs/notes/purse21.md). Updates ``hits`` (the arrays of
    :func:`ray_passes`) in place; returns the (n,) bool mask moved."""
    body, face, pts, dist, outward = hits
    if rules.around is None or not depth > 0.0:
        return np.zeros(len(v), bool)
    b = np.maximum(body, 0)
    todo = (np.asarray(mask, bool) & (body >= 0) & (rules.kinds[b] == MUSCLE) & ~rules.around[b]
            & (dist > float(depth)) & (rules.sides != 0))
    moved = _modiolus_anchors(v, rules.bodies, rules.around, rules.sides, todo, rules.max_distance,
                              rules.allowed, body, face, pts, dist, rules.side_of, rules.face_sides)
    outward[moved] = False
    return moved
