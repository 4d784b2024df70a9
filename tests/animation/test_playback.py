"""The simulation loop and the physical checks, on stand-in layers and a real PBD skin."""

import numpy as np
import pytest

from faceforge.animation.checks import (check_animation, inside_bones, inverted_faces, inverted_triangles,
                                        points_inside)
from faceforge.animation.playback import Rig, Timings, play, static_poses
from tests.pbd.meshes import grid_faces


def grid(n=6):
    """A flat (n x n) sheet in the XY plane facing +Z, triangulated."""
    x, y = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n))
    v = np.column_stack([x.ravel(), y.ravel(), np.zeros(n * n)])
    return v, grid_faces(n)


def box():
    import trimesh
    m = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    return np.asarray(m.vertices), np.asarray(m.faces)


def follower_rig(rest, order):
    """Skull -> muscles -> skin stand-ins that log the call order and move rigidly."""

    def skull(jaw):
        order.append("skull")
        return np.array([0.0, -jaw[0], jaw[2]])

    def muscles(c, bones, dt):
        order.append("muscles")
        return bones + np.array([c.sum(), 0.0, 0.0])

    def skin(bones, muscles, dt):
        order.append("skin")
        return rest + muscles

    return Rig(skull=skull, muscles=muscles, skin=skin, rest=rest)


def test_layers_run_deepest_first_and_rest_is_a_fixed_point():
    rest, _ = grid()
    order = []
    rig = follower_rig(rest, order)
    out = play(rig, np.zeros((4, 2)), np.zeros((4, 3)), fps=25)
    assert order == ["skull", "muscles", "skin"] * 4
    assert np.array_equal(out, np.broadcast_to(rest, out.shape))


def test_influence_weights_the_displacement():
    rest, _ = grid()
    w = np.linspace(0, 1, len(rest))
    rig = follower_rig(rest, [])
    rig.influence = w
    out = play(rig, np.full((1, 2), 0.25), np.zeros((1, 3)), fps=25)
    assert np.allclose(out[0] - rest, w[:, None] * np.array([0.5, 0.0, 0.0]))


def test_progress_timings_and_settle():
    rest, _ = grid()
    calls = []
    rig = follower_rig(rest, [])

    def progress(it, total, desc):
        calls.append((total, desc))
        return it

    t = Timings()
    play(rig, np.zeros((3, 1)), np.zeros((3, 3)), fps=30, progress=progress, timings=t, settle=2)
    assert calls == [(3, "frames")] and t.frames == 9
    ms = t.per_frame_ms()
    assert ms["total"] == pytest.approx(ms["skull"] + ms["muscles"] + ms["skin"])


def test_non_finite_frame_is_named():
    rest, _ = grid()
    rig = follower_rig(rest, [])
    with pytest.raises(FloatingPointError, match="frame 1"):
        play(rig, np.array([[0.0], [np.nan]]), np.zeros((2, 3)), fps=25)


