"""ModelBuilder: collect particles and constraints, then freeze them into a Model.

Every ``add_*`` call appends one block; the solver projects blocks in call order
(deeper layers first, as ``docs/ARCHITECTURE.md`` requires). Rest values default
to the particles' positions at the time of the call. Invalid shapes, indices out
of range or stiffness outside [0, 1] raise ``ValueError`` naming the argument.
"""

from __future__ import annotations

import numpy as np

from faceforge.pbd.constraints import (
    init_area, init_bending, init_distance, init_volume)
from faceforge.pbd.constraints.volume import localize
from faceforge.pbd.model import (
    AREA, ATTACHMENT, BENDING, DISTANCE, POSITION, VOLUME, Model, inverse_masses)


class ModelBuilder:
    """Incremental builder of a :class:`~faceforge.pbd.model.Model`."""

    def __init__(self):
        self._positions: list[np.ndarray] = []
        self._inv_mass: list[np.ndarray] = []
        self._count = 0
        self._kinds: dict[int, list[tuple]] = {k: [] for k in range(6)}
        self._sizes = [0] * 6
        self._blocks: list[list[int]] = []

    # -- particles -------------------------------------------------------------------
    def add_particles(self, positions, inv_mass=1.0) -> int:
        """Add ``positions (m, 3)`` with ``inv_mass (m,)|float`` (>= 0; 0 = kinematic).

        Returns the index of the first new particle.
        """
        p = np.asarray(positions, dtype=np.float64)
        if p.ndim != 2 or p.shape[1] != 3:
            raise ValueError(f"positions must have shape (m, 3), got {p.shape}")
        if not np.all(np.isfinite(p)):
            raise ValueError("positions must be finite")
        w = inverse_masses(inv_mass, len(p))
        first = self._count
        self._positions.append(p.copy())
        self._inv_mass.append(w)
        self._count += len(p)
        return first

    def kinematic_rows(self, particles) -> np.ndarray:
        """Rows ``(m,) int64`` of ``Control.kinematic_positions`` holding ``particles (m,)``
        (added so far, of inverse mass 0)."""
        idx = self._indices("particles", particles, 0)
        w = np.concatenate(self._inv_mass)
        if np.any(w[idx] != 0.0):
            raise ValueError("kinematic_rows: particles of nonzero inverse mass have no row")
        return np.cumsum(w == 0.0)[idx] - 1

    def _all_positions(self) -> np.ndarray:
        return np.concatenate(self._positions) if self._positions else np.zeros((0, 3))

    def _indices(self, name, a, width) -> np.ndarray:
        a = np.asarray(a)
        if a.size == 0:
            a = a.reshape((0, width) if width else (0,))
        shape = (len(a), width) if width else (len(a),)
        if a.shape != shape or (a.size and not np.issubdtype(a.dtype, np.integer)):
            want = f"(m, {width})" if width else "(m,)"
            raise ValueError(f"{name} must be an integer array of shape {want}, got {a.shape} {a.dtype}")
        a = a.astype(np.int64)
        if a.size and (a.min() < 0 or a.max() >= self._count):
            raise ValueError(f"{name} holds particle ids outside [0, {self._count})")
        return a

    @staticmethod
    def _per(name, value, m) -> np.ndarray:
        v = np.asarray(value, dtype=np.float64)
        v = np.full(m, float(v)) if v.ndim == 0 else v
        if v.shape != (m,):
            raise ValueError(f"{name} must be a scalar or have shape ({m},), got {v.shape}")
        if not np.all(np.isfinite(v)):
            raise ValueError(f"{name} must be finite")
        return v

    def _stiffness(self, value, m) -> np.ndarray:
        k = self._per("stiffness", value, m)
        if np.any((k < 0) | (k > 1)):
            raise ValueError("stiffness must lie in [0, 1] (the paper's PBD stiffness k)")
        return k

    def _append(self, kind, m, data):
        if m == 0:
            return
        start = self._sizes[kind]
        self._kinds[kind].append(data)
        self._sizes[kind] += m
        if self._blocks and self._blocks[-1][0] == kind and self._blocks[-1][2] == start:
            self._blocks[-1][2] = start + m
        else:
            self._blocks.append([kind, start, start + m])

    # -- constraints -----------------------------------------------------------------
    def add_distance(self, pairs, stiffness, rest_length=None, weight=None) -> None:
        """Distance constraints on ``pairs (m, 2)``; ``rest_length (m,)`` defaults to current.

        ``weight (m, 2) | (2,)`` (optional, >= 0, not both 0): the inverse masses by which a
        constraint shares its correction between its ends, instead of the particles' own. A
        kinematic end (inverse mass 0) still never moves, but takes its share: a *tether* to
        a particle that the caller holds on a target (``Control.kinematic_positions``) moves
        the other end exactly as the same distance constraint to a particle of that inverse
        mass which a stiffness-1 position constraint put back on the target before it.
        """
        idx = self._indices("pairs", pairs, 2)
        rest = init_distance(self._all_positions(), idx) if rest_length is None \
            else self._per("rest_length", rest_length, len(idx))
        if weight is None:
            wt = np.concatenate(self._inv_mass)[idx] if len(idx) else np.zeros((0, 2))
        else:
            wt = np.broadcast_to(np.asarray(weight, dtype=np.float64), idx.shape).copy() \
                if np.shape(weight) in ((2,), idx.shape) else None
            if wt is None:
                raise ValueError(f"weight must have shape (2,) or ({len(idx)}, 2), got {np.shape(weight)}")
            if not np.all(np.isfinite(wt)) or np.any(wt < 0) or np.any(wt.sum(axis=1) <= 0):
                raise ValueError("weight must be finite, >= 0 and not 0 at both ends")
        self._append(DISTANCE, len(idx), (idx, rest, self._stiffness(stiffness, len(idx)), wt))

    def add_bending(self, quads, stiffness, rest_angle=None) -> None:
        """Dihedral constraints on ``quads (m, 4)``: ``(p0, p1)`` shared edge, ``p2``/``p3`` opposite.

        ``rest_angle (m,)`` radians (signed, 0 = flat) defaults to the current angle.
        """
        idx = self._indices("quads", quads, 4)
        rest = init_bending(self._all_positions(), idx) if rest_angle is None \
            else self._per("rest_angle", rest_angle, len(idx))
        self._append(BENDING, len(idx), (idx, rest, self._stiffness(stiffness, len(idx))))

    def add_area(self, triangles, stiffness, rest_area=None) -> None:
        """Area constraints on ``triangles (m, 3)``; ``rest_area (m,)`` defaults to current."""
        idx = self._indices("triangles", triangles, 3)
        rest = init_area(self._all_positions(), idx) if rest_area is None \
            else self._per("rest_area", rest_area, len(idx))
        self._append(AREA, len(idx), (idx, rest, self._stiffness(stiffness, len(idx))))

    def add_volume(self, triangles, stiffness, rest_volume=None) -> None:
        """One volume constraint over one body's ``triangles (f, 3)`` (open surfaces closed
        virtually, see :mod:`faceforge.pbd.constraints.volume`)."""
        idx = self._indices("triangles", triangles, 3)
        if len(idx) == 0:
            raise ValueError("add_volume needs at least one triangle")
        rest = init_volume(self._all_positions(), idx) if rest_volume is None \
            else float(self._per("rest_volume", rest_volume, 1)[0])
        k = float(self._stiffness(stiffness, 1)[0])
        self._append(VOLUME, 1, (idx, rest, k))

    def add_position(self, particles, stiffness) -> np.ndarray:
        """Pull ``particles (m,)`` toward ``Control.position_targets``; returns their slots (m,)."""
        idx = self._indices("particles", particles, 0)
        start = self._sizes[POSITION]
        self._append(POSITION, len(idx), (idx, self._stiffness(stiffness, len(idx))))
        return np.arange(start, start + len(idx), dtype=np.int64)

    def add_attachment(self, particles, triangles, bary, stiffness) -> None:
        """One-way: pull ``particles (m,)`` toward the points ``bary (m, 3)`` of
        ``triangles (m, 3)`` of another, deeper body; the triangles never move."""
        idx = self._indices("particles", particles, 0)
        tri = self._indices("triangles", triangles, 3)
        b = np.asarray(bary, dtype=np.float64).reshape(-1, 3) if np.size(bary) else np.zeros((0, 3))
        if len(tri) != len(idx) or b.shape != (len(idx), 3):
            raise ValueError(f"particles {idx.shape}, triangles {tri.shape} and bary {b.shape} "
                             "must have matching lengths (m,), (m, 3), (m, 3)")
        if np.any(tri == idx[:, None]):
            raise ValueError("a particle cannot be attached to a triangle it belongs to")
        self._append(ATTACHMENT, len(idx), (idx, tri, b, self._stiffness(stiffness, len(idx))))

    # -- freeze ----------------------------------------------------------------------
    def _cat(self, kind, item, shape):
        parts = [d[item] for d in self._kinds[kind]]
        return np.concatenate(parts) if parts else np.zeros(shape)

    def finalize(self) -> Model:
        """Freeze everything added so far into a read-only :class:`Model`."""
        pos = self._all_positions()
        w = np.concatenate(self._inv_mass) if self._inv_mass else np.zeros(0)
        i64 = np.int64
        vol = self._kinds[VOLUME]
        tstart, pstart, rstart = [0], [0], [0]
        parts, locs, refs = [], [], []
        for tri, _, _ in vol:
            p, loc, ref = localize(tri)
            parts.append(p)
            locs.append(loc)
            refs.append(ref)
            tstart.append(tstart[-1] + len(tri))
            pstart.append(pstart[-1] + len(p))
            rstart.append(rstart[-1] + len(ref))
        cat = (lambda xs, s: np.concatenate(xs) if xs else np.zeros(s, dtype=i64))
        pos_idx = self._cat(POSITION, 0, 0).astype(i64)
        return Model(
            rest_positions=pos, inv_mass=w, kinematic_indices=np.flatnonzero(w == 0).astype(i64),
            distance_indices=self._cat(DISTANCE, 0, (0, 2)).astype(i64),
            distance_rest_length=self._cat(DISTANCE, 1, 0),
            distance_stiffness=self._cat(DISTANCE, 2, 0),
            distance_weight=self._cat(DISTANCE, 3, (0, 2)),
            bending_indices=self._cat(BENDING, 0, (0, 4)).astype(i64),
            bending_rest_angle=self._cat(BENDING, 1, 0),
            bending_stiffness=self._cat(BENDING, 2, 0),
            area_indices=self._cat(AREA, 0, (0, 3)).astype(i64),
            area_rest_area=self._cat(AREA, 1, 0),
            area_stiffness=self._cat(AREA, 2, 0),
            volume_triangle_start=np.array(tstart, dtype=i64),
            volume_triangles=cat([d[0] for d in vol], (0, 3)),
            volume_rest_volume=np.array([d[1] for d in vol], dtype=np.float64),
            volume_stiffness=np.array([d[2] for d in vol], dtype=np.float64),
            volume_particle_start=np.array(pstart, dtype=i64),
            volume_particles=cat(parts, 0),
            volume_local_triangles=cat(locs, (0, 3)),
            volume_reference_start=np.array(rstart, dtype=i64),
            volume_reference=cat(refs, 0),
            position_indices=pos_idx,
            position_rest_target=pos[pos_idx] if len(pos_idx) else np.zeros((0, 3)),
            position_stiffness=self._cat(POSITION, 1, 0),
            attachment_indices=self._cat(ATTACHMENT, 0, 0).astype(i64),
            attachment_triangles=self._cat(ATTACHMENT, 1, (0, 3)).astype(i64),
            attachment_bary=self._cat(ATTACHMENT, 2, (0, 3)),
            attachment_stiffness=self._cat(ATTACHMENT, 3, 0),
            blocks=np.array(self._blocks, dtype=i64).reshape(-1, 3),
        )
