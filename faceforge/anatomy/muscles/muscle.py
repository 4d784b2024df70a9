"""Volumetric muscles from action lines (§5.1.2, §5.2.1 linear, §5.2.2 sphincter).

A :class:`Muscle` is pure data: its rest mesh (a morphed :mod:`.hexmesh`), the
constraint network of Fig. 5 with the stiffness of §5.2.1 / §5.2.2, and the
action lines (surface points on the layer it lies on) that produce the
per-frame position targets of its bound bottom particles. Adding it to a
``pbd.ModelBuilder`` is :meth:`Muscle.add_to_builder`; nothing here steps time.

Stiffness keys (``muscle.linear.stiffness.*`` / ``muscle.sphincter.stiffness.*``
of ``configs/default.yaml``; a missing key means 0 and "0 is not created"):

=================  ==============================================================
latitudinal_up/low  across the fibres, ``(i, j)-(i, j+1)``, top / bottom sheet
longitudinal_up/low along the fibres, ``(i, j)-(i+1, j)``, top / bottom sheet
shear_up/low        both diagonals of every grid cell, top / bottom sheet
connection          bottom ``(i, j)`` to top ``(i, j)``
bend                dihedral angle of every pair of faces sharing an edge
volume              one volume constraint over the closed muscle surface
position            bottom contour particles to their contour samples, and (linear)
                    the interior bottom particles to their fibre targets (below)
=================  ==============================================================

Regular sampling is recomputed on the current layer every frame, as Eq. 3
says, except for the sphincter's loops (see :func:`build_sphincter_muscle`,
``material_sampling``).

The contraction rules: :mod:`.linear` (§5.2.1, Eq. 4) and :mod:`.sphincter` (§5.2.2).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from faceforge.anatomy.muscles.action_line import eval_polyline, sample_positions
from faceforge.anatomy.muscles.hexmesh import HexTopology, hex_topology, morph_hex
from faceforge.anatomy.muscles.linear import (LINEAR_MAX_CONTRACTION, _row_blend, interior_grid, interior_targets,
                                              row_bases)
from faceforge.anatomy.muscles.sphincter import (SPHINCTER_MAX_CONTRACTION, _sphincter_grid, bulge_share,
                                                 lower_raise, sphincter_displacement, vertical_share)
from faceforge.constants import FLOAT, INT
from faceforge.geometry.triangles import check_mesh, vertex_normals

__all__ = [
    "STIFFNESS_KEYS",
    "Muscle",
    "build_linear_muscle",
    "build_sphincter_muscle",
    "distance_network",
    "bending_quads",
]

STIFFNESS_KEYS = (
    "latitudinal_up", "latitudinal_low", "longitudinal_up", "longitudinal_low",
    "shear_up", "shear_low", "connection", "bend", "volume", "position",
)


def _check_stiffness(stiffness: dict) -> dict:
    unknown = sorted(set(stiffness) - set(STIFFNESS_KEYS))
    if unknown:
        raise ValueError(f"unknown muscle stiffness key(s) {unknown}; valid: {', '.join(STIFFNESS_KEYS)}")
    out = {k: float(stiffness.get(k, 0.0)) for k in STIFFNESS_KEYS}
    bad = [k for k, v in out.items() if not 0.0 <= v <= 1.0]
    if bad:
        raise ValueError(f"muscle stiffness {bad} outside [0, 1]")
    return out


def distance_network(topo: HexTopology) -> dict[str, np.ndarray]:
    """The distance constraints of Fig. 5, ``{kind: pairs (m, 2) int64}`` (muscle-local ids)."""
    h, w = topo.h, topo.w
    rows = h if topo.closed else h - 1
    ii, jj = np.meshgrid(np.arange(h), np.arange(w), indexing="ij")
    out = {}
    for sheet, idx in (("up", topo.top), ("low", topo.bottom)):
        i, j = ii[:, :-1].ravel(), jj[:, :-1].ravel()
        out[f"latitudinal_{sheet}"] = np.stack([idx(i, j), idx(i, j + 1)], 1)
        i, j = ii[:rows].ravel(), jj[:rows].ravel()
        out[f"longitudinal_{sheet}"] = np.stack([idx(i, j), idx((i + 1) % h, j)], 1)
        i, j = ii[:rows, :-1].ravel(), jj[:rows, :-1].ravel()
        i1 = (i + 1) % h
        out[f"shear_{sheet}"] = np.concatenate(
            [np.stack([idx(i, j), idx(i1, j + 1)], 1), np.stack([idx(i1, j), idx(i, j + 1)], 1)]
        )
    out["connection"] = np.stack([topo.bottom(ii.ravel(), jj.ravel()), topo.top(ii.ravel(), jj.ravel())], 1)
    return {k: v.astype(INT) for k, v in out.items()}


def bending_quads(faces) -> np.ndarray:
    """One ``(p0, p1, p2, p3)`` per interior edge of a manifold triangle mesh.

    ``(p0, p1)`` is the shared edge, ``p2`` / ``p3`` the vertices opposite to it
    in the two faces. Returns ``(e, 4) int64``; raises ``ValueError`` if an edge
    has more than two faces.
    """
    f = np.asarray(faces, dtype=INT)
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    opp = np.concatenate([f[:, 2], f[:, 0], f[:, 1]])
    key = np.sort(e, axis=1)
    order = np.lexsort((key[:, 1], key[:, 0]))
    key, e, opp = key[order], e[order], opp[order]
    same = np.all(key[1:] == key[:-1], axis=1)
    if np.any(same[1:] & same[:-1]):
        raise ValueError("bending_quads: an edge is shared by more than two faces")
    k = np.flatnonzero(same)
    return np.stack([e[k, 0], e[k, 1], opp[k], opp[k + 1]], 1).astype(INT)


@dataclass
class Muscle:
    """One muscle: rest mesh, constraint network and the action lines that drive it.

    Attributes
    ----------
    name, kind : str
        ``kind`` is "linear" or "sphincter".
    topology : HexTopology
    rest_positions : (2 h w, 3) float64
        The morphed, thickened template (particles in muscle-local order).
    faces : (m, 3) int64
        Closed, outward-oriented surface (muscle-local ids).
    lines : dict[str, ActionLine]
        Linear: "A0", "A1", "A2", "A3" (fibre a, insertion, fibre b, origin);
        sphincter: "A1" (inner loop), "A3" (outer loop). Surface points refer to
        the concatenated mesh of the bodies in ``lies_on``, in that order.
    lies_on : tuple[str, ...]
        Names of the bodies (skull parts or deeper muscles) the lines lie on.
    stiffness : dict[str, float]
        Keys :data:`STIFFNESS_KEYS`; kinds with 0 are not created.
    layer : int
    active : bool
        Passive support tissue ignores its contraction.
    thickness : float
        Mesh units (distance from the bottom to the top sheet at rest).
    max_contraction : float
        ``kappa``: what c = 1 means (module docstring); set by the builders.
    rest_parameters : dict
        Sphincter material sampling: ``{"A1"|"A3": (segment (h,), t (h,))}``;
        empty for arc-length sampling every frame.
    carry_inner : (h,) float64 or None
        Sphincter: per inner sample, the fraction of the outer loop's drag (its sample's
        displacement from rest minus the inner one's) added to the inner target before the
        contraction; None: none (the paper). The lips' mucosa slides over the teeth: an
        inner sample that lies on bone (the skull) would otherwise stay while the lip
        muscles drag the outer margin (see :func:`build_sphincter_muscle`, ``carry_inner``).
    protrusion : float
        Sphincter: how far a full protrusion drive moves the loops out of their plane, forward
        (away from what they lie on), as a fraction of the ellipse's semi-minor axis times
        ``max_contraction``; 0: never (the paper). See :func:`build_sphincter_muscle`.
    closure_centre : float
        Sphincter: where its closure pulls the inner loop, from the paper's centre (0, the
        ellipse's centre: the mean of both loops) to the inner loop's own mean (1, the mouth
        opening). See :func:`build_sphincter_muscle`.
    closure_vertical, eversion_up, bulge : float, bool, float
        Sphincter: the closure's share along the plane's up direction at a full protrusion
        drive (1, the paper), the eversion along it, the lips' forward bulge per unit of their closure's
        length (0, the paper) (:func:`.sphincter.vertical_share`, :func:`.sphincter.sphincter_displacement`).
    interior : (h-2, w-2, 3) float64 or None
        Linear: the rest offset of each interior bottom particle (rows ``i = 1..h-2``,
        columns ``j = 1..w-2``) from the blend of its row's side samples, in the row's
        basis (:func:`row_bases`); these particles are bound to their fibre targets
        (module docstring). None: only the contour is bound.
    constraints : dict
        Derived: ``{kind: indices}`` of the created constraints (muscle-local).
    """

    name: str
    kind: str
    topology: HexTopology
    rest_positions: np.ndarray
    faces: np.ndarray
    lines: dict
    lies_on: tuple
    stiffness: dict
    layer: int = 0
    active: bool = True
    thickness: float = 0.0
    max_contraction: float = SPHINCTER_MAX_CONTRACTION
    rest_parameters: dict = field(default_factory=dict)
    interior: object = None
    carry_inner: object = None
    protrusion: float = 0.0
    closure_centre: float = 0.0
    closure_vertical: float = 1.0
    eversion_up: bool = False
    bulge: float = 0.0
    constraints: dict = field(default_factory=dict)

    def __post_init__(self):
        self.stiffness = _check_stiffness(self.stiffness)
        net = distance_network(self.topology)
        self.constraints = {k: v for k, v in net.items() if self.stiffness[k] > 0}
        if self.stiffness["bend"] > 0:
            self.constraints["bend"] = bending_quads(self.faces)

    @property
    def n_particles(self) -> int:
        return len(self.rest_positions)

    @property
    def bound(self) -> np.ndarray:
        """Bottom particles driven by position constraints, ``(k,)`` (muscle-local): the
        contour (:attr:`HexTopology.contour`), then the :attr:`interior` ones if bound."""
        if self.interior is None:
            return self.topology.contour
        g = interior_grid(self.topology.h, self.topology.w)
        return np.concatenate([self.topology.contour, self.topology.bottom(g[:, 0], g[:, 1])]).astype(INT)

    def constraint_count(self) -> int:
        """Number of constraints :meth:`add_to_builder` creates."""
        n = sum(len(v) for v in self.constraints.values())
        n += int(self.stiffness["volume"] > 0)
        n += len(self.bound) if self.stiffness["position"] > 0 else 0
        return n

    def fibre_lengths(self, positions) -> np.ndarray:
        """Length of each bottom fibre polyline ``j = 0..w-1`` along ``i`` (w,) (linear muscles)."""
        topo = self.topology
        p = np.asarray(positions, FLOAT)[: topo.h * topo.w].reshape(topo.h, topo.w, 3)
        return np.linalg.norm(np.diff(p, axis=0), axis=2).sum(axis=0)

    def inverted_faces(self, positions, vertices, faces, vnormals=None) -> np.ndarray:
        """Boolean mask over the bottom and top sheet faces that are turned over.

        Each sheet face is compared with the underlying layer's normal below
        it: the normals of the samples on the two fibre-side columns ``j = 0``
        and ``j = w - 1`` (A0/A2, or the sphincter's inner/outer loop) on the
        current layer ``(vertices, faces)`` (the concatenation of
        :attr:`lies_on`, or the world mesh for a muscle taken from a
        ``MusculoskeletalSystem``), blended linearly in ``j`` and summed over
        the face's three grid nodes. A bottom face must face into the layer
        (outward normal . reference < 0), a top face away from it (> 0);
        zero-area faces count as inverted. Sliding of the top sheet over the
        bottom (shear, which §5.2.1 leaves free) is not an inversion.
        ``vnormals`` may pass the layer's vertex normals already computed.

        Returns ``(2 s,) bool`` for the ``s`` faces of each sheet (bottom first).
        """
        p = np.asarray(positions, FLOAT)
        v, f = check_mesh(vertices, faces)
        h, w = self.topology.h, self.topology.w
        grid = _grid_normals(self, v, f, vertex_normals(v, f) if vnormals is None else vnormals)
        t = np.linspace(0.0, 1.0, w)[None, :, None]
        ref = ((1.0 - t) * grid[:, :1] + t * grid[:, -1:]).reshape(h * w, 3)
        S = self._sheet_count
        sheets = self.faces[: 2 * S]
        node = sheets % (h * w)
        a, b, c = p[sheets[:, 0]], p[sheets[:, 1]], p[sheets[:, 2]]
        side = np.einsum("ij,ij->i", np.cross(b - a, c - a), ref[node].sum(axis=1))
        sign = np.where(np.arange(2 * S) < S, -1.0, 1.0)
        return sign * side <= 0.0

    @property
    def top_faces(self) -> np.ndarray:
        """The top sheet's faces ``(s, 3)``: the surface shallower layers lie on."""
        return self.faces[self._sheet_count: 2 * self._sheet_count]

    @property
    def top_face_ids(self) -> np.ndarray:
        """Indices of :attr:`top_faces` within :attr:`faces`, ``(s,) int64``."""
        return np.arange(self._sheet_count, 2 * self._sheet_count, dtype=INT)

    @property
    def _sheet_count(self) -> int:
        rows = self.topology.h if self.topology.closed else self.topology.h - 1
        return 2 * rows * (self.topology.w - 1)

    def sample_targets(self, c: float, vertices, faces) -> np.ndarray:
        """Position targets of :attr:`bound`, ``(k, 3)``, for contraction ``c`` in [0, 1].

        ``(vertices, faces)`` is the current concatenated mesh of :attr:`lies_on`.
        Passive muscles (``active=False``) always use c = 0.
        """
        v, f = check_mesh(vertices, faces)
        return self.targets_from_line_points(c, {k: line.positions(v, f) for k, line in self.lines.items()})

    def targets_from_line_points(self, c: float, points: dict, protrude: float = 0.0,
                                 lower: float = 0.0) -> np.ndarray:
        """:meth:`sample_targets` from the current positions of the lines' surface points.

        ``points``: ``{line key: (p, 3)}`` as :meth:`ActionLine.positions` gives
        them (a caller that evaluates many lines at once gathers them itself). ``protrude``
        in [0, 1]: a sphincter's protrusion drive (its control :func:`protrusion_control`;
        :attr:`protrusion`), clipped like ``c``; ``lower`` in [0, 1]: its lower part's drive
        (:func:`faceforge.anatomy.muscles.sphincter.lower_control`, :func:`lower_raise`).
        """
        c = float(np.clip(c, 0.0, 1.0)) if self.active else 0.0
        lift = self._lift(protrude)
        low = lower_raise(lower, self.active, self.max_contraction) if self.kind != "linear" else 0.0
        vert, bul = vertical_share(self.closure_vertical, protrude, self.active), bulge_share(self.bulge, protrude, self.active)
        g = self.bound_grid
        if self.kind != "linear" and self.rest_parameters:   # compiled (the numpy twin below)
            grid = np.empty((self.topology.h, self.topology.w, 3))
            (s1, t1), (s3, t3) = self._loop_parameters
            r1, r3, carry = self._loop_rest
            _sphincter_grid(np.ascontiguousarray(points["A1"], dtype=FLOAT), s1, t1,
                            np.ascontiguousarray(points["A3"], dtype=FLOAT), s3, t3,
                            c * self.max_contraction, grid, r1, r3, carry, lift, self.forward, low,
                            self.closure_centre, vert, self.eversion_up, bul)
        else:
            grid = self._grid_targets(c, points, lift, low, vert, bul)
        return grid[g[:, 0], g[:, 1]]

    @property
    def _loop_parameters(self):
        """Sphincter, material sampling: ``((segment, t) of A1, (segment, t) of A3)`` as
        int64 / float64 arrays (:attr:`rest_parameters`, for the compiled targets)."""
        lp = self.__dict__.get("_lp")
        if lp is None:
            lp = self.__dict__["_lp"] = tuple(
                (np.ascontiguousarray(self.rest_parameters[k][0], dtype=INT),
                 np.ascontiguousarray(self.rest_parameters[k][1], dtype=FLOAT)) for k in ("A1", "A3"))
        return lp

    @property
    def _loop_rest(self):
        """Sphincter: the rest samples of A1 and A3, ``(h, 3)`` each (their bottom particles, which
        :func:`morph_hex` puts exactly on them), and :attr:`carry_inner` as ``(h,)`` float64,
        or ``(0,)`` when there is none (for the compiled targets)."""
        lr = self.__dict__.get("_lr")
        if lr is None:
            h, w = self.topology.h, self.topology.w
            i = np.arange(h)
            r1, r3 = (np.ascontiguousarray(self.rest_positions[self.topology.bottom(i, j)]) for j in (0, w - 1))
            carry = np.zeros(0) if self.carry_inner is None else np.ascontiguousarray(self.carry_inner, FLOAT)
            if carry.shape not in ((0,), (h,)):
                raise ValueError(f"{self.name}: carry_inner must have {h} rows, got {carry.shape}")
            lr = self.__dict__["_lr"] = (r1, r3, carry if np.any(carry) else np.zeros(0))
        return lr

    def _lift(self, protrude: float) -> float:
        """The forward drive of :func:`sphincter_displacement`: ``protrude`` clipped to [0, 1]
        (0 when passive) times :attr:`protrusion` and :attr:`max_contraction`."""
        if not (self.active and self.protrusion):
            return 0.0
        return float(np.clip(protrude, 0.0, 1.0)) * self.protrusion * self.max_contraction

    @property
    def forward(self) -> np.ndarray:
        """``(3,)`` unit vector from the mean of the bottom sheet to the mean of the top one at
        rest: the side of the sheet away from what it lies on (a sphincter's protrusion)."""
        fw = self.__dict__.get("_fw")
        if fw is None:
            hw = self.topology.h * self.topology.w
            d = self.rest_positions[hw:].mean(axis=0) - self.rest_positions[:hw].mean(axis=0)
            fw = self.__dict__["_fw"] = d / max(float(np.linalg.norm(d)), 1e-300)
        return fw

    @property
    def bound_grid(self) -> np.ndarray:
        """``(k, 2)`` grid cells ``(i, j)`` of :attr:`bound`, in order (the targets' rows)."""
        g = self.__dict__.get("_cg")
        if g is None:
            g = self.topology.contour_grid()
            if self.interior is not None:
                g = np.concatenate([g, interior_grid(self.topology.h, self.topology.w)])
            g = self.__dict__["_cg"] = g
        return g

    def _grid_targets(self, c, P, lift: float = 0.0, low: float = 0.0, vert: float = 1.0, bulge: float = 0.0) -> np.ndarray:
        h, w = self.topology.h, self.topology.w
        grid = np.empty((h, w, 3))
        if self.kind == "linear":
            scale = 1.0 - c * self.max_contraction
            a0 = sample_positions(P["A0"], h, False, scale)
            a2 = sample_positions(P["A2"], h, False, scale)
            a3 = sample_positions(P["A3"], w, False, 1.0)
            a1 = sample_positions(P["A1"], w, False, 1.0)
            t = np.linspace(0.0, 1.0, w)[:, None]
            if c > 0:  # the insertion travels with the ends of the two fibres
                a1 = a1 + (1.0 - t) * (a0[-1] - P["A0"][-1]) + t * (a2[-1] - P["A2"][-1])
            grid[0, :] = a3
            grid[-1, :] = a1
            grid[:, 0] = a0
            grid[:, -1] = a2
            if self.interior is not None:  # each interior fibre shortens with the side fibres
                grid[1:-1, 1:-1] = interior_targets(a0, a2, self.interior)
        else:
            if self.rest_parameters:  # material sampling, see build_sphincter_muscle
                s1 = eval_polyline(P["A1"], None, *self.rest_parameters["A1"], closed=True)[0]
                s3 = eval_polyline(P["A3"], None, *self.rest_parameters["A3"], closed=True)[0]
            else:
                s1 = sample_positions(P["A1"], h, True, 1.0)
                s3 = sample_positions(P["A3"], h, True, 1.0)
            r1, r3, carry = self._loop_rest
            if len(carry):
                s1 = s1 + carry[:, None] * ((s3 - r3) - (s1 - r1))
            if c > 0 or lift > 0 or low > 0:
                d = sphincter_displacement(s1, s3, c * self.max_contraction, lift, self.forward, low,
                                           self.closure_centre, vert, self.eversion_up, bulge)
                s1, s3 = s1 + d, s3 + d
            grid[:, 0] = s1
            grid[:, -1] = s3
        return grid

    def add_to_builder(self, builder, positions=None) -> tuple[int, np.ndarray]:
        """Add particles and constraints to a ``pbd.ModelBuilder``.

        Order: distance kinds (in :data:`STIFFNESS_KEYS` order), bending, volume,
        position. Rest values come from :attr:`rest_positions` (or ``positions``).
        Returns ``(first_particle, position_slots (k,))``; slots are empty when
        ``position`` stiffness is 0.
        """
        firsts, slots = add_muscles_to_builder(builder, [self], None if positions is None else [positions])
        return firsts[0], slots[0]


def add_muscles_to_builder(builder, muscles, positions=None) -> tuple[list[int], list[np.ndarray]]:
    """Add muscles that share no particle (one layer) to a ``pbd.ModelBuilder`` kind by kind.

    Each muscle's own constraints come in the order distance kinds (:data:`STIFFNESS_KEYS`
    order), bending, volume, position, and as no constraint reaches from one muscle into
    another, projecting them kind by kind over all the muscles is the same Gauss-Seidel
    sweep per muscle as adding the muscles one after another; the builder then makes four
    blocks in all instead of four per muscle, so the coloured solver's batches fill up.
    ``positions``: per muscle, rest values instead of its :attr:`Muscle.rest_positions`.
    Returns ``(firsts, slots)`` per muscle: first particle, position slots (empty when
    ``position`` stiffness is 0).
    """
    rest = [m.rest_positions for m in muscles] if positions is None else positions
    firsts = [builder.add_particles(p, 1.0) for p in rest]
    for kind in STIFFNESS_KEYS:
        if kind == "bend":
            continue
        for m, first in zip(muscles, firsts):
            if kind in m.constraints:
                builder.add_distance(m.constraints[kind] + first, m.stiffness[kind])
    for m, first in zip(muscles, firsts):
        if "bend" in m.constraints:
            builder.add_bending(m.constraints["bend"] + first, m.stiffness["bend"])
    for m, first in zip(muscles, firsts):
        if m.stiffness["volume"] > 0:
            builder.add_volume(m.faces + first, m.stiffness["volume"])
    slots = []
    for m, first in zip(muscles, firsts):
        slots.append(builder.add_position(m.bound + first, m.stiffness["position"])
                     if m.stiffness["position"] > 0 else np.zeros(0, INT))
    return firsts, slots


def _build(name, kind, topo, lines, vertices, faces, thickness, stiffness, **kw) -> Muscle:
    v, f = check_mesh(vertices, faces)
    material = kw.pop("material_sampling", False)
    carry = kw.pop("carry_inner", None)
    shape = {k: kw.pop(k) for k in ("protrusion", "closure_centre", "closure_vertical", "eversion_up", "bulge") if k in kw}
    proto = Muscle(name, kind, topo, np.zeros((topo.n_particles, 3)), topo.faces, lines,
                   tuple(kw.pop("lies_on", ())), stiffness, **kw)   # carry_inner 0: the true rest samples
    kw["material_sampling"] = material
    vn = vertex_normals(v, f)
    samples = proto.sample_targets(0.0, v, f)
    g = topo.contour_grid()
    normals = _grid_normals(proto, v, f, vn)[g[:, 0], g[:, 1]]
    pos, mfaces = morph_hex(topo, samples, normals, thickness, surface=(v, f))
    params = {}
    if kw.get("material_sampling", False):
        params = {key: lines[key].parameters(v, f, topo.h) for key in ("A1", "A3")}
    if carry is not None:   # (beta, mask over f): beta times the inner samples' share of the mask
        beta, mask = carry
        carry = None
        if beta > 0:
            seg, t = params["A1"] if params else lines["A1"].parameters(v, f, topo.h)
            on = np.asarray(mask, bool)[lines["A1"].points.face_ids].astype(FLOAT)
            carry = float(beta) * ((1.0 - t) * on[seg] + t * on[(seg + 1) % len(on)])
    interior = None
    if kind == "linear" and topo.h > 2 and topo.w > 2:  # see the module docstring
        h, w = topo.h, topo.w
        bottom = pos[: h * w].reshape(h, w, 3)
        a0, a2 = bottom[:, 0], bottom[:, -1]            # the rest samples of A0, A2, exactly
        basis = row_bases(a0, a2)                        # (h-2, 3, 3), rows e_u, e_v, n
        rel = bottom[1:-1, 1:-1] - _row_blend(a0, a2, w)
        interior = np.linalg.solve(np.swapaxes(basis, 1, 2)[:, None], rel[..., None])[..., 0]
        pos[: h * w].reshape(h, w, 3)[1:-1, 1:-1] = interior_targets(a0, a2, interior)  # round-off
    return Muscle(name, kind, topo, pos, mfaces, lines, proto.lies_on, proto.stiffness,
                  proto.layer, proto.active, float(thickness), proto.max_contraction, params,
                  interior, carry, **shape)


def _grid_normals(m: Muscle, v, f, vn) -> np.ndarray:
    h, w = m.topology.h, m.topology.w
    grid = np.zeros((h, w, 3))
    L = m.lines
    if m.kind == "linear":
        grid[0, :] = L["A3"].sample(v, f, w, 1.0, vn)[1]
        grid[-1, :] = L["A1"].sample(v, f, w, 1.0, vn)[1]
        grid[:, 0] = L["A0"].sample(v, f, h, 1.0, vn)[1]
        grid[:, -1] = L["A2"].sample(v, f, h, 1.0, vn)[1]
    else:
        grid[:, 0] = L["A1"].sample(v, f, h, 1.0, vn)[1]
        grid[:, -1] = L["A3"].sample(v, f, h, 1.0, vn)[1]
    return grid


def build_linear_muscle(name, origin, insertion, fibre_a, fibre_b, vertices, faces, h, w,
                        thickness, stiffness, *, lies_on=(), layer=0, active=True,
                        max_contraction=LINEAR_MAX_CONTRACTION) -> Muscle:
    """A sheet muscle (§5.2.1) from its four action lines on the layer ``(vertices, faces)``.

    Parameters
    ----------
    origin, insertion : ActionLine
        A3 and A1, both running from the fibre_a side to the fibre_b side.
    fibre_a, fibre_b : ActionLine
        A0 (origin[0] -> insertion[0]) and A2 (origin[-1] -> insertion[-1]).
    vertices, faces : the rest mesh the lines lie on (concatenation of ``lies_on``).
    h, w : int
        Samples along / across the fibres.
    thickness : float
        In mesh units.
    stiffness : dict
        ``muscle.linear.stiffness`` of the config.
    max_contraction : float in (0, 1]
        Fibre shortening at c = 1 (Eq. 4 becomes ``step' = step (1 - c kappa)``);
        see the module docstring for why the default is 0.5, not 1.
    """
    if not 0.0 < max_contraction <= 1.0:
        raise ValueError(f"muscle {name}: max_contraction must lie in (0, 1], got {max_contraction}")
    topo = hex_topology(int(h), int(w), closed=False)
    lines = {"A0": fibre_a, "A1": insertion, "A2": fibre_b, "A3": origin}
    return _build(name, "linear", topo, lines, vertices, faces, thickness, stiffness,
                  lies_on=lies_on, layer=layer, active=active, max_contraction=max_contraction)


def build_sphincter_muscle(name, inner, outer, vertices, faces, h, w, thickness, stiffness, *,
                           lies_on=(), layer=0, active=True,
                           max_contraction=SPHINCTER_MAX_CONTRACTION, material_sampling=True,
                           carry_inner=0.0, carry_faces=None, protrusion=0.0,
                           closure_centre=0.0, closure_vertical=1.0, eversion_up=False, bulge=0.0) -> Muscle:
    """A sphincter (§5.2.2) from its closed inner (A1) and outer (A3) loops.

    ``material_sampling`` (default True, a deliberate departure from a literal
    Eq. 3): the loops are sampled at regular arc length once, at rest, and the
    samples then keep their place *between the loop's surface points* (segment
    index and fraction), so they ride on the anatomy. Re-sampling both loops by
    their current arc length every frame (False, the literal reading) makes the
    inner and outer samples slide apart when the jaw stretches the lower half of
    the loops more than the upper half; the cells between them shear until they
    fold (observed from a 5 degree jaw opening on the synthetic head). The
    ellipse displacement of §5.2.2 is applied on top of either.

    ``carry_inner`` (default 0, the paper; ``muscle.sphincter.carry_inner``, a departure): the
    lips' inner margin (A1, their contact line) lies partly on the teeth, which do not move
    with the lip muscles, while the outer margin (A3) lies on those muscles; the mucosa
    slides over the teeth, so an inner sample on them is given ``carry_inner`` times the
    outer sample's drag relative to it (:attr:`Muscle.carry_inner`). ``carry_faces (m,)
    bool`` over ``faces`` marks where an inner sample slides (default: everywhere; the builder
    passes the skull's faces), and each inner sample gets ``carry_inner`` times its share of
    its two bracketing surface points on those faces. An inner sample on a muscle already
    moves with it (on the MakeHuman head the levator labii superioris moves the inner loop
    above it 1.8 times as far as the outer one), and carrying there would hold it back.

    ``protrusion`` (default 0, the paper; ``muscle.sphincter.protrusion``, a departure): the
    paper contracts the loops in their plane, so no lip moves forward, while a real mouth
    pushes its lips out (the MakeHuman pursing unit: FDP 8.1 forward 359 MNS for 118 up;
    the protrusion unit: 257 forward). Anatomy gives the orbicularis oris two parts: the pars
    marginalis closes and presses the lips (the paper's in-plane contraction) and the pars
    peripheralis protrudes them. The second has its own drive ``p`` in [0, 1] (the control
    :func:`protrusion_control`), which moves every sample pair ``p kappa protrusion b``
    along the ellipse plane's normal, away from what the loops lie on
    (:attr:`Muscle.forward`), with the contraction's fall-off; ``b`` is the ellipse's
    semi-minor axis. One drive for both, scaled, pushed the lower lip down as it went
    forward and cost the lower-lip raises it assists (calibrated MakeHuman, ICT).

    ``closure_centre`` (default 0, the paper; ``muscle.sphincter.closure_centre``, a departure):
    the paper closes the inner loop toward the ellipse's centre, the mean of both loops; on a face
    whose outer loop reaches down to the chin that centre lies below the mouth, so the closure
    (the pursing half of a pucker) pulls the upper lip down and back (MakeHuman 4.9 mm down, ICT
    7.1) where a real pucker moves it up and forward. The fibres of the pars marginalis run
    round the mouth opening; their purse-string pulls toward it: the closure's centre is moved
    ``closure_centre`` of the way from the ellipse's centre to the inner loop's own mean.
    ``closure_vertical`` in [0, 1] (default 1, the paper; ``muscle.sphincter.closure_vertical``),
    ``eversion_up`` (``muscle.sphincter.eversion_up``) and ``bulge`` >= 0 (default 0, the paper;
    ``muscle.sphincter.bulge``): see :func:`~faceforge.anatomy.muscles.sphincter.sphincter_displacement`.

    The loops must run in the same rotational sense and start at corresponding
    points (the coincident latitudinal lines A0 = A2 join their first points);
    :func:`faceforge.anatomy.muscles.sphincter.align_loops` arranges that for raw points.
    """
    if not (inner.closed and outer.closed):
        raise ValueError(f"sphincter {name}: inner and outer action lines must be closed loops")
    topo = hex_topology(int(h), int(w), closed=True)
    lines = {"A1": inner, "A3": outer}
    if not 0.0 < max_contraction < 1.0:
        raise ValueError(f"sphincter {name}: max_contraction must lie in (0, 1), got {max_contraction}")
    if not 0.0 <= carry_inner <= 1.0:
        raise ValueError(f"sphincter {name}: carry_inner must lie in [0, 1], got {carry_inner}")
    for key, value in (("protrusion", protrusion), ("bulge", bulge)):
        if not (np.isfinite(value) and value >= 0.0):
            raise ValueError(f"sphincter {name}: {key} must be a finite number >= 0, got {value}")
    if not 0.0 <= closure_centre <= 1.0:
        raise ValueError(f"sphincter {name}: closure_centre must lie in [0, 1], got {closure_centre}")
    if not 0.0 <= closure_vertical <= 1.0:
        raise ValueError(f"sphincter {name}: closure_vertical must lie in [0, 1], got {closure_vertical}")
    return _build(name, "sphincter", topo, lines, vertices, faces, thickness, stiffness,
                  lies_on=lies_on, layer=layer, active=active, max_contraction=max_contraction,
                  material_sampling=material_sampling, protrusion=float(protrusion),
                  closure_centre=float(closure_centre), closure_vertical=float(closure_vertical),
                  eversion_up=bool(eversion_up), bulge=float(bulge),
                  carry_inner=(float(carry_inner), np.ones(len(faces), bool) if carry_faces is None else carry_faces))
