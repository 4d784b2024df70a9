"""The lips' contact at the commissure (``skin.commissure_fold_deg``): the skin quads across the lip
line at the corners are picked (skin.lip_contact) and kept from turning over after every step
(SkinSimulation's fold limit, pbd.dihedral_limit)."""

import numpy as np

from faceforge.pbd import SolverSettings
from faceforge.pbd.constraints.bending import dihedral_angle
from faceforge.skin.binding import Body, bind_skin
from faceforge.skin.layer import SkinSimulation, SkinStiffness, skin_topology
from faceforge.skin.lip_contact import commissure_quads
from tests.skin.synthetic import grid, mouth_grid
from tests.skin.test_carry import Bodies


def test_commissure_quads_span_both_lips_at_the_corners_only():
    v, f, lips = mouth_grid(8)
    sides = np.where(v[:, 1] > 0.5 + 1e-9, 1, np.where(v[:, 1] < 0.5 - 1e-9, -1, 0))
    lm = {k: v[i] for k, i in lips.items()}
    lm["8.3"], lm["8.4"] = v[lips["2.4"]] + [0.05, 0, 0], v[lips["2.5"]] - [0.05, 0, 0]
    q = commissure_quads(v, f, sides, lm, radius=0.2)
    assert len(q)
    s = sides[q]
    assert ((s > 0).any(axis=1) & (s < 0).any(axis=1)).all()
    corners = v[[lips["2.4"], lips["2.5"]]]
    reach = 0.2 * np.linalg.norm(lm["8.3"] - lm["8.4"])
    near = np.linalg.norm(v[q][:, :, None] - corners[None, None], axis=3).min(axis=2) <= reach + 1e-12
    assert near.any(axis=1).all()
    # the lip line's middle is not the commissure
    mid = lips["2.2"]
    assert not (q == mid).any()
    assert len(commissure_quads(v, f, None, lm)) == 0
    assert len(commissure_quads(v, f, sides, lm, radius=0.0)) == 0


def _dragged_over(fold_limit):
    """A 4 x 4 sheet tethered to a body under it whose middle vertex is dragged over its lower-left
    neighbour (bending and area off, as a sub-mm corner triangle gives little resistance): the
    sheet's dihedrals after 60 steps, degrees."""
    v, f = grid(4, 4)
    mv = v + [0.0, 0.0, -0.05]
    b = bind_skin(v, f, [Body("muscle", "muscle", mv, f)], max_distance=0.5)
    quads = skin_topology(f).bending_quads
    sim = SkinSimulation(v, f, b, SkinStiffness(bending=0.0, area=0.0), SolverSettings(iterations=10),
                         carried=np.ones(len(b.vertex_ids), bool), tether=np.ones(len(b.vertex_ids)),
                         fold_limit=None if fold_limit is None else (quads, np.radians(fold_limit)))
    body = Bodies(mv, f)
    body.v = mv.copy()
    body.v[12] += [-0.45, -0.45, 0.0]
    for _ in range(60):
        sim.step(body, 1 / 25)
    return np.degrees(np.abs(dihedral_angle(sim.simulated(), quads)))


def test_the_fold_limit_keeps_quads_from_turning_over():
    free = _dragged_over(None)
    held = _dragged_over(75.0)
    assert (free > 90).sum() >= 2, free.max()
    assert held.max() < 80, held.max()
