"""The skin as a network of PBD constraints (§8).

The skin is the user's triangulated mesh. Pure functions on ``faces`` give the
constraint index arrays of §8:

* a stretch (distance) constraint on every edge,
* for each pair of triangles sharing an interior edge, a stretch constraint
  between the two opposite vertices (penalises bending and twisting),
* a dihedral bending constraint on the same pair,
* an area constraint per triangle,
* one volume constraint over all triangles (the PBD engine closes an open
  surface virtually).

:func:`add_skin` feeds them, plus the anchors found by
:mod:`faceforge.skin.binding`, into a :class:`faceforge.pbd.ModelBuilder`.
Each anchor is a particle ``q`` held by a position constraint whose target is
a surface point on a muscle or a bone (recomputed every frame from the
deformed layer, :meth:`SkinLayer.anchor_targets`) and a stretch constraint
``k_anchor`` between the skin vertex and ``q``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from faceforge.anatomy.muscles.targets import bary_points
from faceforge.constants import FLOAT, INT, NUMBA_OPTIONS
from faceforge.skin.carry_smooth import carry_smoothed

__all__ = [
    "SkinTopology",
    "SkinStiffness",
    "SkinLayer",
    "skin_topology",
    "add_skin",
]


@dataclass(frozen=True)
class SkinTopology:
    """Constraint index arrays of a skin mesh (all ``int64``).

    Attributes
    ----------
    edges : (e, 2)
        Every undirected edge once, ``edges[:, 0] < edges[:, 1]``, sorted.
    cross_pairs : (p, 2)
        For every interior manifold edge, the two vertices opposite to it
        (one per adjacent triangle).
    bending_quads : (p, 4)
        ``(e0, e1, o0, o1)``: the shared edge then the opposite vertices, in
        the order the PBD engine's ``add_bending`` expects; row ``i`` is the
        same pair as ``cross_pairs[i]``.
    triangles : (m, 3)
        The faces, for area and volume constraints.
    boundary_edges : (b, 2)
        Edges used by one triangle only (open borders).
    nonmanifold_edges : (k, 2)
        Edges used by more than two triangles; they get an edge stretch
        constraint but no cross-stretch or bending (the pair is ambiguous).
    """

    edges: np.ndarray
    cross_pairs: np.ndarray
    bending_quads: np.ndarray
    triangles: np.ndarray
    boundary_edges: np.ndarray
    nonmanifold_edges: np.ndarray


def skin_topology(faces) -> SkinTopology:
    """Build the §8 constraint topology of a triangle mesh.

    Parameters
    ----------
    faces : (m, 3) int
        Triangles; vertex ids index any vertex array.

    Returns
    -------
    SkinTopology
        Deterministic (sorted by edge) index arrays. For a manifold mesh
        ``3 m = 2 * len(cross_pairs) + len(boundary_edges)``.
    """
    f = np.asarray(faces, dtype=INT)
    if f.ndim != 2 or f.shape[1] != 3:
        raise ValueError(f"faces must have shape (m, 3), got {f.shape}")
    m = len(f)
    # half-edge k of face t goes f[t, k] -> f[t, k+1]; its opposite vertex is f[t, k+2]
    a = f.reshape(-1)
    b = np.roll(f, -1, axis=1).reshape(-1)
    opp = np.roll(f, -2, axis=1).reshape(-1)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    order = np.lexsort((np.repeat(np.arange(m), 3), hi, lo))
    lo, hi, opp = lo[order], hi[order], opp[order]
    if len(lo) == 0:
        empty2 = np.zeros((0, 2), INT)
        return SkinTopology(empty2, empty2, np.zeros((0, 4), INT), f, empty2, empty2)
    new = np.r_[True, (lo[1:] != lo[:-1]) | (hi[1:] != hi[:-1])]
    start = np.flatnonzero(new)
    count = np.diff(np.r_[start, len(lo)])
    edges = np.stack([lo[start], hi[start]], axis=1)
    two = start[count == 2]
    cross = np.stack([opp[two], opp[two + 1]], axis=1)
    quads = np.concatenate([edges[count == 2], cross], axis=1)
    return SkinTopology(
        edges=edges,
        cross_pairs=cross,
        bending_quads=quads,
        triangles=f,
        boundary_edges=edges[count == 1],
        nonmanifold_edges=edges[count > 2],
    )


@dataclass(frozen=True)
class SkinStiffness:
    """PBD stiffness ``k`` in [0, 1] of each skin constraint kind (§8)."""

    stretching: float = 0.15
    bending: float = 0.95
    area: float = 0.95
    anchor: float = 0.2
    volume: float = 1.0
    #: position constraint holding each anchor particle q on its surface point
    #: (the paper binds q "through a position constraint" without a value)
    position: float = 1.0

    @classmethod
    def from_config(cls, config) -> "SkinStiffness":
        """Read ``skin.stiffness.*`` from a validated config (``config.get(dotted)``)."""
        kw = {}
        for key in ("stretching", "bending", "area", "anchor", "volume", "position"):
            value = config.get(f"skin.stiffness.{key}")
            if value is not None:  # position is optional (older configs)
                kw[key] = float(value)
        return cls(**kw)


@dataclass(frozen=True)
class SkinLayer:
    """Where the skin lives in the PBD model (indices, all ``int64``).

    Attributes
    ----------
    first : int
        Particle index of skin vertex 0; skin vertex ``i`` is particle ``first + i``.
    n_vertices : int
        Number of skin particles (the working mesh, after the mouth cut).
    anchor_vertices : (k,)
        Skin vertex of each anchor.
    anchor_particles : (k,)
        Particle index of each anchor particle ``q``.
    anchor_slots : (k,)
        Row of each anchor's surface point in :meth:`anchor_targets` of a ``Control``.
    kinematic_anchors : bool
        The anchor particles are kinematic (``Control.kinematic_positions``; see
        :func:`add_skin`), else held by position constraints (``Control.position_targets``).
    """

    first: int
    n_vertices: int
    anchor_vertices: np.ndarray
    anchor_particles: np.ndarray
    anchor_slots: np.ndarray
    kinematic_anchors: bool = False

    def anchor_targets(self, control) -> np.ndarray:
        """The ``Control`` array whose rows :attr:`anchor_slots` hold the anchors' surface points."""
        return control.kinematic_positions if self.kinematic_anchors else control.position_targets

    def skin_positions(self, state_positions) -> np.ndarray:
        """The skin's rows ``(n_vertices, 3)`` of a PBD positions array."""
        return np.asarray(state_positions)[self.first : self.first + self.n_vertices]


