"""Solver: Müller et al. 2007 position-based dynamics over a frozen Model.

``step(state_in, state_out, control, dt)``: for each of ``substeps`` substeps of
length ``h = dt / substeps``: damp velocities (``damping`` per step, spread evenly
over the substeps), predict ``p = x + h v`` for dynamic particles, move kinematic
particles linearly toward ``control.kinematic_positions`` (reached exactly at the
last substep), project all constraints ``iterations`` times in builder order
(sequential Gauss-Seidel), set ``v = (p - x) / h``. Deterministic: fastmath limited to
arcp/nsz (same bytes run to run), no allocation inside the compiled step.

With ``SolverSettings(colouring=True)`` the distance, bending and area constraints of
each builder block are visited colour by colour (blocks keep their order, so deeper
layers are still projected first), and in the PBD modes bending and area run in
vectorised batches of independent constraints (see :mod:`faceforge.pbd.colouring`);
there, a bending block right after a distance block also takes over the stretches on
its quads' edges and cross pairs, projected quad by quad in one fused pass, and an area
block right after that takes each quad's matched triangle into the same pass (see
:mod:`faceforge.pbd.constraints.quad`). Distance blocks run in vectorised batches of
their colour runs too.

With ``SolverSettings(partitions=k)``, ``k > 1``, the model is renumbered and regrouped into
k particle-disjoint parts and a seam (:mod:`faceforge.pbd.partition`); each iteration
projects the parts at once on numba's threads, each in block order, then the seam. Without
usable threads (:mod:`faceforge.pbd.threads`) the same sweep runs on the calling thread: the
result depends on k, never on the threads. The caller's State and Control keep the model's
numbering; the step gathers and scatters them.

Note: numba's on-disk cache does not track the constraint modules that ``_step``
inlines; after editing one, delete ``faceforge/pbd/**/__pycache__/*.nb[ic]``.
"""

from __future__ import annotations

import numpy as np

from faceforge.pbd._kernels import QUAD, QUAD_AREA, _step, _step_parts, _take_rows
from faceforge.pbd.colouring import colour_order, straddling
from faceforge.pbd.constraints._common import BATCH, BATCH_ROWS
from faceforge.pbd.constraints.bending import rest_cos_sin
from faceforge.pbd.constraints.distance import move_weights, pbd_coefficients
from faceforge.pbd.constraints.quad import (
    area_table, areas_first, match_quad_stretches, match_quad_triangles, stretch_table)
from faceforge.pbd.constraints.volume import pair_triangles
from faceforge.pbd.model import AREA, BENDING, DISTANCE, Control, Model, State
from faceforge.pbd.partition import MIN_SLAB_CONSTRAINTS, partitioned, row_cuts
from faceforge.pbd.settings import SolverSettings
from faceforge.pbd.thread_choice import ThreadChooser
from faceforge.pbd.threads import threaded, threads_used
from faceforge.pbd.compile_ahead import wait as wait_for_compile


def _own(a: np.ndarray) -> np.ndarray:
    return np.array(a, order="C", copy=True)


def _writable(a) -> np.ndarray:
    a = np.ascontiguousarray(a, dtype=np.float64)
    return a if a.flags.writeable else a.copy()


def effective_stiffness(k: np.ndarray, settings: SolverSettings) -> tuple[np.ndarray, np.ndarray]:
    """Per-projection ``(k_eff, c)`` for the stiffness mode (see :mod:`faceforge.pbd.settings`).

    k : (m,) float in [0, 1]. Returns two (m,) float64 arrays: the PBD scale and the
    XPBD compliance ratio (0 in the PBD modes).
    """
    k = np.asarray(k, dtype=np.float64)
    mode = settings.stiffness_mode
    if mode == "paper":
        return k.copy(), np.zeros_like(k)
    if mode == "iteration_independent":
        return 1.0 - (1.0 - k) ** (1.0 / settings.iterations), np.zeros_like(k)
    on = k > 0
    c = np.zeros_like(k)
    c[on] = (1.0 - k[on]) / k[on]
    return on.astype(np.float64), c


