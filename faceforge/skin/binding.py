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

from faceforge.constants import FLOAT, INT
from faceforge.geometry.triangles import barycentric, check_mesh, vertex_normals
from faceforge.skin.casting import _KIND_CODES, CRANIUM, MANDIBLE, MUSCLE, UNBOUND

__all__ = ["Body", "Binding", "bind_skin", "MUSCLE", "CRANIUM", "MANDIBLE", "UNBOUND"]

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
class BrowRegion:
    """The brow's insertion (:func:`bind_skin`'s ``regions.brow``).

    mask : (n,) bool, the brow's skin (:func:`faceforge.skin.brow.brow_mask`); muscles : indices
    into ``bodies`` of the brow muscles: a vertex of the mask on the bone after the rays and the
    fallback binds to their closest point (:func:`faceforge.skin.brow.brow_anchors`).
    eyes : pairs ((n,) bool, indices): the eyes' skin (:func:`faceforge.skin.brow.eye_mask`) and
    the muscles it may not bind to; such vertices rebind to the closest bone
    (:func:`faceforge.skin.brow.eye_anchors`).
    shared_reach : skin units (0: off): the brow's vertices get a second anchor on the nearest
    other insertion muscle (:func:`faceforge.skin.brow.shared_anchors`) and the outer brow on
    the frontalis and orbicularis; raisers : indices of the muscles that raise the brow
    (``bind.brow_raisers``), a further anchor within that reach, or None.
    """

    mask: np.ndarray
    muscles: tuple = ()
    eyes: tuple = ()
    shared_reach: float = 0.0
    raisers: tuple | None = None


@dataclass(frozen=True)
class InsertionRegions:
    """The skin regions that bind by a rule of their own rather than by their rays alone
    (:func:`bind_skin`; each mask ``(n,) bool`` over the skin vertices, None: no such rule).

    modiolus : the skin at the mouth corners, onto the muscles around the mouth
    (:func:`faceforge.skin.bind_passes` ``fallbacks``); commissure : the lip skin at the inner
    lip corners, onto either lip's arc (:func:`faceforge.skin.bind_passes.commissure_anchors`);
    vermilion : the red of the lips on the bone, onto its own lip's arc
    (:func:`faceforge.skin.bind_passes.vermilion_anchors`); deep : the red of the lips, where
    bound deeper than ``deep_depth`` (skin units) to a muscle not around the mouth, onto its own
    lip's arc (:func:`faceforge.skin.bind_passes.deep_vermilion_anchors`); brow : :class:`BrowRegion`.
    """

    modiolus: np.ndarray | None = None
    commissure: np.ndarray | None = None
    vermilion: np.ndarray | None = None
    deep: np.ndarray | None = None
    deep_depth: float = 0.0
    brow: BrowRegion | None = None


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

    def on_bone(self) -> np.ndarray:
        """(k,) bool: the anchors on a bone (cranium, mandible), not on a muscle."""
        from faceforge.anatomy.skull import BONES

        return np.isin(np.asarray(self.body_names, dtype=object)[np.asarray(self.body)], BONES)

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

    def sole_bone_anchors(self, mask) -> tuple[np.ndarray, np.ndarray]:
        """The vertices of ``mask`` (n,) bool whose one anchor is on a bone, and where each vertex's
        anchor row is: ``(todo (j,) vertex ids, row (n,) int)`` (``row[v]`` the row of ``v``'s
        anchor when it has exactly one, else another of its rows or -1): what the rebinding passes
        (cheek, ala) move onto a muscle."""
        ids = np.asarray(self.vertex_ids, INT)
        n = len(self.status)
        counts = np.bincount(ids, minlength=n)
        row = np.full(n, -1, INT)
        row[ids] = np.arange(len(ids))        # with one anchor per vertex, that anchor's row
        on_bone = (self.status != MUSCLE) & (self.status != UNBOUND) & (counts == 1)
        return np.flatnonzero(np.asarray(mask, bool) & on_bone), row

    def as_arrays(self) -> dict:
        """Flat arrays for an npz stage file (no pickle)."""
        return {
            "status": self.status, "vertex_ids": self.vertex_ids, "body": self.body,
            "face_ids": self.face_ids, "bary": self.bary, "points": self.points,
            "distance": self.distance, "outward": self.outward, "normals": self.normals,
            "closest": self.closest,
            "body_names": np.asarray(self.body_names, dtype=str),
        }


