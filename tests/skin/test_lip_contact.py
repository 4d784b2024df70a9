"""The lips' contact at the commissure (``skin.commissure_fold_deg``): the skin quads across the lip
line at the corners are picked (skin.lip_contact) and kept from turning over after every step
(SkinSimulation's fold limit, pbd.dihedral_limit)."""

import numpy as np

from faceforge.pbd import SolverSettings
from faceforge.pbd.constraints.bending import dihedral_angle
from faceforge.skin.binding import Body, bind_skin
from faceforge.skin.layer import SkinSimulation, SkinStiffness, skin_topology
from faceforge.skin.lip_contact import commissure_quads, lip_contacts
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


def _two_lips():
    """Two sheets 0.05 apart: the lower lip (6 x 6 cells over [-0.25, 1.25]^2) at z = 0 facing +z,
    the upper (4 x 4 over [0, 1]^2, over the lower one's inside) at z = 0.05 facing -z (each lip's
    outside toward the other), as one skin; lip_sides -1 / +1."""
    v, f = grid(6, 6, 1.5, 1.5)
    v = v - [0.25, 0.25, 0.0]
    u, g = grid(4, 4)
    up = u + [0.0, 0.0, 0.05]
    verts = np.r_[v, up]
    faces = np.r_[f, g[:, ::-1] + len(v)]
    sides = np.r_[np.full(len(v), -1), np.full(len(up), 1)]
    return verts, faces, sides


def test_lip_contacts_pair_each_lip_with_the_other_lips_faces():
    v, f, sides = _two_lips()
    pts, (start, cand), tris, floor, reach, margin = lip_contacts(v, f, sides, 0.1)
    assert set(sides[pts]) == {1, -1}
    assert (sides[pts] > 0).sum() == 25 and (sides[pts] < 0).sum() < 49   # the lower lip's rim is too far
    for i, x in enumerate(pts):   # every candidate is a face of the other lip
        assert (sides[tris[cand[start[i]:start[i + 1]]]] == -sides[x]).all()
    assert np.all(floor == 0.0) and reach == 0.1
    # a wide radius: each vertex keeps at most NEAREST faces of the other lip
    from faceforge.skin.lip_contact import NEAREST

    pts, (start, cand), tris, _, _, _ = lip_contacts(v, f, sides, 0.6)
    assert np.diff(start).max() == NEAREST   # (the 0.6 ball holds more: a lip face is 0.25 x 0.25)
    assert lip_contacts(v, f, None, 0.1) is None
    assert lip_contacts(v, f, np.zeros(len(v), int), 0.1) is None
    # a face bridging the two lips belongs to neither
    bridged = np.r_[f, [[0, 1, 60]]]
    _, _, tris2, _, _, _ = lip_contacts(v, bridged, sides, 0.1)
    assert len(tris2) == len(f)


def _pressed(contact: bool):
    """The upper lip's body driven 0.2 down over 20 frames, through the lower lip: the upper lip's signed
    distances to the lower lip's faces after 40 steps (negative: crossed)."""
    from faceforge.pbd.triangle_contact import signed_depths

    v, f, sides = _two_lips()
    body_v = np.where((sides < 0)[:, None], v - [0, 0, 0.05], v + [0, 0, 0.05])
    b = bind_skin(v, f, [Body("muscle", "muscle", body_v, f)], max_distance=0.075)   # each lip its own body
    assert np.allclose(np.abs(b.points[:, 2] - v[b.vertex_ids, 2]), 0.05)
    pairs = lip_contacts(v, f, sides, 0.3)
    sim = SkinSimulation(v, f, b, SkinStiffness(), SolverSettings(iterations=10),
                         carried=np.ones(len(b.vertex_ids), bool), tether=np.ones(len(b.vertex_ids)),
                         lip_contact=pairs if contact else None)
    body = Bodies(body_v, f)
    body.v = body_v.copy()
    for k in range(40):   # pressed down over 20 frames, then held
        body.v[sides > 0] = body_v[sides > 0] + [0.0, 0.0, -0.2 * min(1.0, (k + 1) / 20)]
        sim.step(body, 1 / 25)
    pts, (start, cand), tris, _, _, margin = pairs
    return signed_depths(sim.simulated(), pts, start, cand, tris, margin)[sides[pts] > 0]


def test_the_lips_touch_but_do_not_pass_through_each_other():
    free = _pressed(False)
    held = _pressed(True)
    assert np.nanmin(free) < -0.05, np.nanmin(free)   # without the contact the upper lip crosses
    assert np.nanmin(held) > -1e-3, np.nanmin(held)   # with it, the lips meet


def test_a_lip_that_jumps_through_the_other_one_does_not_drag_it():
    """The lower lip springs 0.2 up through the upper lip within one step (a released FAP): the
    skin's contact, given the step's start, does not drag the upper lip's vertices up with the lower
    lip's faces (ICT's released raise_b_lip_lm: 30 folded edges in a frame, docs/notes/lips17.md);
    the contact without the history does."""
    v, f, sides = _two_lips()
    body_v = np.where((sides < 0)[:, None], v - [0, 0, 0.05], v + [0, 0, 0.05])
    b = bind_skin(v, f, [Body("muscle", "muscle", body_v, f)], max_distance=0.075)
    sim = SkinSimulation(v, f, b, SkinStiffness(), SolverSettings(iterations=10),
                         carried=np.ones(len(b.vertex_ids), bool), lip_contact=lip_contacts(v, f, sides, 0.3))
    first = sim.layer.first
    sim._contact_prev[:] = sim.state.positions            # the step's start: at rest
    jumped = sim.state.positions.copy()
    jumped[first + np.flatnonzero(sides < 0), 2] += 0.2   # the step's end: the lower lip 0.15 past the upper
    sim.state.positions[:] = jumped
    sim.touch_lips()
    up = first + np.flatnonzero(sides > 0)
    assert np.allclose(sim.state.positions[up], jumped[up])                 # the upper lip stays
    assert (sim.state.positions[first + np.flatnonzero(sides < 0), 2] < jumped[first + np.flatnonzero(sides < 0), 2]).any()
    blind = jumped.copy()
    sim._contact(blind)                                                     # no history
    assert (blind[up, 2] - jumped[up, 2]).max() > 0.1                       # dragged up