def test_real_pbd_skin_follows_its_anchor_and_settles():
    """A PBD sheet whose border is position-driven follows a translation of its border."""
    from faceforge.pbd import ModelBuilder, Solver, SolverSettings

    rest, faces = grid(5)
    b = ModelBuilder()
    b.add_particles(rest, np.ones(len(rest)))
    ring = np.array([i for i in range(25) if i % 5 in (0, 4) or i // 5 in (0, 4)])
    b.add_position(ring, 1.0)
    edges = np.unique(np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1), axis=0)
    b.add_distance(edges, 0.5)
    model = b.finalize()
    solver = Solver(model, SolverSettings(iterations=10, substeps=1, damping=0.1))
    state = {"s": model.state()}
    control = model.control()

    def reset():
        state["s"] = model.state()

    def skin(bones, muscles, dt):
        control.position_targets[:] = rest[ring] + bones
        solver.step(state["s"], state["s"], control, dt)
        return state["s"].positions

    rig = Rig(skull=lambda jaw: np.array([jaw[2], 0.0, 0.0]), muscles=lambda c, b, dt: None,
              skin=skin, rest=rest, reset=reset)
    # (the skull stand-in moves the border in-plane by jaw[2] along X: a flat membrane has
    # no linear out-of-plane stiffness, in-plane it converges geometrically)
    # rest is a fixed point
    assert np.allclose(play(rig, np.zeros((5, 1)), np.zeros((5, 3)), fps=25), rest, atol=1e-12)
    # a pure translation of both anchors is followed by the whole sheet once settled
    poses = static_poses(rig, np.zeros((1, 1)), np.array([[0.0, 0.0, 0.1]]), fps=25, settle=100)
    err = np.abs(poses[0] - (rest + [0.1, 0, 0])).max()
    assert err < 1e-3, err


def test_inverted_triangles_counts_flips():
    rest, faces = grid(4)
    flipped = rest * np.array([-1.0, 1.0, 1.0])        # mirrored: every triangle flips
    counts = inverted_triangles(rest, np.stack([rest, flipped, rest + 1.0]), faces)
    assert counts.tolist() == [0, len(faces), 0]


def test_small_triangles_count_and_only_degenerate_ones_are_skipped():
    """A sliver 1e-8 of the others' area that turns over is inverted; a rest
    triangle with (numerically) no area has no normal to turn and is skipped."""
    rest = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0],
                     [0.5, 0.5, 0], [0.5 + 1e-4, 0.5, 0], [0.5, 0.5 + 1e-4, 0],   # sliver
                     [2, 0, 0], [3, 0, 0], [4, 0, 0]])                             # collinear
    faces = np.array([[0, 1, 2], [1, 3, 2], [4, 5, 6], [7, 8, 9]])
    moved = rest.copy()
    moved[6, 1] = 0.5 - 1e-4                    # the sliver turns over
    moved[8, 1] = -1.0                          # the degenerate one gains an area
    flips = inverted_faces(rest, moved[None], faces)
    assert flips.tolist() == [[False, False, True, False]]
    rep = check_animation(rest, np.stack([rest, moved, moved]), faces)
    assert rep.inverted_triangles == 2 and rep.inverted_faces == 1 and rep.inverted_max_per_frame == 1
    assert not rep.ok


def test_folded_edges_are_new_creases_only():
    """A hinge of two triangles folded past 90 degrees is one folded edge; the same fold from a
    hinge already creased 70 degrees at rest is not counted (it was no new crease), nor is a
    rigid motion; check_animation counts distinct folded edges and the most in one frame,
    without failing the animation for them."""
    import math

    from faceforge.animation.checks import folded_edges

    def hinge(deg):   # triangles (0, 1, 2) and (1, 0, 3) on the edge 0-1, each wing lifted deg / 2
        h = math.radians(deg) / 2.0
        return np.array([[0.0, 0, 0], [1, 0, 0], [0.5, math.cos(h), math.sin(h)],
                         [0.5, -math.cos(h), math.sin(h)]])

    faces = np.array([[0, 1, 2], [1, 0, 3]])
    flat, bent, folded = hinge(0.0), hinge(70.0), hinge(120.0)
    turned = flat @ np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]]).T + 3.0     # rigid
    assert folded_edges(flat, np.stack([flat, bent, folded, turned]), faces)[:, 0].tolist() == \
        [False, False, True, False]
    assert not folded_edges(bent, folded[None], faces).any()        # creased 70 at rest already
    # the hinge in a larger still mesh (a far vertex of no triangle): alone, its wings moved 0.87
    # of a 2.2 diagonal, which the checks take for a thrown vertex (checks.THROWN)
    far = np.array([[10.0, 0.0, 0.0]])
    rep = check_animation(np.vstack([flat, far]), np.stack([np.vstack([p, far]) for p in (flat, folded, folded)]), faces)
    assert rep.inverted_triangles == 0                              # each wing turned 60 degrees
    assert rep.folded_edges == 1 and rep.folded_max_per_frame == 1 and rep.ok


def test_points_inside_box_and_check_animation():
    bv, bf = box()
    pts = np.array([[0.0, 0.0, 0.0], [0.2, 0.1, -0.3], [0.9, 0.0, 0.0], [0.0, 0.0, 0.51]])
    assert points_inside(pts, bv, bf).tolist() == [True, True, False, False]

    rest, faces = grid(4)
    rest = 0.8 * rest + np.array([-0.4, -0.4, 0.8])      # a sheet in front of the box
    frames = np.stack([rest, rest - [0, 0, 0.6], rest])  # frame 1 pushes it into the box
    rep = check_animation(rest, frames, faces, skull=lambda i: [(bv, bf)])
    assert rep.non_finite == 0 and rep.inverted_triangles == 0
    assert rep.skin_inside_skull == len(rest) and rep.worst_frame == 1 and not rep.ok
    ok = check_animation(rest, np.stack([rest, rest + [0, 0, 0.2]]), faces, skull=lambda i: [(bv, bf)])
    assert ok.ok
    # the rest's inside vertices given by the caller (a bake checks 40 shapes against one rest):
    # the same count; vertices said to be inside at rest are not counted again
    assert inside_bones(rest, [(bv, bf)]).sum() == 0
    given = check_animation(rest, frames, faces, skull=lambda i: [(bv, bf)], inside_at_rest=inside_bones(rest, []))
    assert given.skin_inside_skull == rep.skin_inside_skull
    assert check_animation(rest, frames, faces, skull=lambda i: [(bv, bf)],
                           inside_at_rest=np.ones(len(rest), bool)).skin_inside_skull == 0