def _anchor_stiffness(anchor: float, tether, k: int):
    """(per-anchor stiffness (k,), tethered (k,) bool) from ``stiffness.anchor`` and ``tether``
    (see :func:`add_skin`)."""
    t = np.zeros(k, FLOAT) if tether is None else np.asarray(tether, FLOAT).reshape(-1)
    if t.shape != (k,) or np.any((t < 0) | (t > 1)):
        raise ValueError(f"tether must be ({k},) stiffnesses in [0, 1], got shape {t.shape}")
    tied = t > 0
    return np.where(tied, t, float(anchor)), tied


def add_skin(builder, vertices, faces, stiffness: SkinStiffness, anchor_vertices=None,
             anchor_points=None, inv_mass: float = 1.0, tether=None) -> SkinLayer:
    """Add the skin particles, §8 constraints and anchors to a PBD builder.

    Constraints are added in the order: anchors (q position, then p-q stretch),
    edge stretch, cross stretch, bending, area, volume; the builder projects them
    in that order after the deeper layers added before. With ``stiffness.position`` 1 (the
    default) each q is exactly on its surface point when the p-q stretch reads it, so q is
    kinematic instead (``Control.kinematic_positions``) and the stretch weighs it as a
    particle of ``inv_mass``: the same projections, without the position constraints and
    the q's prediction (:attr:`SkinLayer.kinematic_anchors`).

    Parameters
    ----------
    builder : faceforge.pbd.ModelBuilder
    vertices : (n, 3) float
        Rest positions of the skin (the working mesh).
    faces : (m, 3) int
    stiffness : SkinStiffness
    anchor_vertices : (k,) int, optional
        Skin vertices bound to a muscle or bone.
    anchor_points : (k, 3) float, optional
        Rest position of each anchor's surface point (the ray hit).
    inv_mass : float
        Inverse mass of every skin and anchor particle.
    tether : (k,) float, optional
        Per anchor, 0: the p-q stretch of ``stiffness.anchor`` (§8); > 0: a *tether* of that
        stiffness whose whole correction goes to the skin vertex (its ``q`` does not yield;
        ``skin.cheek_tether``, :func:`faceforge.skin.cheek.cheek_tether`).

    Returns
    -------
    SkinLayer
    """
    v = np.asarray(vertices, dtype=FLOAT)
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"vertices must have shape (n, 3), got {v.shape}")
    topo = skin_topology(faces)
    if topo.triangles.size and topo.triangles.max() >= len(v):
        raise ValueError(f"faces index vertices outside [0, {len(v)})")
    av = np.zeros(0, INT) if anchor_vertices is None else np.asarray(anchor_vertices, INT).reshape(-1)
    ap = np.zeros((0, 3)) if anchor_points is None else np.asarray(anchor_points, FLOAT).reshape(-1, 3)
    if len(av) != len(ap):
        raise ValueError(f"anchor_vertices {av.shape} and anchor_points {ap.shape} differ in length")

    first = builder.add_particles(v, np.full(len(v), inv_mass, FLOAT))
    held = stiffness.position == 1.0
    k_anchor, tied = _anchor_stiffness(stiffness.anchor, tether, len(av))
    if len(av) and held:
        # every iteration q is exactly on its surface point (its position projection) when
        # the p-q stretch reads it: a kinematic q, with the stretch a tether weighing it as the
        # particle it was, gives the same projection without the position constraints
        # (pbd.ModelBuilder.add_distance; tests/pbd/test_tether.py)
        q_first = builder.add_particles(ap, np.zeros(len(ap)))
        q = q_first + np.arange(len(ap), dtype=INT)
        slots = builder.kinematic_rows(q)
        builder.add_distance(np.stack([first + av, q], axis=1), k_anchor,
                             weight=np.stack([np.full(len(av), inv_mass), np.where(tied, 0.0, inv_mass)], 1))
    elif len(av):
        q_first = builder.add_particles(ap, np.full(len(ap), inv_mass, FLOAT))
        q = q_first + np.arange(len(ap), dtype=INT)
        slots = np.asarray(builder.add_position(q, stiffness.position), INT)
        builder.add_distance(np.stack([first + av, q], axis=1), k_anchor,
                             weight=None if not tied.any() else np.stack(
                                 [np.full(len(av), inv_mass), np.where(tied, 0.0, inv_mass)], 1))
    else:
        q = np.zeros(0, INT)
        slots = np.zeros(0, INT)
    if len(topo.edges):
        builder.add_distance(first + topo.edges, stiffness.stretching)
    if len(topo.cross_pairs):
        builder.add_distance(first + topo.cross_pairs, stiffness.stretching)
        builder.add_bending(first + topo.bending_quads, stiffness.bending)
    if len(topo.triangles):
        builder.add_area(first + topo.triangles, stiffness.area)
        builder.add_volume(first + topo.triangles, stiffness.volume)
    return SkinLayer(first=int(first), n_vertices=len(v), anchor_vertices=av,
                     anchor_particles=q, anchor_slots=slots, kinematic_anchors=bool(len(av)) and held)


