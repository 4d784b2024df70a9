"""Ray-cast binding of the skin to the muscles and the skull (§8).

For each skin vertex ``p`` a ray is cast along its normal (the area-weighted
average of the normals of its star of faces), outward first: after the fit,
parts of some muscles may lie outside the skin and the skin binds to them
first. Without a hit, a second ray is cast inward. Along each ray the muscles
are tested from the most superficial to the deepest (the first muscle in that
order that the ray meets wins, wherever along the ray it lies); inward, when no
muscle is met, the skull (cranium and mandible, nearest hit) is tested. Hits
farther than ``max_distance`` are ignored.

On a hit the binding records a surface point (triangle + barycentric
coordinates) on the hit body. The skin layer (:func:`faceforge.skin.layer.add_skin`)
turns each into a particle ``q`` held on that surface point by a position
constraint and a stretch constraint ``k_anchor`` between ``p`` and ``q``;
:meth:`Binding.targets` recomputes the surface points on the deformed bodies
every frame.

Lips: skin of the upper lip may bind only to the cranium (upper structures),
skin of the lower lip only to the mandible (``lip_sides`` from
:func:`faceforge.skin.mouth.lip_side`), so the lips part when the jaw opens.
A lip vertex ignores muscle hits on the other side of the lip line (the lower
lip never binds to the upper half of the orbicularis oris), muscle hits far from
the lips, and the other lip's muscles
(:func:`faceforge.skin.mouth.muscle_lip_side`).

Beyond the paper: some muscles insert into the skin through the muscles above them (the
corrugator and the depressor supercilii pass through the frontalis and the orbicularis
oculi into the deep surface of the brow skin). Bound only to the muscle its ray meets
first, the brow skin followed the frontalis alone, which passes on about half of what a
deep muscle moves it, and its own anchors held the skin back from the deep muscle's pull
(MakeHuman, depressor supercilii at c = 1: muscle 122 ENS, brow 20.7). With ``insertions``
a vertex bound to another muscle whose ray, cast on, meets one of them also gets an anchor
on it: the vertex then has two anchors, each with the skin's ``k_anchor``, and follows both
muscles (:func:`bind_skin`).

Beyond the paper, the modiolus: at each mouth corner the zygomaticus, risorius, depressor
anguli, the lip elevators and the orbicularis oris meet in a knot of fibres tied to the
skin, and the corner moves with the knot whichever of them pulls. In the layered map the
orbicularis oris lies on top of all of them and each moves it, so its corners are the knot.
By its ray the corner skin bound to whichever muscle the ray met first: on MakeHuman the
outer corner (FDP 8.3) to the risorius, the inner one (2.4) to the ring. The risorius at
c = 1 then moved 8.3 twice as far as 2.4 (by 265 against 138 MW), the zygomaticus (which the
risorius does not lie on) 2.4 1.4 times as far as 8.3, and the outer and inner lip FAPs of
a corner, which MPEG-4 files give alike, could not both be met. The skin within
``modiolus_radius`` x MW0 of a corner FDP (:func:`modiolus_mask`) that its ray bound to
another muscle binds to the closest point of the orbicularis oris instead, a lip vertex to
its own arc (``modiolus`` of :func:`bind_skin`). Corner skin on the bone (inner lips on the
teeth) stays there: moved to the ring as well, MediaPipe's inner corners (on the mandible)
came to outrun the outer ones and its calibration lost 7 rows within 10 % (median 6.6 ->
9.4 %; MakeHuman 73 -> 72 rows, ICT 92 -> 96). With the modiolus the calibration medians
went from 13.5 / 6.2 / 6.9 % to 5.9 / 3.0 / 6.6 % (MakeHuman / ICT / MediaPipe).

Beyond the paper: a vertex whose two rays both miss (they look into a hole of
the skull: eye sockets, nostrils, the gap between the teeth) binds to the
closest point of the skull within ``max_distance`` (its own jaw's bone near
the lips); :attr:`Binding.closest` marks those anchors and the report counts
them. :func:`bind_head` allows this only on the face front (in front of the
ears, below the hairline, above the chin), so the neck is not tied to the jaw.

Ray casting uses :class:`faceforge.geometry.rays.RayCaster` (trimesh, Embree
where installed); all bodies of one pass are merged into one mesh so every pass
is a single batched query.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from faceforge.skin.mouth import AROUND_MOUTH
from faceforge.constants import FLOAT, INT
from faceforge.geometry.rays import RayCaster
from faceforge.geometry.triangles import barycentric, check_mesh, vertex_normals

__all__ = ["Body", "Binding", "bind_skin", "MUSCLE", "CRANIUM", "MANDIBLE", "UNBOUND"]

#: kinds of body (and the per-vertex status codes of :attr:`Binding.status`)
UNBOUND, MUSCLE, CRANIUM, MANDIBLE = 0, 1, 2, 3
_KIND_CODES = {"muscle": MUSCLE, "cranium": CRANIUM, "mandible": MANDIBLE}
KIND_NAMES = {UNBOUND: "none", MUSCLE: "muscle", CRANIUM: "cranium", MANDIBLE: "mandible"}


@dataclass(frozen=True)
class Body:
    """A surface the skin can bind to.

    Attributes
    ----------
    name : str
        Muscle name, ``"cranium"`` or ``"mandible"``.
    kind : str
        ``"muscle"``, ``"cranium"`` or ``"mandible"``.
    vertices : (n, 3) float64
        Rest positions (after the fit), skin units.
    faces : (m, 3) int64
    """

    name: str
    kind: str
    vertices: np.ndarray = field(repr=False)
    faces: np.ndarray = field(repr=False)

    def __post_init__(self):
        if self.kind not in _KIND_CODES:
            raise ValueError(f"body kind must be one of {sorted(_KIND_CODES)}, got {self.kind!r}")
        v, f = check_mesh(self.vertices, self.faces)
        object.__setattr__(self, "vertices", v)
        object.__setattr__(self, "faces", f)


@dataclass(frozen=True)
class Binding:
    """The anchors of the skin (one per bound skin vertex).

    Attributes
    ----------
    body_names : tuple of str
        The bodies, in the order given to :func:`bind_skin`.
    status : (n,) int8
        Per skin vertex: ``UNBOUND`` 0, ``MUSCLE`` 1, ``CRANIUM`` 2, ``MANDIBLE`` 3.
    vertex_ids : (k,) int64
        Bound skin vertices, non-decreasing: one anchor each, and a second, right after
        the first, where a muscle inserts into the skin through the one the ray met first
        (``insertions`` of :func:`bind_skin`).
    body : (k,) int64
        Index into ``body_names`` of each anchor's body.
    face_ids : (k,) int64
        Hit triangle, in that body's faces.
    bary : (k, 3) float64
        Barycentric coordinates of the hit on that triangle.
    points : (k, 3) float64
        Rest position of the hit (skin units).
    distance : (k,) float64
        Distance from the skin vertex to the hit.
    outward : (k,) bool
        True when found by the outward ray.
    normals : (n, 3) float64
        The skin normals used for the rays.
    closest : (k,) bool
        True when both rays missed and the anchor is the closest skull point.
    """

    body_names: tuple
    status: np.ndarray
    vertex_ids: np.ndarray
    body: np.ndarray
    face_ids: np.ndarray
    bary: np.ndarray
    points: np.ndarray
    distance: np.ndarray
    outward: np.ndarray
    normals: np.ndarray
    closest: np.ndarray | None = None

    def __post_init__(self):
        if self.closest is None:
            object.__setattr__(self, "closest", np.zeros(len(self.vertex_ids), bool))

    def targets(self, surfaces) -> np.ndarray:
        """Anchor surface points ``(k, 3)`` on the current (deformed) bodies.

        ``surfaces`` gives, for each body in ``body_names`` order, its current
        ``(vertices (n_b, 3), faces (m_b, 3))`` with the faces used at bind time
        (``MusculoskeletalSystem.surface(name)`` does).
        """
        out = np.full((len(self.vertex_ids), 3), np.nan)
        for b, (verts, faces) in enumerate(surfaces):
            sel = self.body == b
            if sel.any():
                tri = np.asarray(verts, FLOAT)[np.asarray(faces, INT)[self.face_ids[sel]]]
                out[sel] = np.einsum("ij,ijk->ik", self.bary[sel], tri)
        return out

    @classmethod
    def from_arrays(cls, arrays: dict, prefix: str = "anchor_") -> "Binding":
        """Inverse of :meth:`as_arrays` (anchor arrays may carry ``prefix``, as in bind.npz)."""
        def get(key):
            return arrays[key] if key in arrays else arrays[prefix + key]

        return cls(
            body_names=tuple(str(n) for n in get("body_names")),
            status=np.asarray(get("status"), np.int8), vertex_ids=np.asarray(get("vertex_ids"), INT),
            body=np.asarray(get("body"), INT), face_ids=np.asarray(get("face_ids"), INT),
            bary=np.asarray(get("bary"), FLOAT), points=np.asarray(get("points"), FLOAT),
            distance=np.asarray(get("distance"), FLOAT), outward=np.asarray(get("outward"), bool),
            normals=np.asarray(get("normals"), FLOAT),
            closest=np.asarray(get("closest"), bool) if ("closest" in arrays or prefix + "closest" in arrays)
            else None)

    def as_arrays(self) -> dict:
        """Flat arrays for an npz stage file (no pickle)."""
        return {
            "status": self.status, "vertex_ids": self.vertex_ids, "body": self.body,
            "face_ids": self.face_ids, "bary": self.bary, "points": self.points,
            "distance": self.distance, "outward": self.outward, "normals": self.normals,
            "closest": self.closest,
            "body_names": np.asarray(self.body_names, dtype=str),
        }


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
                p, d, tri = closest_points(v[todo], bv, bf[sub])
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


def bind_skin(vertices, faces, bodies, max_distance: float, lip_sides=None,
              normals=None, depth_rank=None, side_of=None, fallback=True, body_sides=None,
              insertions=None, face_sides=None, lips_to_ring=False, modiolus=None) -> Binding:
    """Bind every skin vertex to the first muscle or bone its normal ray meets (§8).

    Parameters
    ----------
    vertices : (n, 3) float
        Skin rest positions (the working mesh, after the mouth cut).
    faces : (m, 3) int
    bodies : sequence of Body
        Muscles ordered from the most superficial to the deepest, and the
        skull parts (kind ``"cranium"`` / ``"mandible"``) in any position.
    max_distance : float
        Longest ray, in skin units (``bind.max_ray_distance`` x head diagonal).
    lip_sides : (n,) int, optional
        +1 upper lip (binds to the cranium only), -1 lower lip (mandible only),
        0 elsewhere; see :func:`faceforge.skin.mouth.lip_side`.
    normals : (n, 3) float, optional
        Outward unit normals; default the area-weighted star average.
    depth_rank : (len(bodies),) int, optional
        Superficiality of each body, smaller = more superficial (e.g. minus the
        muscle layer); among equal ranks the nearest hit wins. Default: the
        muscles' order in ``bodies``.
    side_of : callable, optional
        ``points (k, 3) -> (k,) int`` side of the lip line (+1 above, -1 below,
        0 far; :func:`faceforge.skin.mouth.side_of_points`). A lip vertex
        (``lip_sides != 0``) ignores hits on the other side, so the lower lip
        never binds to the upper part of a muscle around the mouth; it also ignores
        muscle hits far from the lips (side 0: a ray up the nose to the brows).
    fallback : bool or (n,) bool
        Vertices (all, or those of the mask) whose two rays miss bind to the
        closest skull point within ``max_distance`` (:attr:`Binding.closest`);
        False keeps the paper's rays only.
    body_sides : (len(bodies),) int, optional
        With ``side_of``: the lip each body acts on (:func:`faceforge.skin.mouth.
        muscle_lip_side`): +1 upper, -1 lower, ``AROUND_MOUTH`` (2), 0 neither (and the
        skull parts). Rays and fallback of an upper-lip vertex skip the lower lip's
        muscles and vice versa (an upper-lip vertex never binds to the end of a depressor
        that crosses the line); a lip vertex whose rays miss takes the closest point of
        the own half of the muscles around the mouth (see :func:`_closest_fallback`).
    insertions : sequence of int, optional
        Indices into ``bodies`` of muscles that insert into the skin through the
        muscles above them (module docstring): a vertex bound by its ray to another
        muscle whose same ray, cast on, also meets one of these gets a second anchor
        on it (the nearest hit; :attr:`Binding.vertex_ids` then lists the vertex twice).
    face_sides : sequence, optional
        Per body, None or ``(f_i,) int8``: the lip side of each face of a ring around the
        mouth by its rows (:func:`faceforge.skin.mouth.ring_face_sides`), used for that
        body in place of the side of the lip line its hits and faces lie on.
    lips_to_ring : bool
        A lip vertex whose rays miss binds to its own half of the muscles around the mouth
        when one is within ``max_distance``, before the bone (:func:`_closest_fallback`).
    modiolus : (n,) bool, optional
        The skin at the mouth corners (with ``side_of`` and ``body_sides``): a vertex of it
        that its rays (or the fallback) bound to a muscle not around the mouth binds instead
        to the closest point of the muscles around the mouth within ``max_distance``, a lip
        vertex to its own arc (:func:`_modiolus_anchors`; module docstring), and gets no
        second anchor. Skin on the bone stays there.

    Returns
    -------
    Binding

    Length (152 lines): the passes over one shared state (per-vertex body, face, point,
    distance, status arrays), outward, inward, insertions, modiolus, closest-point fallback, in
    the order the docstring gives; split, each helper would take most of the 14 parameters and
    those arrays. Left as it is (issue 24).
    """
    v, f = check_mesh(vertices, faces)
    bodies = list(bodies)
    n, nb = len(v), len(bodies)
    nrm = vertex_normals(v, f) if normals is None else np.asarray(normals, FLOAT)
    if nrm.shape != v.shape:
        raise ValueError(f"normals {nrm.shape} must match vertices {v.shape}")
    sides = np.zeros(n, INT) if lip_sides is None else np.asarray(lip_sides, INT).reshape(-1)
    if len(sides) != n:
        raise ValueError(f"lip_sides {sides.shape} must have one entry per vertex ({n})")
    kinds = np.array([_KIND_CODES[b.kind] for b in bodies], INT)
    muscles = [i for i in range(nb) if kinds[i] == MUSCLE]
    skull = [i for i in range(nb) if kinds[i] != MUSCLE]
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

    body = np.full(n, -1, INT)
    face = np.full(n, -1, INT)
    pts = np.full((n, 3), np.nan)
    dist = np.full(n, np.inf)
    outward = np.zeros(n, bool)
    has_dir = np.linalg.norm(nrm, axis=1) > 0
    corner = np.zeros(n, bool) if modiolus is None else np.array(modiolus, bool).reshape(-1)  # a copy
    if len(corner) != n:
        raise ValueError(f"modiolus {corner.shape} must have one entry per vertex ({n})")
    passes = ((muscles, +1.0), (muscles, -1.0), (skull, -1.0))
    for p, (ids, sign) in enumerate(passes):
        todo = np.flatnonzero((body < 0) & has_dir)
        res = _cast(bodies, ids, rank, v[todo], sign * nrm[todo], max_distance, allowed[todo],
                    sides[todo], side_of, strict, face_sides)
        hit = res[0] >= 0
        t = todo[hit]
        body[t], face[t], pts[t], dist[t] = (r[hit] for r in res)
        outward[t] = sign > 0

    mask = np.broadcast_to(np.asarray(fallback, bool), (n,))
    closest = _closest_fallback(v, bodies, kinds, sides, max_distance, body, face, pts, dist, mask, side_of,
                                allowed, around, face_sides, lips_to_ring)
    if around is not None:   # the modiolus: corner skin on another muscle moves to the ring
        corner &= (body >= 0) & (kinds[np.maximum(body, 0)] == MUSCLE) & ~around[np.maximum(body, 0)]
        corner = _modiolus_anchors(v, bodies, around, sides, corner, max_distance, allowed, body, face,
                                   pts, dist, side_of, face_sides)
        outward[corner] = closest[corner] = False
    else:
        corner[:] = False

    ids = np.flatnonzero(body >= 0).astype(INT)
    status = np.zeros(n, np.int8)
    status[ids] = kinds[body[ids]]
    anchors = (ids, body[ids], face[ids], pts[ids], dist[ids], outward[ids], closest[ids])
    ins = [int(i) for i in (insertions or ()) if kinds[i] == MUSCLE]
    if ins:   # second anchors: skin over a muscle that inserts into it through the muscles above
        cand = ids[(kinds[body[ids]] == MUSCLE) & ~np.isin(body[ids], ins) & ~closest[ids] & ~corner[ids]]
        res = _cast(bodies, ins, np.zeros(nb, INT), v[cand],    # nearest hit, along the same ray
                    np.where(outward[cand, None], 1.0, -1.0) * nrm[cand], max_distance, allowed[cand],
                    sides[cand], side_of, strict, face_sides)
        hit = res[0] >= 0
        extra = cand[hit]
        order = np.argsort(np.concatenate([ids, extra]), kind="stable")   # each right after its first
        second = (extra,) + tuple(r[hit] for r in res) + (outward[extra], np.zeros(len(extra), bool))
        anchors = tuple(np.concatenate([a, b])[order] for a, b in zip(anchors, second))
    ids, a_body, a_face, a_pts, a_dist, a_out, a_closest = anchors
    bary = np.zeros((len(ids), 3), FLOAT)
    for b in np.unique(a_body):
        sel = a_body == b
        bary[sel] = barycentric(a_pts[sel], bodies[b].vertices, bodies[b].faces, a_face[sel])
    return Binding(
        body_names=tuple(b.name for b in bodies), status=status, vertex_ids=ids,
        body=a_body, face_ids=a_face, bary=bary, points=a_pts, distance=a_dist,
        outward=a_out, normals=nrm, closest=a_closest,
    )
