"""The layered musculoskeletal system of §6: kinematic skull, muscles in layers.

Design: one ``pbd.Model`` + ``Solver`` **per muscle layer**, solved in order
from the deepest layer up. Before layer ``n`` is stepped, the position
targets of its muscles are sampled from the action lines on the *already
solved* positions of the skull and of layers ``< n`` of the same frame. This
(rather than one Model with constraints ordered deep to shallow) is chosen
because

* coupling between layers goes only through position targets, which are
  read-only inputs of a layer's solve, so a shallower layer can never move a
  deeper one (Fig. 7, "each layer influences the layers on top of it, but not
  those underlying it") — by construction, not by constraint order;
* in a single Model the targets of layer ``n`` would have to be computed
  before the step from the *previous* frame's deeper positions, so a jaw
  motion would reach layer ``n`` only ``n`` frames late; here it arrives in
  the same frame;
* muscles of one layer never share constraints, so one Model per layer keeps
  every solve as small as it can be.

The skull is not simulated at all: the cranium stays at rest and the mandible
is the rest mandible transformed by the frame's rigid 4x4 jaw matrix (§6.1).

All bodies live in one "world" mesh (cranium, mandible, then the muscles in
layer order): :meth:`MusculoskeletalSystem.world` returns its current vertices
and faces, and every muscle's action-line surface points are re-expressed on
the world faces once, at construction, so each frame only gathers positions.

Extension point for the skin (next issue: bind)
-----------------------------------------------
The skin is the shallowest layer. It binds its anchor particles ``q`` to
surface points of the skull and muscles at rest, then follows them:

1. at bind time: ``v, f = system.world(rest=True)`` (or
   ``system.composite(names, rest=True)`` for chosen bodies) and
   ``faceforge.geometry.surface_points.project_to_surface`` or a ray cast on it
   gives ``SurfacePoints`` on world faces; ``system.body_of_faces(face_ids)``
   says which body each lies on;
2. write a class with ``step(system, dt)`` that reads
   ``system.world()`` (the current, solved deeper layers), evaluates its
   surface points (``SurfacePoints.positions(*system.world())``), sets them as
   the anchors' kinematic positions / position targets of its own
   ``pbd.Model`` and steps its solver;
3. ``system.add_layer(skin_layer)``: :meth:`MusculoskeletalSystem.step` calls
   every added layer's ``step`` after the muscles, in the order added. Such a
   layer must not write into the system (it only reads ``world()``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace

import numpy as np

from faceforge.anatomy.muscles.action_line import ActionLine
from faceforge.anatomy.muscles.targets import LinearTargets, bary_points
from faceforge.anatomy.muscles.muscle import Muscle, add_muscles_to_builder
from faceforge.anatomy.muscles.sphincter import lower_control, protrusion_control
from faceforge.constants import FLOAT, INT
from faceforge.exceptions import TemplateError
from faceforge.geometry.surface_points import SurfacePoints
from faceforge.geometry.triangles import check_mesh

__all__ = ["MusculoskeletalSystem", "SKULL", "expand_lies_on", "underlying_mesh"]

#: bodies that are not simulated; "skull" in ``lies_on`` means both
SKULL = ("cranium", "mandible")


def _is_rigid(t: list) -> bool:
    """Whether a (4, 4) matrix given as nested lists is a rigid transform: ``np.allclose(R^T R,
    I, atol=1e-6)``, ``det R > 0`` and ``np.allclose(T[3], (0, 0, 0, 1))``, in Python floats
    (numpy's per-call overhead on 3 x 3 arrays is several times this; it runs every frame)."""
    r = [row[:3] for row in t[:3]]
    for i in range(3):
        for j in range(3):
            dot = r[0][i] * r[0][j] + r[1][i] * r[1][j] + r[2][i] * r[2][j]
            if not abs(dot - (i == j)) <= 1e-6 + 1e-5 * (i == j):
                return False
    det = (r[0][0] * (r[1][1] * r[2][2] - r[1][2] * r[2][1])
           - r[0][1] * (r[1][0] * r[2][2] - r[1][2] * r[2][0])
           + r[0][2] * (r[1][0] * r[2][1] - r[1][1] * r[2][0]))
    last = t[3]
    return det > 0 and all(abs(a) <= 1e-8 for a in last[:3]) and abs(last[3] - 1.0) <= 1e-8 + 1e-5


def expand_lies_on(names) -> tuple[str, ...]:
    """``lies_on`` with "skull" replaced by ``("cranium", "mandible")``, duplicates removed."""
    out: list[str] = []
    for n in names:
        for m in (SKULL if n == "skull" else (n,)):
            if m not in out:
                out.append(m)
    return tuple(out)


@dataclass
class _Layer:
    index: int
    muscles: list          # Muscle, with action lines on world faces
    firsts: list           # first particle of each muscle in the layer model
    slots: list            # position slots of each muscle
    model: object
    solver: object
    state: object
    control: object
    vids: np.ndarray = None    # (k, 3) world vertex ids of every action-line surface point
    bary: np.ndarray = None    # (k, 3)
    pieces: list = None        # per muscle: {line key: slice into the k points}
    linear: object = None      # LinearTargets of the layer's linear muscles (compiled)
    linear_direct: bool = False  # its slots are every position slot of the layer, in order
    pts: np.ndarray = None     # (k, 3) scratch: the gathered surface points
    copies: list = None        # (world slice, layer state slice) pairs written back each step
    columns: np.ndarray = None  # (muscles,) each muscle's column in the system's contraction array
    protrusion_columns: np.ndarray = None  # (muscles,) its protrusion drive's column, or -1
    lower_columns: np.ndarray = None  # (muscles,) its lower part's drive column, or -1

    def gather(self):
        """Precompute one gather for all surface points of all lines of the layer."""
        vids, bary, pieces, start = [], [], [], 0
        for m in self.muscles:
            own = {}
            for key, line in m.lines.items():
                n = len(line.points)
                own[key] = slice(start, start + n)
                vids.append(line.points.face_ids)
                bary.append(line.points.bary)
                start += n
            pieces.append(own)
        self.vids = np.concatenate(vids) if vids else np.zeros(0, INT)
        self.bary = np.concatenate(bary) if bary else np.zeros((0, 3))
        self.pieces = pieces
        lin = [i for i, m in enumerate(self.muscles) if m.kind == "linear" and len(self.slots[i])]
        self.linear = LinearTargets([self.muscles[i] for i in lin], [pieces[i] for i in lin],
                                    [self.slots[i] for i in lin]) if lin else None
        targets = self.control.position_targets
        self.linear_direct = bool(self.linear is not None and targets.flags.c_contiguous
                                  and np.array_equal(self.linear.slots, np.arange(len(targets))))
        self.pts = np.empty((len(self.vids), 3))

    def plan_copies(self, vslice: dict) -> None:
        """The write-back of the solved muscles into the world vertices as few slice copies
        as possible: muscles that follow one another in both the layer model and the world
        mesh (the usual case: one copy for the whole layer) share one."""
        copies = []
        for m, first in zip(self.muscles, self.firsts):
            w, n = vslice[m.name], m.n_particles
            if copies and copies[-1][0].stop == w.start and copies[-1][1].stop == first:
                w0, s0 = copies.pop()
                copies.append((slice(w0.start, w.stop), slice(s0.start, first + n)))
            else:
                copies.append((slice(w.start, w.stop), slice(first, first + n)))
        self.copies = copies


class MusculoskeletalSystem:
    """Kinematic skull + layered muscles (§6), stepped frame by frame.

    Build with :meth:`from_parts`. ``step(contractions, jaw_matrix, dt)``
    advances one frame; ``positions(name)`` reads any body's current vertices.
    """

    def __init__(self, bodies, layers, settings):
        self._names = [b[0] for b in bodies]
        self._faces = {name: f for name, _, f in bodies}
        offsets = np.cumsum([0] + [len(v) for _, v, _ in bodies])
        self._vslice = {n: slice(int(offsets[i]), int(offsets[i + 1])) for i, n in enumerate(self._names)}
        foffsets = np.cumsum([0] + [len(f) for _, _, f in bodies])
        self._fslice = {n: slice(int(foffsets[i]), int(foffsets[i + 1])) for i, n in enumerate(self._names)}
        self._rest = np.concatenate([v for _, v, _ in bodies]).astype(FLOAT)
        self._world_f = np.concatenate(
            [f + offsets[i] for i, (_, _, f) in enumerate(bodies)]).astype(INT)
        self._world_v = self._rest.copy()
        self._layers: list[_Layer] = layers
        self._muscles = {m.name: m for layer in layers for m in layer.muscles}
        self._controls = tuple(self._muscles) + tuple(protrusion_control(n) for n, m in self._muscles.items()
                                                      if m.kind == "sphincter") \
            + tuple(lower_control(n) for n, m in self._muscles.items() if m.kind == "sphincter")
        self._column = {name: i for i, name in enumerate(self._controls)}
        for layer in layers:   # each layer reads its muscles' columns of the contraction array
            layer.columns = np.array([self._column[m.name] for m in layer.muscles], dtype=INT)
            layer.protrusion_columns = np.array(
                [self._column.get(protrusion_control(m.name), -1) for m in layer.muscles], dtype=INT)
            layer.lower_columns = np.array(
                [self._column.get(lower_control(m.name), -1) for m in layer.muscles], dtype=INT)
            if layer.linear is not None:
                layer.linear.columns = np.array([self._column[n] for n in layer.linear.names], dtype=INT)
        self._rest_controls = np.zeros(len(self._controls))
        self.settings = settings
        self._extra: list = []
        self._jaw = np.eye(4)
        self._ties: dict = {}   # sphincter name -> [anatomy.muscles.modiolus.LoopTie], applied in order

    # -- construction -------------------------------------------------------------
    @classmethod
    def from_parts(cls, cranium, mandible, muscles, settings=None, mirror=None) -> "MusculoskeletalSystem":
        """Assemble the system.

        Parameters
        ----------
        cranium, mandible : (vertices (n, 3), faces (m, 3))
            Rest skull meshes (template or fitted space).
        muscles : sequence of Muscle
            Each built on the concatenation (in ``expand_lies_on(m.lies_on)``
            order) of the rest meshes of the bodies it lies on; ``m.layer``
            must exceed the layer of every muscle in ``lies_on``.
        settings : pbd.SolverSettings, optional
            Shared by every layer (default: the paper's 10 iterations).
        mirror : :class:`faceforge.geometry.mirror.Mirror`, optional
            A symmetric rig's plane: each layer's solver colours mirror twins alike
            (:func:`faceforge.anatomy.muscles.mirror.particle_mirror`).

        Raises :class:`~faceforge.exceptions.TemplateError` naming the muscle
        when a name is duplicated, unknown, or a muscle lies on a layer that
        is not deeper.
        """
        from faceforge.pbd import ModelBuilder, Solver, SolverSettings

        settings = settings or SolverSettings()
        bodies = [("cranium", *check_mesh(*cranium)), ("mandible", *check_mesh(*mandible))]
        muscles = sorted(muscles, key=lambda m: m.layer)  # stable: keeps the given order in a layer
        layer_of: dict[str, int] = {}
        for m in muscles:
            if m.name in layer_of or m.name in SKULL or m.name == "skull":
                raise TemplateError(f"muscle {m.name!r}: duplicate or reserved name")
            for dep in expand_lies_on(m.lies_on):
                if dep in SKULL:
                    continue
                if dep not in layer_of:
                    raise TemplateError(f"muscle {m.name!r} lies on unknown or later-listed body {dep!r}")
                if layer_of[dep] >= m.layer:
                    raise TemplateError(f"muscle {m.name!r} (layer {m.layer}) lies on {dep!r} "
                                        f"(layer {layer_of[dep]}): it must be deeper")
            layer_of[m.name] = m.layer
            bodies.append((m.name, m.rest_positions, m.faces))
        fstart = np.cumsum([0] + [len(f) for _, _, f in bodies])
        fstart = {name: int(fstart[i]) for i, (name, _, _) in enumerate(bodies)}
        fcount = {name: len(f) for name, _, f in bodies}
        layers: list[_Layer] = []
        for index in sorted(set(layer_of.values())):
            group = [_to_world(m, fstart, fcount) for m in muscles if m.layer == index]
            b = ModelBuilder()
            firsts, slots = add_muscles_to_builder(b, group)
            model = b.finalize()
            partner = None
            if mirror is not None:
                from faceforge.anatomy.muscles.mirror import particle_mirror

                diag = float(np.linalg.norm(np.ptp(np.vstack([cranium[0], mandible[0]]), axis=0)))
                partner = particle_mirror(group, firsts, model.particle_count, mirror, 5e-3 * diag)
            layers.append(_Layer(index, group, firsts, slots, model, Solver(model, settings, partner),
                                 model.state(), model.control()))
            layers[-1].gather()
        system = cls(bodies, layers, settings)
        for layer in layers:  # face ids -> world vertex ids, once
            layer.vids = np.ascontiguousarray(system._world_f[layer.vids], dtype=INT)
            layer.bary = np.ascontiguousarray(layer.bary, dtype=FLOAT)
            layer.plan_copies(system._vslice)
        for layer in layers:  # rest targets: the rest state is a fixed point
            system._set_targets(layer, system._rest_controls)
        return system

    # -- reading --------------------------------------------------------------------
    @property
    def names(self) -> tuple[str, ...]:
        """All bodies, deepest first: cranium, mandible, muscles by layer."""
        return tuple(self._names)

    @property
    def muscles(self) -> dict:
        """``{name: Muscle}`` (action lines expressed on the world faces)."""
        return dict(self._muscles)

    @property
    def controls(self) -> tuple[str, ...]:
        """What :meth:`step` drives: every muscle by name, then each sphincter's protrusion
        (:func:`faceforge.anatomy.muscles.sphincter.protrusion_control`), then each sphincter's
        lower part (:func:`faceforge.anatomy.muscles.sphincter.lower_control`)."""
        return self._controls

    @property
    def threads(self) -> int:
        """Most threads any muscle layer's step runs on (``pbd.Solver.threads``)."""
        return max((layer.solver.threads for layer in self._layers), default=1)

    @property
    def layer_indices(self) -> tuple[int, ...]:
        return tuple(layer.index for layer in self._layers)

    def positions(self, name: str) -> np.ndarray:
        """Current vertices of body ``name``, ``(n, 3)`` copy."""
        return self._world_v[self._slice(name)].copy()

    def rest_positions(self, name: str) -> np.ndarray:
        return self._rest[self._slice(name)].copy()

    def faces(self, name: str) -> np.ndarray:
        """Faces of body ``name`` in its own vertex numbering, ``(m, 3)``."""
        self._slice(name)
        return self._faces[name]

    def surface(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """Current ``(vertices, faces)`` of one body."""
        return self.positions(name), self.faces(name)

    def world(self, rest: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """All bodies as one mesh ``(vertices (N, 3), faces (M, 3))`` (current or rest).

        Vertex/face ranges of each body: :meth:`vertex_range`, :meth:`face_range`.
        The returned vertices are a copy.
        """
        return (self._rest if rest else self._world_v).copy(), self._world_f

    def world_view(self) -> np.ndarray:
        """The current world vertices ``(N, 3)`` as a read-only view (no copy): valid until the
        next :meth:`step`, :meth:`set_jaw` or :meth:`reset`, which write into it."""
        v = self._world_v.view()
        v.flags.writeable = False
        return v

    def composite(self, names, rest: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """The bodies ``names`` ("skull" allowed) concatenated, faces renumbered."""
        from faceforge.geometry.triangles import concatenate_meshes

        src = self._rest if rest else self._world_v
        v, f, _ = concatenate_meshes([(src[self._slice(n)], self._faces[n]) for n in expand_lies_on(names)])
        return v, f

    def vertex_range(self, name: str) -> slice:
        return self._slice(name)

    def face_range(self, name: str) -> slice:
        self._slice(name)
        return self._fslice[name]

    def body_of_faces(self, face_ids) -> np.ndarray:
        """Name of the body owning each world face id, ``(k,) object``."""
        ids = np.asarray(face_ids, INT)
        starts = np.array([self._fslice[n].start for n in self._names])
        return np.asarray(self._names, dtype=object)[np.searchsorted(starts, ids, side="right") - 1]

    def _slice(self, name: str) -> slice:
        try:
            return self._vslice[name]
        except KeyError:
            raise KeyError(f"unknown body {name!r}; bodies: {', '.join(self._names)}") from None

    def sphincter_lines(self, name: str, world=None) -> dict:
        """The loop points of sphincter ``name`` on ``world (N, 3)`` (default: the current
        vertices): ``{"A1": (k1, 3), "A3": (k3, 3)}``."""
        world = self._world_v if world is None else np.asarray(world, FLOAT)
        for layer in self._layers:
            for m, own in zip(layer.muscles, layer.pieces):
                if m.name == name:
                    pts = bary_points(layer.bary, layer.vids, world, np.empty((len(layer.vids), 3)))
                    return {key: pts[sl].copy() for key, sl in own.items()}
        raise KeyError(f"unknown muscle {name!r}")

    def add_loop_tie(self, name: str, tie) -> None:
        """Tie some of sphincter ``name``'s loop points to the muscles inserting there (a
        :class:`faceforge.anatomy.muscles.modiolus.LoopTie`: the modiolus at the corners, a lip on
        its depressor or levator), after the ties it has; the rest targets are set again."""
        self._ties.setdefault(name, []).append(tie)
        for layer in self._layers:
            self._set_targets(layer, self._rest_controls)

    def clear_loop_ties(self, name: str) -> None:
        """Untie sphincter ``name``'s loop points (:meth:`add_loop_tie`)."""
        self._ties.pop(name, None)
        for layer in self._layers:
            self._set_targets(layer, self._rest_controls)

    # -- stepping -------------------------------------------------------------------
    def add_layer(self, layer) -> None:
        """Append a shallower layer (e.g. the skin): an object with ``step(system, dt)``."""
        if not callable(getattr(layer, "step", None)):
            raise TypeError("a layer must have a step(system, dt) method")
        self._extra.append(layer)

    def set_jaw(self, jaw_matrix) -> None:
        """Place the mandible: rest vertices transformed by the rigid ``(4, 4)`` matrix."""
        T = np.asarray(jaw_matrix, dtype=FLOAT)
        if T.shape != (4, 4):
            raise ValueError(f"jaw_matrix must be (4, 4), got {T.shape}")
        if np.array_equal(T, self._jaw):  # the mandible is already there
            return
        if not _is_rigid(T.tolist()):
            raise ValueError("jaw_matrix must be a rigid transform (rotation + translation)")
        sl = self._vslice["mandible"]
        out = self._world_v[sl]
        np.matmul(self._rest[sl], T[:3, :3].T, out=out)
        out += T[:3, 3]
        self._jaw = T.copy()

    def contraction_array(self, contractions=None) -> np.ndarray:
        """``(m,)`` float64 contractions in :attr:`controls` order from a dict (control -> c;
        missing ones 0; unknown names raise ``KeyError`` listing the controls), None (all 0)
        or an array already in that order (or of the muscles alone, which come first: the
        protrusion drives then stay at rest)."""
        if contractions is None:
            return self._rest_controls
        if isinstance(contractions, Mapping):
            unknown = sorted(set(contractions).difference(self._controls))
            if unknown:
                raise KeyError(f"unknown muscle(s) {unknown}; controls: {', '.join(self.controls)}")
            out = np.zeros(len(self._controls))
            for name, c in contractions.items():
                out[self._column[name]] = c
            return out
        c = np.asarray(contractions, dtype=FLOAT)
        if c.shape == (len(self._muscles),) and len(self._muscles) < len(self._controls):
            out = np.zeros(len(self._controls))   # the muscles alone: the protrusion drives at rest
            out[:len(c)] = c
            return out
        if c.shape != (len(self._controls),):
            raise ValueError(f"contractions must be ({len(self._controls)},) in controls order "
                             f"(or ({len(self._muscles)},), the muscles alone), got {c.shape}")
        return c

    def step(self, contractions=None, jaw_matrix=None, dt: float = 1.0 / 25.0) -> None:
        """Advance one frame.

        Parameters
        ----------
        contractions : (m,) float array in :attr:`controls` order, or dict, optional
            c in [0, 1] (Eq. 4) per control (a muscle's name, or a sphincter's protrusion);
            a dict names them (missing ones at rest, 0; unknown names raise ``KeyError``
            listing the controls). See :meth:`contraction_array`.
        jaw_matrix : (4, 4) float, optional
            Rigid transform of the mandible from its rest pose; None keeps the last.
        dt : float
            Frame time in seconds.
        """
        contractions = self.contraction_array(contractions)
        if jaw_matrix is not None:
            self.set_jaw(jaw_matrix)
        for layer in self._layers:
            self._set_targets(layer, contractions)
            layer.solver.step(layer.state, layer.state, layer.control, dt)
            for world, own in layer.copies:
                self._world_v[world] = layer.state.positions[own]
        for extra in self._extra:
            extra.step(self, dt)

    def _set_targets(self, layer: _Layer, contractions: np.ndarray) -> None:
        """The layer's position targets for ``contractions (m,)`` in :attr:`controls` order."""
        # every surface point of every line of the layer in one gather
        pts = bary_points(layer.bary, layer.vids, self._world_v, layer.pts)
        if layer.linear is not None:   # every linear muscle in one compiled call
            targets = layer.control.position_targets
            if layer.linear_direct:    # its slots are every row of the targets, in order
                layer.linear(pts, contractions, out=targets)
            else:
                targets[layer.linear.slots] = layer.linear(pts, contractions)
        for i, (m, s, own) in enumerate(zip(layer.muscles, layer.slots, layer.pieces)):
            if len(s) and m.kind != "linear":          # the sphincter, in numpy
                lp = {key: pts[sl] for key, sl in own.items()}
                for tie in self._ties.get(m.name, ()):   # points ride on the muscles inserting there
                    lp = tie.apply(lp, self._world_v, contractions)
                c = contractions[layer.columns[i]]
                k = layer.protrusion_columns[i]
                p = contractions[k] if k >= 0 else 0.0
                k = layer.lower_columns[i]
                low = contractions[k] if k >= 0 else 0.0
                layer.control.position_targets[s] = m.targets_from_line_points(c, lp, p, low)

    def reset(self) -> None:
        """Back to the rest state (jaw closed, muscles at rest, zero velocities)."""
        self._world_v[:] = self._rest
        self._jaw = np.eye(4)
        for layer in self._layers:
            fresh = layer.model.state()
            layer.state.positions[:] = fresh.positions
            layer.state.velocities[:] = fresh.velocities
            self._set_targets(layer, self._rest_controls)

    def folded_faces(self, rest: bool = False) -> dict[str, int]:
        """Muscle name -> number of sheet faces turned over (:meth:`Muscle.inverted_faces`)
        in the current frame (or at rest); only muscles with at least one."""
        from faceforge.geometry.triangles import vertex_normals

        v, f = self.world(rest=rest)
        vn = vertex_normals(v, f)
        out = {}
        for name, m in self._muscles.items():
            p = self.rest_positions(name) if rest else self.positions(name)
            k = int(m.inverted_faces(p, v, f, vn).sum())
            if k:
                out[name] = k
        return out

    def constraint_count(self) -> int:
        """Constraints in all layer models."""
        return sum(m.constraint_count() for m in self._muscles.values())

    def particle_count(self) -> int:
        return sum(m.n_particles for m in self._muscles.values())


def underlying_mesh(lies_on, cranium, mandible, muscles=()) -> tuple[np.ndarray, np.ndarray]:
    """The rest surface a muscle with ``lies_on`` is built on: ``(vertices, faces)``.

    The bodies of ``expand_lies_on(lies_on)`` concatenated in that order (whole
    meshes: cranium, mandible, and each deeper muscle's closed surface, all
    faces in their own order). This numbering is the contract with
    :meth:`MusculoskeletalSystem.from_parts`, which re-expresses the action
    lines on the world mesh. A muscle lies on the *top* of a deeper one: build
    its lines with ``ActionLine.from_points(..., project="outermost")`` so that
    points drawn on the skull under a deeper muscle land on that muscle's top
    sheet rather than on its bottom (which touches the skull).
    ``muscles`` is any iterable of the deeper :class:`Muscle` objects.
    """
    from faceforge.geometry.triangles import concatenate_meshes

    by_name = {m.name: m for m in muscles}
    parts = []
    for name in expand_lies_on(lies_on):
        if name == "cranium":
            parts.append(check_mesh(*cranium))
        elif name == "mandible":
            parts.append(check_mesh(*mandible))
        elif name in by_name:
            parts.append((by_name[name].rest_positions, by_name[name].faces))
        else:
            raise TemplateError(f"lies_on names unknown body {name!r}")
    v, f, _ = concatenate_meshes(parts)
    return v, f


def _to_world(m: Muscle, fstart: dict, fcount: dict) -> Muscle:
    """Re-express the muscle's action lines (on :func:`underlying_mesh`) on world faces."""
    names = expand_lies_on(m.lies_on)
    mapping = np.concatenate([fstart[n] + np.arange(fcount[n]) for n in names]).astype(INT)
    lines = {}
    for key, line in m.lines.items():
        ids = line.points.face_ids
        if len(ids) and ids.max() >= len(mapping):
            raise TemplateError(f"muscle {m.name!r}: action line {key} refers to face {ids.max()}, "
                                f"but {'+'.join(names)} have only {len(mapping)} faces")
        lines[key] = ActionLine(SurfacePoints(mapping[ids], line.points.bary), line.closed)
    return replace(m, lines=lines, constraints=dict(m.constraints))