def _particle_mirror(layer: SkinLayer, partner, binding) -> np.ndarray | None:
    """The skin model's particle mirror map from the skin vertices' ``partner (n,)`` (None:
    none): each anchor particle maps to the anchor of its vertex's partner on the mirrored
    body (``X_L`` <-> ``X_R``; a midline vertex holds one anchor on each twin), itself when
    there is none."""
    if partner is None:
        return None
    from faceforge.anatomy.muscles.muscle_map import mirrored_name

    partner = np.asarray(partner, dtype=INT)
    n = layer.first + layer.n_vertices
    count = len(layer.anchor_particles)
    out = np.arange(max(n, int(layer.anchor_particles.max()) + 1 if count else n), dtype=INT)
    out[layer.first:n] = layer.first + partner
    if count:
        names = [str(binding.body_names[b]) for b in binding.body]
        key = {(int(v), nm): a for a, (v, nm) in enumerate(zip(layer.anchor_vertices, names))}
        for a, (v, nm) in enumerate(zip(layer.anchor_vertices, names)):
            t = key.get((int(partner[v]), mirrored_name(nm)))
            if t is not None:
                out[layer.anchor_particles[a]] = layer.anchor_particles[t]
    return out


#: radians a quad may stay past its fold limit (:meth:`SkinSimulation.limit_folds`): quads projected
#: one after another nudge their neighbours a hair past again, and the guards' alternation, which
#: repeats the pass until it has nothing to do, needs a tolerance to end (0.06 deg, nothing next to
#: the 10 deg between ``skin.fold_deg`` and what the fold check counts)
FOLD_TOL = 1e-3