def test_contact_sheet_writes_a_png_with_the_chosen_frames(tmp_path):
    import matplotlib.image as mpimg

    from faceforge.viz.contact_sheet import contact_sheet, pick_frames

    assert pick_frames(100, 5) == [0, 25, 50, 74, 99]
    assert pick_frames(10, spec="0,-1,3") == [0, 9, 3]
    with pytest.raises(ValueError, match=r"\[12\]"):
        pick_frames(10, spec="1,12")
    rest, faces = grid(4)
    frames = np.stack([rest + [0, 0.1 * k, 0] for k in range(4)])
    png = contact_sheet(tmp_path / "s.png", frames, faces, [0, 3], fps=25, title="t")
    img = mpimg.imread(png)
    assert img.shape[1] > img.shape[0] > 50          # two panels side by side
    assert img[..., :3].std() > 0.01                 # something was drawn


def test_fdp_vertices_pick_the_lip_copy_of_their_side():
    from faceforge.animation.rig import fdp_vertices, lever_arm

    rest = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0, 1.0, 1.0], [0.0, -1.0, 1.0]])
    sides = np.array([1, -1, 1, -1], dtype=np.int8)      # 0/1: a cut ring's upper/lower copies
    lm = {"2.2": rest[0], "2.3": rest[0], "8.1": rest[2] + 0.01, "2.1": rest[3]}
    got = fdp_vertices(lm, rest, sides)
    assert got == {"2.2": 0, "2.3": 1, "8.1": 2, "2.1": 3}
    assert fdp_vertices(lm, rest, None)["2.3"] == 0      # no lip sides: plain nearest
    assert lever_arm(np.array([0.0, -3.0, 4.0]), np.zeros(3), np.array([2.0, 0.0, 0.0])) == pytest.approx(5.0)


def test_skull_guard_keeps_skin_outside_a_moving_bone():
    from faceforge.animation.guards.skull import SkullGuard

    bv, bf = box()                                          # unit cube at the origin
    rest = np.array([[0.0, 0.0, 0.6], [0.2, 0.1, 0.7], [0.0, 0.0, 3.0], [0.0, 0.0, 0.0]])
    guard = SkullGuard(rest, {"bone": (bv, bf)}, reach=0.5, keep=0.5)
    assert guard.vertex.tolist() == [0, 1]                  # near and outside; far and inside skipped
    pos = rest + np.array([0.0, 0.0, -0.3])                 # pulled toward (and into) the bone
    moved = guard.apply(pos, {"bone": bv})
    assert moved == 2
    assert np.allclose(pos[:2, 2], [0.55, 0.6])             # at half their rest depth (0.1, 0.2)
    assert np.allclose(pos[2:], rest[2:] - [0, 0, 0.3])     # unguarded vertices untouched
    # the bone moves forward: the floor moves with it; a vertex above its floor stays put
    pos = rest.copy()
    assert guard.apply(pos, {"bone": bv + [0.0, 0.0, 0.15]}) == 2
    assert np.allclose(pos[:2, 2], [0.7, 0.75])
    pos = rest.copy()
    assert guard.apply(pos, {"bone": bv}) == 0 and np.array_equal(pos, rest)


def test_inside_check_tolerance_ignores_grazing_contact():
    bv, bf = box()
    rest, faces = grid(4)
    rest = 0.8 * rest + np.array([-0.4, -0.4, 0.8])
    grazing = np.stack([rest, rest - [0, 0, 0.3 + 0.0005]])      # 0.5e-3 below the top face
    deep = np.stack([rest, rest - [0, 0, 0.35]])
    skull = lambda i: [(bv, bf)]                                     # noqa: E731
    assert check_animation(rest, grazing, faces, skull=skull, tolerance=1e-3).skin_inside_skull == 0
    assert check_animation(rest, grazing, faces, skull=skull, tolerance=0.0).skin_inside_skull == len(rest)
    assert check_animation(rest, deep, faces, skull=skull, tolerance=1e-3).skin_inside_skull == len(rest)


