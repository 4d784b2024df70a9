"""Model (frozen rest data), State (positions, velocities) and Control (per-frame targets).

Kept apart as in Newton/warp.sim: rest data never lives on State and targets never
live on Model. Constraint data is one block of arrays per kind, named prefix-first.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

#: kind codes used in :attr:`Model.blocks`
DISTANCE, BENDING, AREA, VOLUME, POSITION, ATTACHMENT = range(6)
KIND_NAMES = ("distance", "bending", "area", "volume", "position", "attachment")


@dataclass
class State:
    """Dynamic state of all particles.

    positions : (n, 3) float64, length units; velocities : (n, 3) float64, length / s.
    """

    positions: np.ndarray
    velocities: np.ndarray

    def copy(self) -> "State":
        return State(self.positions.copy(), self.velocities.copy())


@dataclass
class Control:
    """Per-frame inputs.

    position_targets : (n_pos, 3) float64, one row per slot returned by
        ``ModelBuilder.add_position`` (the point each constrained particle is pulled to).
    kinematic_positions : (n_kin, 3) float64, one row per ``Model.kinematic_indices``
        entry, written into those particles (inverse mass 0) at the end of each step.
    """

    position_targets: np.ndarray
    kinematic_positions: np.ndarray


def checked_positions(positions: np.ndarray, touched, n: int) -> np.ndarray:
    """The ``touched`` buffer of an in-place projection over ``positions`` ((n, 3) float64,
    C-contiguous; ValueError otherwise): ``touched`` itself ((n,) bool, set True where a particle
    moves) or, when None, an empty one (the kernels skip recording)."""
    if positions.dtype != np.float64 or positions.shape != (n, 3) or not positions.flags.c_contiguous:
        raise ValueError(f"positions must be a C-contiguous ({n}, 3) float64 array")
    if touched is None:
        return np.zeros(0, dtype=np.bool_)
    if touched.dtype != np.bool_ or touched.shape != (n,):
        raise ValueError(f"touched must be a ({n},) bool array")
    return touched


def inverse_masses(inv_mass, n: int) -> np.ndarray:
    """``(n,)`` C-contiguous float64 inverse masses (0: kinematic / pinned) from ``inv_mass``:
    None (all 1), a scalar (the same for all) or an ``(n,)`` array (not copied when it already is
    one). ValueError unless every value is finite and >= 0."""
    if inv_mass is None:
        return np.ones(n)
    if np.ndim(inv_mass) == 0:
        w = np.full(n, float(inv_mass))
    else:
        w = np.ascontiguousarray(inv_mass, dtype=np.float64)
        if w.shape != (n,):
            raise ValueError(f"inv_mass must have shape ({n},) or be a scalar, got {w.shape}")
    if not np.all(np.isfinite(w)) or np.any(w < 0):
        raise ValueError("inv_mass must be finite and >= 0")
    return w


def _ro(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a)
    a.flags.writeable = False
    return a


@dataclass(frozen=True)
class Model:
    """Frozen rest data: particles and per-kind constraint arrays (all read-only).

    Particles: ``rest_positions (n, 3) float64``, ``inv_mass (n,) float64`` (0 =
    kinematic), ``kinematic_indices (n_kin,) int64``.

    Kinds (``m_kind`` constraints each, stiffness in [0, 1], the paper's k):

    * ``distance_indices (m, 2) int64``, ``distance_rest_length (m,)``, ``distance_stiffness (m,)``,
      ``distance_weight (m, 2) float64``: the inverse masses by which each constraint shares its
      correction between its two ends (default: the particles' ``inv_mass``). An end of
      inverse mass 0 in the model never moves; given a weight here, it still takes its share
      of the denominator: a particle the caller moves itself, e.g. to a target, before each
      iteration (the end of a tether: ``ModelBuilder.add_distance``)
    * ``bending_indices (m, 4) int64`` (shared edge first), ``bending_rest_angle (m,)`` rad,
      ``bending_stiffness (m,)``
    * ``area_indices (m, 3) int64``, ``area_rest_area (m,)``, ``area_stiffness (m,)``
    * ``volume_triangle_start (b+1,)`` CSR into ``volume_triangles (f, 3) int64`` (global ids),
      ``volume_rest_volume (b,)``, ``volume_stiffness (b,)``; solver data
      ``volume_particle_start``/``volume_particles`` (global ids),
      ``volume_local_triangles (f, 3)`` and ``volume_reference_start``/``volume_reference``
      (local ids; see :mod:`faceforge.pbd.constraints.volume`)
    * ``position_indices (m,) int64``, ``position_rest_target (m, 3)``, ``position_stiffness (m,)``
    * ``attachment_indices (m,) int64``, ``attachment_triangles (m, 3) int64``,
      ``attachment_bary (m, 3) float64``, ``attachment_stiffness (m,)``

    ``blocks (nb, 3) int64`` rows ``(kind, start, stop)`` give the projection order
    (the order of the builder calls).
    """

    rest_positions: np.ndarray
    inv_mass: np.ndarray
    kinematic_indices: np.ndarray
    distance_indices: np.ndarray
    distance_rest_length: np.ndarray
    distance_stiffness: np.ndarray
    bending_indices: np.ndarray
    bending_rest_angle: np.ndarray
    bending_stiffness: np.ndarray
    area_indices: np.ndarray
    area_rest_area: np.ndarray
    area_stiffness: np.ndarray
    volume_triangle_start: np.ndarray
    volume_triangles: np.ndarray
    volume_rest_volume: np.ndarray
    volume_stiffness: np.ndarray
    volume_particle_start: np.ndarray
    volume_particles: np.ndarray
    volume_local_triangles: np.ndarray
    volume_reference_start: np.ndarray
    volume_reference: np.ndarray
    position_indices: np.ndarray
    position_rest_target: np.ndarray
    position_stiffness: np.ndarray
    attachment_indices: np.ndarray
    attachment_triangles: np.ndarray
    attachment_bary: np.ndarray
    attachment_stiffness: np.ndarray
    blocks: np.ndarray
    distance_weight: np.ndarray | None = None

    def __post_init__(self):
        if self.distance_weight is None:
            object.__setattr__(self, "distance_weight", self.inv_mass[self.distance_indices].reshape(-1, 2))
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, np.ndarray):
                object.__setattr__(self, f.name, _ro(value))

    @property
    def particle_count(self) -> int:
        return len(self.rest_positions)

    @property
    def distance_count(self) -> int:
        return len(self.distance_indices)

    @property
    def bending_count(self) -> int:
        return len(self.bending_indices)

    @property
    def area_count(self) -> int:
        return len(self.area_indices)

    @property
    def volume_count(self) -> int:
        return len(self.volume_rest_volume)

    @property
    def position_count(self) -> int:
        return len(self.position_indices)

    @property
    def attachment_count(self) -> int:
        return len(self.attachment_indices)

    @property
    def constraint_count(self) -> int:
        """All constraints (a volume constraint counts once)."""
        return sum(getattr(self, f"{k}_count") for k in KIND_NAMES)

    def state(self) -> State:
        """The rest state: a copy of the rest positions and zero velocities."""
        return State(np.array(self.rest_positions), np.zeros_like(self.rest_positions))

    def control(self) -> Control:
        """Control at rest: targets at their rest points, kinematic particles at rest."""
        return Control(np.array(self.position_rest_target),
                       np.array(self.rest_positions[self.kinematic_indices]))