def _check_particle_ids(m: Model) -> None:
    """ValueError when an index array of ``m`` holds a particle id outside
    ``[0, particle_count)`` (the kernels read ids unsigned, without bounds checks)."""
    for name in ("kinematic_indices", "distance_indices", "bending_indices", "area_indices",
                 "volume_triangles", "volume_particles", "position_indices",
                 "attachment_indices", "attachment_triangles"):
        ids = getattr(m, name)
        if ids.size and (ids.min() < 0 or ids.max() >= m.particle_count):
            raise ValueError(f"model.{name} holds particle ids outside "
                             f"[0, {m.particle_count})")


def _volume_arrays(m: Model, part, partitions: int) -> tuple:
    """The volume kernel's eight arrays (private copies), in the compiled step's order.

    ``(particle_start (bodies + 1,), particles (p,), particle_cuts (bodies, partitions + 2),
    row_cuts (bodies, partitions + 2), rows (r, 4) paired triangles, reference_start,
    reference particles in global ids, rest volumes (bodies,))``. With ``part`` ((particles,)
    int, -1 none) each body's rows are grouped by part, the seam last, and its particles by
    part, those of no part last (offsets in its slice), so that a body joining parts sums them
    part by part at once (``volume._solve_volume_parts``); without, one group each.
    """
    ref_global = np.concatenate([  # reference particles of each body, in global ids
        m.volume_particles[m.volume_particle_start[j]:][
            m.volume_reference[m.volume_reference_start[j]:m.volume_reference_start[j + 1]]]
        for j in range(m.volume_count)]) if m.volume_count else np.zeros(0, dtype=np.int64)
    ts = m.volume_triangle_start  # the kernel takes each body's triangles paired
    rows = [pair_triangles(m.volume_triangles[ts[j]:ts[j + 1]])
            for j in range(m.volume_count)]
    row_start = np.concatenate([[0], np.cumsum([len(r) for r in rows])]).astype(np.int64)
    cuts = np.repeat(row_start[1:, None], partitions + 2, axis=1)
    cuts[:, 0] = row_start[:-1]
    ps = m.volume_particle_start
    particles = np.array(m.volume_particles)
    pcuts = np.repeat(np.diff(ps)[:, None], partitions + 2, axis=1)
    pcuts[:, 0] = 0
    if part is not None:
        for j in range(m.volume_count):
            order, cuts_j = row_cuts(rows[j], part, partitions)
            rows[j] = rows[j][order]
            cuts[j] = row_start[j] + cuts_j
            own = particles[ps[j]:ps[j + 1]]
            label = np.where(part[own] < 0, partitions, part[own])
            order = np.argsort(label, kind="stable")
            particles[ps[j]:ps[j + 1]] = own[order]
            pcuts[j] = np.searchsorted(label[order], np.arange(partitions + 2))
    return tuple(_own(a) for a in (
        m.volume_particle_start, particles, pcuts, cuts,
        np.concatenate(rows) if rows else np.zeros((0, 4), dtype=np.int64),
        m.volume_reference_start, ref_global, m.volume_rest_volume))


