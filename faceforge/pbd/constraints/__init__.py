"""Constraint kinds: per kind ``init_<kind>`` (rest values), ``residual_<kind>`` (C per
constraint) and ``solve_<kind>`` (one Gauss-Seidel sweep, wrapping the private numba
kernel ``_solve_<kind>`` that projects a single constraint in place).

All kernels share :func:`._common._multiplier`, so the three stiffness modes of
:class:`faceforge.pbd.SolverSettings` apply to every kind alike.
"""

from faceforge.pbd.constraints.area import init_area, residual_area, solve_area
from faceforge.pbd.constraints.attachment import (
    init_attachment, residual_attachment, solve_attachment)
from faceforge.pbd.constraints.bending import init_bending, residual_bending, solve_bending
from faceforge.pbd.constraints.distance import init_distance, residual_distance, solve_distance
from faceforge.pbd.constraints.position import init_position, residual_position, solve_position
from faceforge.pbd.constraints.volume import init_volume, residual_volume, solve_volume

__all__ = [
    "init_area", "residual_area", "solve_area",
    "init_attachment", "residual_attachment", "solve_attachment",
    "init_bending", "residual_bending", "solve_bending",
    "init_distance", "residual_distance", "solve_distance",
    "init_position", "residual_position", "solve_position",
    "init_volume", "residual_volume", "solve_volume",
]