def bind_skin(vertices, faces, bodies, max_distance: float, lip_sides=None,
              normals=None, depth_rank=None, side_of=None, fallback=True, body_sides=None,
              insertions=None, face_sides=None, lips_to_ring=False,
              regions: InsertionRegions | None = None) -> Binding:
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
    regions : InsertionRegions, optional
        The skin regions with a binding rule of their own (with ``side_of`` and ``body_sides``
        for the lips'): the modiolus, a vertex of which that its rays (or the fallback) bound to a
        muscle not around the mouth binds instead to the closest point of the muscles around the
        mouth within ``max_distance``, a lip vertex to its own arc, and gets no second anchor
        (skin on the bone stays there; :func:`_modiolus_anchors`, module docstring); the
        commissure, bound to the muscles around the mouth, onto their closest point on either
        lip's arc; the vermilion, on the skull after the passes, onto its own arc; the brow
        (:class:`BrowRegion`).

    Returns
    -------
    Binding

    The passes (:mod:`faceforge.skin.bind_passes`), over one shared state (per-vertex body,
    face, point, distance arrays), in the order above: the rays (``ray_passes``), the
    closest-point fallback and the modiolus (``fallbacks``), the second anchors
    (``second_anchors``).
    """
    from faceforge.skin.bind_passes import bind_rules, commissure_anchors, fallbacks, ray_passes, second_anchors

    v, f = check_mesh(vertices, faces)
    bodies = list(bodies)
    n = len(v)
    nrm = vertex_normals(v, f) if normals is None else np.asarray(normals, FLOAT)
    if nrm.shape != v.shape:
        raise ValueError(f"normals {nrm.shape} must match vertices {v.shape}")
    sides = np.zeros(n, INT) if lip_sides is None else np.asarray(lip_sides, INT).reshape(-1)
    if len(sides) != n:
        raise ValueError(f"lip_sides {sides.shape} must have one entry per vertex ({n})")
    rules = bind_rules(bodies, sides, max_distance, depth_rank, side_of, body_sides, face_sides)
    regions = InsertionRegions() if regions is None else regions
    corner, comm, verm, deep = (None if m is None else _vertex_mask(m, n, name) for m, name in
                                ((regions.modiolus, "modiolus"), (regions.commissure, "commissure"),
                                 (regions.vermilion, "vermilion"), (regions.deep, "deep")))
    corner = np.zeros(n, bool) if corner is None else corner
    hits = ray_passes(v, nrm, rules)
    closest = fallbacks(v, rules, hits, np.broadcast_to(np.asarray(fallback, bool), (n,)),
                         lips_to_ring, corner)
    if comm is not None:   # the inner lip corners: both lips on the whole ring
        closest[commissure_anchors(v, rules, hits, comm)] = False
    if verm is not None:   # the red of the lips: off the teeth, onto its own lip's arc
        from faceforge.skin.bind_passes import vermilion_anchors

        closest[vermilion_anchors(v, rules, hits, verm)] = False
    if deep is not None and regions.deep_depth > 0:   # the red of the lips on a deep muscle: onto its arc
        from faceforge.skin.bind_passes import deep_vermilion_anchors

        closest[deep_vermilion_anchors(v, rules, hits, deep, regions.deep_depth)] = False
    body, face, pts, dist, outward = hits
    brow = regions.brow
    if brow is not None:   # the brow's insertion: brow skin on the bone moves to the brow muscles
        from faceforge.skin.brow import brow_anchors, eye_anchors

        brow_mask = np.asarray(brow.mask, bool)
        moved = brow_anchors(v, bodies, rules.kinds, list(brow.muscles), brow_mask, max_distance,
                             body, face, pts, dist, rules.allowed)
        outward[moved] = closest[moved] = False
        for eye, eye_ids in brow.eyes:   # the eye's skin stays off these muscles
            moved = eye_anchors(v, bodies, rules.kinds, list(eye_ids), np.asarray(eye, bool), max_distance,
                                body, face, pts, dist, rules.allowed)
            outward[moved], closest[moved] = False, True
    ids = np.flatnonzero(body >= 0).astype(INT)
    status = np.zeros(n, np.int8)
    status[ids] = rules.kinds[body[ids]]
    anchors = (ids, body[ids], face[ids], pts[ids], dist[ids], outward[ids], closest[ids])
    anchors = second_anchors(v, nrm, rules, anchors, insertions, outward, corner)
    if brow is not None and brow.shared_reach > 0:   # the brow's dermis takes two insertions
        from faceforge.skin.brow import outer_shared_anchors, raiser_anchors, shared_anchors

        anchors = shared_anchors(v, bodies, anchors, brow_mask, list(brow.muscles),
                                 list(insertions or ()), brow.shared_reach)
        # the outer brow: frontalis and orbicularis
        anchors = outer_shared_anchors(v, bodies, anchors, brow_mask, brow.shared_reach)
        if brow.raisers is not None:   # and the frontalis, which raises it (bind.brow_raisers)
            anchors = raiser_anchors(v, bodies, anchors, brow_mask, list(brow.raisers), brow.shared_reach)
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


def _vertex_mask(mask, n: int, name: str) -> np.ndarray:
    """``mask`` as a fresh ``(n,) bool`` array; ValueError naming it when its length is not ``n``."""
    out = np.array(mask, bool).reshape(-1)
    if len(out) != n:
        raise ValueError(f"{name} {out.shape} must have one entry per vertex ({n})")
    return out