#: the lips' contact moves only the vertex that crossed (0), not the other lip's face too (1, PBD's
#: share): each face pushed by the several vertices over it crumpled ICT's lower lip's middle in
#: anger and p_b_m (docs/notes/lipcontact16.md); with the face held the lip line is smooth
CONTACT_SHEET = 0.0

#: the lips' contact looks at each step's history (:class:`faceforge.pbd.triangle_contact.TriangleContact`'s
#: ``previous``, ``lost`` = this fraction of the contact's reach): a lip vertex already that far behind
#: the other lip at the step's start is left (it did not cross in this step), and a lip that jumped
#: more than that onto a vertex in one step does not drag it (the vertex moves by its own share).
#: Without it ICT's lower lip springing back from raise_b_lip_lm -870 MNS in one frame passed 2-6 mm
#: through the upper lip's vertices, which the contact then dragged up, those within reach and not
#: their neighbours: 30 folded edges in the frame (0.1: the presses' remainders got lost, MakeHuman's
#: p_b_m kept 20 crossed vertices; docs/notes/lips17.md)
CONTACT_LOST = 0.3


class SkinSimulation:
    """The skin as the shallowest layer of a :class:`~faceforge.anatomy.layers.MusculoskeletalSystem`.

    Holds the skin's own PBD model (skin particles + anchor particles ``q``).
    ``system.add_layer(sim)`` makes ``system.step`` call :meth:`step` after the
    muscles: the anchors' position targets are recomputed from the surface
    points on the *current* skull and muscles (``system.surface(name)``), then
    the skin is stepped.

    Parameters
    ----------
    vertices : (n, 3) float
        Working skin rest positions (after the mouth cut).
    faces : (m, 3) int
    binding : faceforge.skin.binding.Binding
        Its ``body_names`` must be bodies of the system the layer is added to.
    stiffness : SkinStiffness
    settings : faceforge.pbd.SolverSettings, optional
    weights : (n,) float, optional
        Influence map; :meth:`positions` returns ``rest + w (simulated - rest)``.
    carried : (k,) bool, optional
        Anchors that *carry* their skin vertex (default: none, the paper's anchors). §8 ties
        a skin vertex ``p`` to its anchor particle ``q`` (held on the surface point) by a
        stretch of the rest length ``|p - q|``; that link passes on only the part of the
        anchor's motion along ``p - q`` (to first order), so a muscle sliding under the skin
        (the mouth corner pulled down) barely drags it. A carried anchor's ``q`` starts at
        ``p`` (rest length 0) and is held at ``p``'s rest position moved as the surface point
        moved (:meth:`carry_targets`): the skin goes where the tissue under it goes, as where
        mimetic muscles insert into the skin. Bone anchors are best left uncarried (skin
        slides over bone).
    carry_radius : float, optional
        Skin units: each carried vertex moves by the mean motion of the carried anchors within
        this radius of it (:mod:`faceforge.skin.carry_smooth`, ``skin.carry_radius_mm``); 0 off.
    mirror : (n,) int, optional
        Each skin vertex's mirror partner on a symmetric rig: the solver then colours mirror
        twins alike (:func:`faceforge.pbd.colouring.mirror_colouring`).
    tether : (k,) float, optional
        Per anchor, a tether's stiffness (0: none): see :func:`add_skin`.
    fold_limit : ((m, 4) int, float or (m,) float), optional
        Skin quads (skin vertex ids) and the dihedral limit in radians (one for all or one per
        quad) they may not bend past (those bent more at rest: their rest angle), enforced after
        each solver step (:meth:`limit_folds`, :func:`faceforge.pbd.dihedral_limit.limit_dihedrals`;
        ``skin.fold_deg``, ``skin.commissure_fold_deg``: :func:`faceforge.skin.fold_limit.fold_limits`).
    lip_contact : (points (m,), (start (m + 1,), cand (k,)), tris (t, 3), floor (m,), reach, margin), optional
        Skin vertices that may touch the skin triangles ``tris`` (skin vertex ids; each point's
        candidates ``cand[start[i]:start[i + 1]]``; pushed out from at most ``reach`` skin units
        behind; ``margin`` the barycentric slack of "over a face"), not cross them (``skin.lip_contact_mm``:
        :func:`faceforge.skin.lip_contact.lip_contacts`), enforced after each solver step, before the
        fold limit (:meth:`touch_lips`, :class:`faceforge.pbd.triangle_contact.TriangleContact`).
    sink : (rows (h,) int, share float[, up (3,) float[, medial (h, 3) float]]), optional
        Carried anchor rows whose target follows its skin vertex by ``share`` of its sinking
        below its rest place along ``up`` (default +Y) and of its motion toward ``medial`` (per
        row; default none), read at each step's start: a hold the skin may sink and draw toward
        the nose from, not rise (``skin.lid_hold_sink``, :mod:`faceforge.skin.sink`).
    """

    def __init__(self, vertices, faces, binding, stiffness: SkinStiffness, settings=None, weights=None,
                 carried=None, mirror=None, join=False, tether=None, carry_radius=0.0, fold_limit=None,
                 lip_contact=None, sink=None):
        from faceforge.pbd import ModelBuilder, Solver, SolverSettings

        self.rest = np.array(vertices, dtype=FLOAT)
        self.faces = np.asarray(faces, dtype=INT)
        self.binding = binding
        k = len(binding.vertex_ids)
        self.carried = np.zeros(k, bool) if carried is None else np.asarray(carried, bool).reshape(-1)
        if self.carried.shape != (k,):
            raise ValueError(f"carried must have one flag per anchor ({k}), got {self.carried.shape}")
        self._any_carried = bool(self.carried.any())
        from faceforge.skin.joined import join_args   # skin.join_insertions

        self._joined = join_args(vertices, binding.vertex_ids, self.carried) if join else None
        self._smooth = None
        if carry_radius > 0 and self._any_carried:   # skin.carry_smooth: the tissue spreads the motion
            from faceforge.skin.carry_smooth import smoothing_rows

            p0 = self.rest[binding.vertex_ids[self.carried]]
            self._smooth = smoothing_rows(p0, carry_radius, binding.body[self.carried]) + (np.empty((len(p0), 3), FLOAT),)
        q_rest = binding.points.copy()
        q_rest[self.carried] = self.rest[binding.vertex_ids[self.carried]]
        builder = ModelBuilder()
        self.layer = add_skin(builder, self.rest, self.faces, stiffness, binding.vertex_ids, q_rest, tether=tether)
        self.model = builder.finalize()
        self._sink = None
        if sink is not None and len(sink[0]) and float(sink[1]) > 0:   # skin.lid_hold_sink
            from faceforge.skin.sink import sink_args

            rows, vid, p0, up, medial = sink_args(self.rest, binding.vertex_ids, sink[0], *sink[2:])
            if not self.carried[rows].all():
                raise ValueError("sink rows must be carried anchors")
            self._sink = (rows, (self.layer.first + vid).astype(INT), p0, up, medial, float(sink[1]))
        self._fold = None
        if fold_limit is not None and len(fold_limit[0]):
            from faceforge.pbd.dihedral_limit import DihedralLimit, rest_limits

            quads = np.asarray(fold_limit[0], INT).reshape(-1, 4)   # never below a quad's rest angle
            self._fold = DihedralLimit(self.layer.first + quads, rest_limits(self.rest, quads, fold_limit[1]),
                                       self.model.particle_count, tol=FOLD_TOL, incremental=True)
        self._contact = None
        if lip_contact is not None and len(lip_contact[0]):
            from faceforge.pbd.triangle_contact import TriangleContact

            pts, cands, tris, floor, reach, margin = lip_contact
            self._contact = TriangleContact(self.layer.first + np.asarray(pts, INT), cands,
                                            self.layer.first + np.asarray(tris, INT),
                                            self.model.particle_count, floor=floor, reach=reach, margin=margin,
                                            sheet=CONTACT_SHEET)
        self.solver = Solver(self.model, settings or SolverSettings(), _particle_mirror(self.layer, mirror, binding))
        self.state = self.model.state()
        #: the positions at the step's start, for the lips' contact (:meth:`touch_lips`)
        self._contact_prev = self.state.positions.copy()
        self._fold_mark = np.zeros(len(self.state.positions), dtype=bool)   # limit_folds' scratch
        #: the skin vertices the last :meth:`limit_folds` moved
        self.folded = np.zeros(0, dtype=np.int64)
        self.control = self.model.control()
        self._bary = np.ascontiguousarray(binding.bary, dtype=FLOAT)
        slots = self.layer.anchor_slots
        targets = self.layer.anchor_targets(self.control)
        self._direct = bool(np.array_equal(slots, np.arange(len(slots)))
                            and targets.shape == (len(slots), 3) and targets.flags.c_contiguous)
        self.weights = None if weights is None else np.asarray(weights, FLOAT).reshape(-1)
        if self.weights is not None and len(self.weights) != len(self.rest):
            raise ValueError(f"weights {self.weights.shape} must have one entry per skin vertex")

    def anchor_targets(self, system, out: np.ndarray | None = None) -> np.ndarray:
        """Surface points of every anchor on the system's current bodies, ``(k, 3)``: the
        same points as ``binding.targets([system.surface(n) for n in body_names])``, in one
        compiled gather from the system's world mesh (its vertex ids are found once per
        system). ``out`` (k, 3) float64, filled and returned when given."""
        return bary_points(self._bary, self._gather_ids(system), system.world_view(), out)

    def _gather_ids(self, system) -> np.ndarray:
        """:meth:`_world_vertex_ids`, found once per system."""
        if getattr(self, "_gather_for", None) is not system:
            self._gather = self._world_vertex_ids(system)
            self._gather_for = system
        return self._gather

    def _world_vertex_ids(self, system) -> np.ndarray:
        """``(k, 3)`` world vertex ids of each anchor's triangle (the system's world faces)."""
        b = self.binding
        _, world_faces = system.world()
        starts = np.array([system.face_range(name).start for name in b.body_names], dtype=INT)
        return np.ascontiguousarray(world_faces[starts[b.body] + b.face_ids], dtype=INT)

    def carry_targets(self, system, targets) -> np.ndarray:
        """Targets of the carried anchors' ``q``, ``(c, 3)``, from the surface points ``targets
        (k, 3)`` on the current bodies: the skin vertex's rest position moved as its surface
        point moved, ``p0 + (s - s0)``; exactly ``p0`` at rest (the rest state stays a fixed
        point). The offset is not turned with the anchor triangle: a muscle's triangles tilt
        and shear as it contracts, and turning the ~1-2 mm offset with them threw the skin
        about (the MakeHuman chin moved 1.5 mm down and back while the mentalis under it rose
        3 mm); a rigid turn of the tissue (the jaw) leaves an error of the turn angle times
        the offset (0.2 rad x 1.5 mm = 0.3 mm), and skin on the mandible itself slides as in §8."""
        s0, p0 = self._carry_rest(system)
        return p0 + (targets[self.carried] - s0)

    def _carry_rest(self, system):
        """``(s0, p0)`` of :meth:`carry_targets`, ``(c, 3)`` each, computed once per system."""
        if getattr(self, "_carry_for", None) is not system:
            v0, _ = system.world(rest=True)
            ids = self._gather_ids(system)[self.carried]
            self._carry = (bary_points(np.ascontiguousarray(self._bary[self.carried]), ids, v0),
                           np.ascontiguousarray(self.rest[self.binding.vertex_ids[self.carried]]))
            self._carry_for = system
            self._carried_rows = np.flatnonzero(self.carried).astype(INT)
        return self._carry

    def step(self, system, dt: float) -> None:
        """One frame: anchor targets from ``system``, then a PBD step of the skin."""
        if len(self.layer.anchor_slots):
            # when the anchors hold every row of their Control array, in order, it is filled in place
            targets = self.layer.anchor_targets(self.control)
            t = self.anchor_targets(system, targets if self._direct else None)
            if self._any_carried:   # t[carried] = carry_targets(system, t), compiled, in place
                s0, p0 = self._carry_rest(system)
                if self._smooth is None:
                    _carry(t, self._carried_rows, s0, p0)
                else:
                    carry_smoothed(t, self._carried_rows, s0, p0, *self._smooth)
                if self._sink is not None:   # held skin may sink (skin.lid_hold_sink)
                    from faceforge.skin.sink import sink

                    rows, vid, q0, up, medial, share = self._sink
                    sink(t, rows, vid, q0, up, medial, self.state.positions, share)
                if self._joined is not None:   # a vertex on several muscles follows the one that pulls
                    from faceforge.skin.joined import join

                    join(t, *self._joined)
            if not self._direct:
                targets[self.layer.anchor_slots] = t
        if self._contact is not None:
            self._contact_prev[:] = self.state.positions
        self.solver.step(self.state, self.state, self.control, dt)
        self.touch_lips()
        self.limit_folds()

    def touch_lips(self) -> int:
        """Push lip vertices that passed through the other lip back to it (``lip_contact``), in place
        on the skin's state, once after each solver step, with the step's history (the positions at
        its start, :data:`CONTACT_LOST`); returns the projections made (0: none, or no contact). Not
        repeated in the guards' alternation: there the skull guard pushes lip skin out of the teeth
        and the contact back in, round after round, and on ICT's sadness the lips' corners were
        thrown 10-160 mm (202 folded edges; once a step: none)."""
        if self._contact is None:
            return 0
        return self._contact(self.state.positions, previous=self._contact_prev,
                             lost=CONTACT_LOST * self._contact.reach)

    def limit_folds(self) -> int:
        """Keep the fold limit's quads within their limits, in place on the skin's state (after each
        step, and again by the guards after they move the skin). Returns the projections made (0:
        none needed, or no limit); :attr:`folded` then holds the skin vertices it moved ((p,) int)."""
        if self._fold is None:
            return 0
        mark = self._fold_mark
        mark[:] = False
        done = self._fold(self.state.positions, touched=mark)
        self.folded = np.flatnonzero(self.layer.skin_positions(mark))
        return done

    def simulated(self) -> np.ndarray:
        """Current simulated skin positions ``(n, 3)`` (a copy, no influence weighting)."""
        return self.layer.skin_positions(self.state.positions).copy()

    def positions(self) -> np.ndarray:
        """Animated skin ``(n, 3)``: the simulation weighted by the influence map."""
        sim = self.simulated()
        if self.weights is None:
            return sim
        return self.rest + self.weights[:, None] * (sim - self.rest)

    def reset(self) -> None:
        """Back to the rest state."""
        fresh = self.model.state()
        self.state.positions[:] = fresh.positions
        self.state.velocities[:] = fresh.velocities


@numba.njit(**NUMBA_OPTIONS)
def _carry(t, rows, s0, p0):  # pragma: no cover - numba
    """``t[rows] = p0 + (t[rows] - s0)`` in place (:meth:`SkinSimulation.carry_targets`, whose
    numpy is the plain twin): ``t (k, 3)``, ``rows (c,)`` ascending, ``s0, p0 (c, 3)``."""
    for i in range(rows.shape[0]):
        r = rows[i]
        for d in range(3):
            t[r, d] = p0[i, d] + (t[r, d] - s0[i, d])
