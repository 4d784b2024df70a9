"""Position-based dynamics (Müller et al. 2007) as used by the paper (§3).

Knows nothing about faces: particles, per-kind constraint arrays, a compiled step::

    from faceforge.pbd import ModelBuilder, Solver, SolverSettings
    b = ModelBuilder(); b.add_particles(positions, inv_mass); b.add_distance(pairs, 0.15)
    model = b.finalize(); state = model.state(); control = model.control()
    Solver(model, SolverSettings(iterations=10)).step(state, state, control, 1 / 25)
"""

from faceforge.pbd.builder import ModelBuilder
from faceforge.pbd.model import Control, Model, State
from faceforge.pbd.residual import max_abs_residuals, residuals
from faceforge.pbd.settings import STIFFNESS_MODES, SolverSettings
from faceforge.pbd.solver import Solver, effective_stiffness

__all__ = ["ModelBuilder", "Model", "State", "Control", "Solver", "SolverSettings",
           "STIFFNESS_MODES", "effective_stiffness", "residuals", "max_abs_residuals"]