class Solver:
    """Steps a :class:`Model`; holds only derived per-mode arrays and scratch buffers."""

    def __init__(self, model: Model, settings: SolverSettings | None = None, mirror: np.ndarray | None = None,
                 reverse: bool = False):
        """Derive the compiled step's arrays from ``model`` (left untouched) for ``settings``.

        model : :class:`Model` (particle ids checked against ``particle_count``; ValueError
        otherwise). settings : :class:`SolverSettings`, default ``SolverSettings()``. With
        ``partitions > 1`` the kernels see the model renumbered part by part
        (:meth:`_partition`); with ``colouring`` the distance, bending and area constraints are
        reordered colour by colour (:meth:`_constraint_arrays`). Every array handed to the
        compiled step is a private writable C-contiguous copy, so that all models share one
        compiled signature (read-only arrays would type differently). ``mirror`` ((particles,)
        int, optional): each particle's mirror partner in a mirror-symmetric model; with
        ``colouring`` a constraint and its twin then share a colour
        (:func:`faceforge.pbd.colouring.mirror_colouring`), so the sweep treats both sides alike.
        Twins sharing a particle (straddling the plane) still take two colours, one side first;
        a small model (fewer than ``partition.MIN_SLAB_CONSTRAINTS`` constraints: the lip ring)
        holding such twins is then also stepped by a second solver with those pairs in the
        other order (``reverse``) and each step averages the two: a symmetric result for about
        twice the (small) cost (issue 25: the ring's order alone made the levator labii move
        the two sides 7-9 % apart).
        """
        self.model = model
        self.settings = settings or SolverSettings()
        s = self.settings
        _check_particle_ids(model)
        self._reverse = reverse
        self._mirror = None
        if mirror is not None:
            mirror = np.asarray(mirror, dtype=np.int64)
            if mirror.shape != (model.particle_count,):
                raise ValueError(f"mirror must map each of the {model.particle_count} particles, got {mirror.shape}")
        m, part = self._partition(model, s, mirror)
        if mirror is not None:
            self._mirror = mirror if self._particle_order is None else \
                self._old_order[mirror[self._particle_order]]
        self._w = _own(m.inv_mass)
        self._kin = _own(m.kinematic_indices)
        self._blocks = _own(m.blocks)
        self._volume = _volume_arrays(m, part, s.partitions)
        self._position = _own(m.position_indices)
        self._attachment = tuple(_own(a) for a in (
            m.attachment_indices, m.attachment_triangles, m.attachment_bary))
        self._kin_start = np.zeros((len(self._kin), 3))
        self._prev = np.zeros((m.particle_count, 3))
        self._k = {}
        for kind in ("distance", "bending", "area", "volume", "position", "attachment"):
            self._k[kind] = effective_stiffness(getattr(m, f"{kind}_stiffness"), s)
        self._lams = np.zeros(m.constraint_count)
        self._vol_g = np.zeros((m.particle_count, 3))
        self._damp = (1.0 - s.damping) ** (1.0 / s.substeps)
        d_weight = self._constraint_arrays(m, s)
        self._sweep_data(m, s, d_weight)
        self._frozen = self._frozen_arguments()
        self._mirrored = None   # the solver in the other order, averaged with (see above)
        if self._mirror is not None and s.colouring and not reverse and \
                model.constraint_count < MIN_SLAB_CONSTRAINTS and any(
                    straddling(getattr(model, f"{k}_indices"), mirror) for k in ("distance", "bending", "area")):
            self._mirrored = Solver(model, settings, mirror, reverse=True)
            self._spare = (model.state(), model.state())

    def _partition(self, model: Model, s: SolverSettings, mirror=None):
        """Renumber and regroup ``model`` into parts when ``s.partitions > 1`` (cut at the
        mirror plane when ``mirror``, the particles' partners, is given: :func:`partitioned`).

        Sets ``_segment`` ((blocks,) int64: the part of each block row, 0 with one part) and,
        when the numbering changes, ``_particle_order`` / ``_old_order`` / ``_x`` / ``_v``
        (particles, gathered and scattered by the step) and ``_position_order`` /
        ``_targets`` (position-constraint slots). A model left in one part (too small to cut)
        keeps its numbering. Returns ``(model the kernels see, part)``: ``part`` (particles,)
        int, the part of each particle (-1 none), or None without parts.
        """
        self._position_order = self._particle_order = None
        self._segment = np.zeros(len(model.blocks), dtype=np.int64)
        split = partitioned(model, s.partitions, mirror) if s.partitions > 1 else None
        if split is None or split.segment.max() <= 0:
            return model, None
        self._segment = split.segment
        order, slots = split.particle_order, split.position_order
        if not np.array_equal(order, np.arange(len(order))):
            self._particle_order = order
            self._old_order = np.argsort(order)   # new id of each old particle
            self._x = np.zeros((len(order), 3))
            self._v = np.zeros((len(order), 3))
        if not np.array_equal(slots, np.arange(len(slots))):
            self._position_order = slots
            self._targets = np.zeros((len(slots), 3))
        return split.model, split.part

    def _constraint_arrays(self, m: Model, s: SolverSettings) -> np.ndarray:
        """Set ``_arrays`` (per kind ``(indices, rest, k_eff, c)``) and ``_runs`` (per kind,
        run starts of independent constraints for the vectorised sweeps; empty: the scalar
        sweep) for distance, bending and area, permuted colour by colour with
        ``s.colouring``. Returns the distance weights ((distance,) float) in the same order.
        """
        self._arrays = {
            "distance": (_own(m.distance_indices), _own(m.distance_rest_length)),
            "bending": (_own(m.bending_indices), rest_cos_sin(m.bending_rest_angle)),
            "area": (_own(m.area_indices), _own(m.area_rest_area)),
        }
        self._runs = {kind: np.zeros(0, dtype=np.int64) for kind in ("distance", "bending", "area")}
        d_weight = m.distance_weight
        for code, kind in ((DISTANCE, "distance"), (BENDING, "bending"), (AREA, "area")):
            idx, rest = self._arrays[kind]
            kk, c = self._k[kind]
            if s.colouring:
                order, runs = colour_order(idx, m.particle_count,
                                           m.blocks[m.blocks[:, 0] == code, 1:], self._mirror,
                                           self._reverse)
                idx, rest, kk, c = (np.ascontiguousarray(a[order]) for a in (idx, rest, kk, c))
                if kind == "distance":
                    d_weight = d_weight[order]
                if kind in self._runs and s.stiffness_mode != "xpbd":
                    self._runs[kind] = runs
            self._arrays[kind] = (idx, rest, kk, c)
        return d_weight

    def _sweep_data(self, m: Model, s: SolverSettings, d_weight: np.ndarray) -> None:
        """Per-constraint data of the PBD sweeps (inverse masses are frozen in the Model), the
        XPBD sweep's weights, the fused quad tables (colouring in the PBD modes), the scratch
        buffers (one per part) and the part boundaries ``_seg`` ((partitions + 2,) int64)."""
        d_idx, d_rest, d_k, _ = self._arrays["distance"]
        self._d_coef = pbd_coefficients(d_idx, d_rest, d_k, m.inv_mass, d_weight)
        self._d_wt = move_weights(d_idx, m.inv_mass, d_weight)
        self._q_stretch = np.zeros((6, m.bending_count))  # transposed: rows are vectors
        self._q_area = np.zeros((3, m.bending_count))
        # per bending run, the end of its quads with a fused area (all of them by default)
        self._q_area_stop = np.ascontiguousarray(self._runs["bending"][1:])
        if s.colouring and s.stiffness_mode != "xpbd":
            self._fuse_quad_stretches()
            self._fuse_quad_areas()
        b_idx, b_rest, _, _ = self._arrays["bending"]
        self._b_w = np.ascontiguousarray(m.inv_mass[b_idx].T)
        self._b_rest_t = np.ascontiguousarray(b_rest.T)
        self._a_w = np.ascontiguousarray(m.inv_mass[self._arrays["area"][0]].T)
        self._d_coef_t = np.ascontiguousarray(self._d_coef.T)
        self._bufs = np.zeros((s.partitions, BATCH_ROWS * BATCH))  # one scratch per part
        self._seg = np.searchsorted(self._segment, np.arange(s.partitions + 2)).astype(np.int64)
        # the parts on threads when numba can run them well (pbd.threads); else one after
        # the other in the same order: _project's block order is parts, then the seam
        # (not when one part holds every row: a small model, partition.MIN_SLAB_CONSTRAINTS)
        busy = np.count_nonzero(np.diff(self._seg) > 0)
        self._threaded = busy > 1 and threaded()
        # threads or the calling thread, whichever the clock says is faster (same bits)
        self._chooser = ThreadChooser(self._threaded)
        self._compiled = False   # a background compile of the step kernels waited for (pbd.compile_ahead)

    def _frozen_arguments(self) -> tuple:
        """The compiled step's arguments that never change, gathered once (a step's Python
        side then costs a few microseconds, which the small muscle layers notice)."""
        s, k = self.settings, self._k
        return (
            self._w, self._kin, self._kin_start, self._prev, float(s.gravity), self._damp,
            s.substeps, s.iterations, s.stiffness_mode == "xpbd", self._blocks, self._seg,
            self._lams,
            *self._arrays["distance"], self._d_coef, self._runs["distance"], self._d_coef_t,
            self._d_wt,
            *self._arrays["bending"], self._runs["bending"], self._b_w, self._b_rest_t,
            self._q_stretch, self._q_area, self._q_area_stop,
            *self._arrays["area"], self._runs["area"], self._a_w, self._bufs,
            *self._volume, *k["volume"], self._vol_g,
            self._position, *k["position"],
            *self._attachment,
            *k["attachment"])

    @property
    def threads(self) -> int:
        """How many threads a step runs on (1 without partitions, for a model too small to
        cut, or without usable threads: :mod:`faceforge.pbd.threads`)."""
        return threads_used(self.settings.partitions) if self._threaded else 1

    def _fuse_quad_stretches(self) -> None:
        """Fold the stretches of each bending quad into a fused sweep (kind ``QUAD``).

        For every bending block that directly follows a distance block, the distance
        constraints on a quad's edge or cross pair move from the distance block into the
        quad's column of ``_q_stretch`` and the block becomes a fused block (see
        :mod:`faceforge.pbd.constraints.quad`); the other distance constraints keep their
        block and order.
        """
        blocks = self._blocks
        d_idx = self._arrays["distance"][0]
        b_idx = self._arrays["bending"][0]
        drop = np.zeros(len(d_idx), dtype=bool)
        for r in range(1, len(blocks)):
            if (blocks[r, 0] != BENDING or blocks[r - 1, 0] != DISTANCE
                    or self._segment[r] != self._segment[r - 1]):
                continue
            (ds, de), (bs, be) = blocks[r - 1, 1:], blocks[r, 1:]
            match = match_quad_stretches(d_idx[ds:de], b_idx[bs:be])
            if not (match >= 0).any():
                continue
            self._q_stretch[:, bs:be] = stretch_table(d_idx[ds:de], b_idx[bs:be], match,
                                                      self._d_coef[ds:de]).T
            drop[ds + match[match >= 0]] = True
            blocks[r, 0] = QUAD
        keep = self._drop_constraints(DISTANCE, "distance", drop)
        if keep is not None:
            self._d_coef = np.ascontiguousarray(self._d_coef[keep])
            self._d_wt = np.ascontiguousarray(self._d_wt[keep])

    def _drop_constraints(self, code: int, kind: str, drop: np.ndarray):
        """Remove the constraints ``drop (m,) bool`` of ``kind`` (taken over by a fused sweep):
        their arrays, colour runs and block ranges are renumbered, emptied blocks go. Returns
        the kept mask, or None when nothing is dropped."""
        if not drop.any():
            return None
        keep = ~drop
        new_index = np.concatenate([[0], np.cumsum(keep)])
        rows, segment = [], []
        for (k, start, stop), part in zip(self._blocks, self._segment):
            if k == code:
                start, stop = new_index[start], new_index[stop]
                if start == stop:
                    continue
            rows.append((k, start, stop))
            segment.append(part)
        self._blocks = np.array(rows, dtype=np.int64).reshape(-1, 3)
        self._segment = np.array(segment, dtype=np.int64)
        self._arrays[kind] = tuple(np.ascontiguousarray(a[keep]) for a in self._arrays[kind])
        self._runs[kind] = np.unique(new_index[self._runs[kind]])
        return keep

    def _fuse_quad_areas(self) -> None:
        """Fold area constraints into the fused quads (kind ``QUAD_AREA``).

        For every fused quad block directly followed by an area block, each quad takes
        at most one of that block's triangles lying on it (:func:`match_quad_triangles`),
        projected right after the quad's bending (a Gauss-Seidel order change within the
        layer, like the stretch fusion); the other triangles keep their block, order and
        colour runs.
        """
        blocks = self._blocks
        a_idx = self._arrays["area"][0]
        b_idx = self._arrays["bending"][0]
        drop = np.zeros(len(a_idx), dtype=bool)
        owner = np.full(len(b_idx), -1, dtype=np.int64)  # fused triangle of each quad
        for r in range(len(blocks) - 1):
            if (blocks[r, 0] != QUAD or blocks[r + 1, 0] != AREA
                    or self._segment[r] != self._segment[r + 1]):
                continue
            (bs, be), (a_s, ae) = blocks[r, 1:], blocks[r + 1, 1:]
            match = match_quad_triangles(a_idx[a_s:ae], b_idx[bs:be])
            if not (match >= 0).any():
                continue
            _, rest, kk, _ = self._arrays["area"]
            self._q_area[:, bs:be] = area_table(a_idx[a_s:ae], b_idx[bs:be], match,
                                                rest[a_s:ae], kk[a_s:ae]).T
            drop[a_s + match[match >= 0]] = True
            owner[bs:be] = match
            blocks[r, 0] = QUAD_AREA
        self._drop_constraints(AREA, "area", drop)
        if (owner >= 0).any():  # quads with an area first in each run: the sweep skips the rest
            order, self._q_area_stop = areas_first(owner, self._runs["bending"])
            self._arrays["bending"] = tuple(np.ascontiguousarray(a[order])
                                            for a in self._arrays["bending"])
            self._q_stretch = np.ascontiguousarray(self._q_stretch[:, order])
            self._q_area = np.ascontiguousarray(self._q_area[:, order])

    def step(self, state_in: State, state_out: State, control: Control, dt: float) -> None:
        """Advance ``state_in`` by ``dt`` seconds into ``state_out`` (may be the same object).

        Arrays of ``state_out`` are written in place; they must be C-contiguous float64
        ``(n, 3)`` like ``state_in``'s. With a mirrored twin solver (see ``__init__``) the
        positions and velocities are the mean of the two orders' steps.
        """
        if self._mirrored is None:
            return self._step_one(state_in, state_out, control, dt)
        a, b = self._spare
        np.copyto(b.positions, state_in.positions)
        np.copyto(b.velocities, state_in.velocities)
        self._mirrored._step_one(b, b, control, dt)
        self._step_one(state_in, a, control, dt)
        np.add(a.positions, b.positions, out=state_out.positions)
        state_out.positions *= 0.5
        np.add(a.velocities, b.velocities, out=state_out.velocities)
        state_out.velocities *= 0.5

    def _step_one(self, state_in: State, state_out: State, control: Control, dt: float) -> None:
        """:meth:`step` in this solver's own order."""
        m = self.model
        n = m.particle_count
        for name, a in (("state_in.positions", state_in.positions),
                        ("state_in.velocities", state_in.velocities),
                        ("state_out.positions", state_out.positions),
                        ("state_out.velocities", state_out.velocities)):
            if a.shape != (n, 3) or a.dtype != np.float64 or not a.flags.c_contiguous:
                raise ValueError(f"{name} must be a C-contiguous float64 array of shape "
                                 f"({n}, 3), got {a.shape} {a.dtype}")
        targets = _writable(control.position_targets)
        kin = _writable(control.kinematic_positions)
        if targets.shape != (m.position_count, 3):
            raise ValueError(f"control.position_targets must have shape ({m.position_count}, 3), "
                             f"got {targets.shape}")
        if kin.shape != (len(self._kin), 3):
            raise ValueError(f"control.kinematic_positions must have shape ({len(self._kin)}, 3), "
                             f"got {kin.shape}")
        if self._position_order is not None:  # into the partitioned model's slot order
            targets = _take_rows(targets, self._position_order, self._targets)
        if not dt > 0:
            raise ValueError(f"dt must be > 0, got {dt!r}")
        s = self.settings
        x_in, v_in, x_out, v_out = (state_in.positions, state_in.velocities,
                                    state_out.positions, state_out.velocities)
        if self._particle_order is not None:  # stepped in the partitioned model's numbering
            x_in = x_out = _take_rows(x_in, self._particle_order, self._x)
            v_in = v_out = _take_rows(v_in, self._particle_order, self._v)
        if not self._compiled:   # the kernels a background process may be compiling (pbd.compile_ahead)
            wait_for_compile()
            self._compiled = True
        # two kernels: a run that never threads never compiles the parallel one (issue 28)
        self._chooser.run(lambda threaded: (_step_parts if threaded else _step)(
            x_in, v_in, x_out, v_out, kin, targets, dt / s.substeps, threaded, *self._frozen))
        if self._particle_order is not None:
            _take_rows(self._x, self._old_order, state_out.positions)
            _take_rows(self._v, self._old_order, state_out.velocities)