def test_contact_sheet_focus_zooms_on_what_moves(tmp_path):
    import matplotlib.image as mpimg

    from faceforge.viz.contact_sheet import contact_sheet

    rest, faces = grid(8)
    moved = rest.copy()
    moved[[27, 28, 35, 36], 2] += 0.05                     # only a patch in the middle moves
    frames = np.stack([rest, moved])
    whole = mpimg.imread(contact_sheet(tmp_path / "a.png", frames, faces, [0, 1], fps=25))
    zoom = mpimg.imread(contact_sheet(tmp_path / "b.png", frames, faces, [0, 1], fps=25, focus=True))
    assert whole.shape == zoom.shape
    # zoomed in, the sheet's triangles cover more of the panel (fewer background pixels)
    bg = lambda img: np.mean(np.all(img[..., :3] > 0.99, axis=-1))   # noqa: E731
    assert bg(zoom) < bg(whole)


def _skull_guard_twin(guard, positions, bodies_now):
    """Plain numpy twin of the compiled SkullGuard.apply (the algorithm as first written)."""
    s = np.empty((len(guard.vertex), 3))
    nrm = np.empty((len(guard.vertex), 3))
    for b, name in enumerate(guard.names):
        sel = guard.body == b
        if not sel.any():
            continue
        tri = np.asarray(bodies_now[name], dtype=float)[guard.faces[b][guard.face[sel]]]
        s[sel] = np.einsum("ij,ijk->ik", guard.bary[sel], tri)
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        nrm[sel] = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    p = positions[guard.vertex]
    depth = np.einsum("ij,ij->i", p - s, nrm)
    low = depth < guard.floor
    positions[guard.vertex[low]] = p[low] + (guard.floor[low] - depth[low])[:, None] * nrm[low]
    return int(np.count_nonzero(low))


def test_compiled_skull_guard_matches_its_twin_on_two_moving_bones():
    from faceforge.animation.guards.skull import SkullGuard

    bv, bf = box()
    rng = np.random.default_rng(5)
    # skin points near a cube (the cranium) and near a second, offset cube (the mandible)
    rest = np.vstack([rng.uniform(-0.7, 0.7, (300, 3)), rng.uniform(-0.7, 0.7, (300, 3)) + [0.0, -2.0, 0.0]])
    bodies = {"cranium": (bv, bf), "mandible": (bv + [0.0, -2.0, 0.0], bf)}
    guard = SkullGuard(rest, bodies, reach=0.3, keep=0.5)
    assert set(guard.body.tolist()) == {0, 1} and len(guard.vertex) > 100
    for step in range(3):
        now = {"cranium": bv + rng.normal(scale=0.02, size=bv.shape),
               "mandible": bv + [0.0, -2.0, 0.05 * step] + rng.normal(scale=0.02, size=bv.shape)}
        pulled = rest + rng.normal(scale=0.1, size=rest.shape)
        a, b = pulled.copy(), pulled.copy()
        moved = guard.apply(a, now)
        assert moved == _skull_guard_twin(guard, b, now) and moved > 0
        assert np.allclose(a, b, rtol=0.0, atol=1e-12)
        # the moved vertices come out in the guard's order, the others kept their positions
        ids = np.full(len(guard.vertex), -1, dtype=np.int64)
        c = pulled.copy()
        bones = np.ascontiguousarray(np.vstack([now[n] for n in guard.names]))
        assert guard.apply_stacked(c, bones, ids) == moved
        changed = np.flatnonzero(np.any(c != pulled, axis=1))
        assert ids[:moved].tolist() == changed.tolist() and np.all(ids[moved:] == -1)
        # after a pass, move a few vertices: a pass over just those and the pushed ones (the
        # others were left above their floor) is a full pass, bit for bit
        some = rng.choice(len(rest), 40)
        c[some] += rng.normal(scale=0.1, size=(40, 3))
        full = c.copy()
        k_full = guard.apply_stacked(full, bones)
        k_only = guard.apply_stacked(c, bones, ids, np.concatenate([some, ids[:moved], [0, 0]]))
        assert k_only == k_full > 0 and np.array_equal(c, full)
        assert not guard._mark.any()
