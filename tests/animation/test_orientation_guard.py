"""The orientation guard (animation.guards.orientation): skin triangles do not turn over."""

import numpy as np
import pytest

from faceforge.animation.checks import inverted_faces
from faceforge.animation.playback import Rig, play
from faceforge.animation.guards.orientation import OrientationGuard, _project_signed_areas, _watched

from .test_playback import grid


def _twin(x, tris, nref, floor, aim, iterations, hit, w=None, reach=None):
    """Plain-Python twin of the numba kernel (same order, same updates); ``w (n,)`` the vertices'
    inverse masses (None: all 1); ``reach (k,)`` the farthest a projection moves a vertex (None:
    unbounded)."""
    w = np.ones(len(x)) if w is None else w
    reach = np.full(len(tris), np.inf) if reach is None else reach
    moved = 0
    for _ in range(iterations):
        changed = 0
        for t, (a, b, c) in enumerate(tris):
            n = nref[t]
            s = 0.5 * n @ np.cross(x[b] - x[a], x[c] - x[a])
            if s - floor[t] >= 0.0:
                continue
            g = [0.5 * np.cross(n, x[tris[t, (k + 2) % 3]] - x[tris[t, (k + 1) % 3]]) for k in range(3)]
            denom = sum(w[tris[t, k]] * (g[k] @ g[k]) for k in range(3))
            if denom <= 1e-300:
                continue
            lam = -(s - floor[t] - aim * floor[t]) / denom
            step = max(w[tris[t, k]] * abs(lam) * np.linalg.norm(g[k]) for k in range(3))
            if step > reach[t]:
                lam *= reach[t] / step
            for k in range(3):
                if w[tris[t, k]] > 0:
                    x[tris[t, k]] += w[tris[t, k]] * lam * g[k]
            hit[t] = 1
            changed += 1
        moved += changed
        if changed == 0:
            break
    return moved


def _random_triangles(rng):
    """30 random points, 40 random triangles on them with random unit normals and area floors."""
    x = rng.normal(size=(30, 3))
    tris = np.array([rng.choice(30, 3, replace=False) for _ in range(40)], dtype=np.int64)
    n = rng.normal(size=(40, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    floor = rng.uniform(0.0, 0.3, 40)
    return x, tris, n, floor


def test_kernel_matches_its_python_twin():
    rng = np.random.default_rng(3)
    x, tris, n, floor = _random_triangles(rng)
    a, b = x.copy(), x.copy()
    ha, hb = np.zeros(40, np.uint8), np.zeros(40, np.uint8)
    ka = _project_signed_areas(a, tris, n, floor, 0.25, 7, ha, np.ones(30), np.full(40, np.inf))
    kb = _twin(b, tris, n, floor, 0.25, 7, hb)
    assert ka == kb > 0
    assert np.allclose(a, b, rtol=0, atol=1e-12)
    assert ha.tolist() == hb.tolist() and 0 < ha.sum() < 40
    # the triangles not projected moved none of their vertices (unless they share one)
    free = np.setdiff1d(np.arange(30), tris[ha.astype(bool)])
    assert len(free) and np.array_equal(a[free], x[free])


def test_weighted_kernel_matches_its_python_twin_and_keeps_pinned_vertices():
    """Inverse masses: a pinned vertex (w 0) never moves, the others move w-weighted; equal
    masses of 1 are the unweighted pass bit for bit."""
    rng = np.random.default_rng(4)
    x, tris, n, floor = _random_triangles(rng)
    w = rng.uniform(0.2, 2.0, 30)
    pinned = np.unique(tris[:6].ravel())
    w[pinned] = 0.0
    a, b = x.copy(), x.copy()
    ha, hb = np.zeros(40, np.uint8), np.zeros(40, np.uint8)
    ka = _project_signed_areas(a, tris, n, floor, 0.25, 7, ha, w, np.full(40, np.inf))
    kb = _twin(b, tris, n, floor, 0.25, 7, hb, w)
    assert ka == kb > 0
    assert np.allclose(a, b, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(a[pinned], x[pinned])
    assert not np.array_equal(a, x)
    c, d = x.copy(), x.copy()
    _project_signed_areas(c, tris, n, floor, 0.25, 7, np.zeros(40, np.uint8), np.ones(30), np.full(40, np.inf))
    _twin(d, tris, n, floor, 0.25, 7, np.zeros(40, np.uint8))
    assert np.allclose(c, d, rtol=0, atol=1e-12)


def test_a_projection_moves_no_vertex_farther_than_its_reach():
    """A triangle seen nearly edge-on along its rest normal has gradients near 0: the linearised
    step threw a vertex across the face (MakeHuman's pride.fap on a levelled risorius: a lid-corner
    vertex 6 units, frame 45). With ``reach`` no vertex moves farther than it in one projection,
    the twin agrees, and an unbounded reach is the old step."""
    x = np.array([[0.0, 0.0, 0.0], [1e-3, 0.0, 1.0], [0.0, 1e-3, -1.0]])   # nearly edge-on along +z
    tris = np.array([[0, 1, 2]], dtype=np.int64)
    n = np.array([[0.0, 0.0, 1.0]])
    floor = np.array([0.1])
    free = x.copy()
    _project_signed_areas(free, tris, n, floor, 0.25, 1, np.zeros(1, np.uint8), np.ones(3), np.full(1, np.inf))
    assert np.abs(free - x).max() > 50.0                                   # thrown
    a, b = x.copy(), x.copy()
    _project_signed_areas(a, tris, n, floor, 0.25, 1, np.zeros(1, np.uint8), np.ones(3), np.array([0.5]))
    _twin(b, tris, n, floor, 0.25, 1, np.zeros(1, np.uint8), reach=np.array([0.5]))
    assert np.linalg.norm(a - x, axis=1).max() == pytest.approx(0.5)
    assert np.allclose(a, b, rtol=0, atol=1e-12)


@pytest.mark.parametrize("watch_angle, min_area", [(60.0, 0.2), (30.0, 0.0), (120.0, 0.0), (90.0, 0.1)])
def test_watched_kernel_matches_the_numpy_test(watch_angle, min_area):
    # the kernel compares squares (no square root), both signs of cos(watch_angle)
    rng = np.random.default_rng(5)
    rest, faces = grid(7)
    guard = OrientationGuard(rest, faces, min_area=min_area, watch_angle=watch_angle)
    for scale in (0.02, 0.1, 0.3, 0.6):
        pos = np.ascontiguousarray(rest + rng.normal(scale=scale, size=rest.shape))
        rows = _watched(pos, guard.faces, guard.normal0, guard.floor, guard.cos_watch, guard.active)
        assert rows.tolist() == np.flatnonzero(guard.watched(pos)).tolist()


def test_rescan_around_moved_vertices_gives_the_full_scan():
    rng = np.random.default_rng(8)
    rest, faces = grid(9)
    guard = OrientationGuard(rest, faces, min_area=0.2)
    for scale in (0.05, 0.2):
        pos = np.ascontiguousarray(rest + rng.normal(scale=scale, size=rest.shape))
        rows = _watched(pos, guard.faces, guard.normal0, guard.floor, guard.cos_watch, guard.active)
        assert 0 < len(rows) < len(faces)
        for count in (0, 1, 5, 40):
            moved = rng.choice(len(rest), count)                 # repeats allowed
            after = pos.copy()
            after[moved] += rng.normal(scale=0.3, size=(count, 3))
            again = guard._rewatched(after, rows, moved)
            assert again.tolist() == np.flatnonzero(guard.watched(after)).tolist()
            assert not guard._mark.any()                         # the scratch is left clean


def test_apply_after_moved_vertices_is_apply_from_scratch():
    """``apply(x, moved)`` on the array the last apply left, changed only at ``moved``, does
    exactly what a full apply does (the skin step's skull-guard rounds)."""
    rng = np.random.default_rng(9)
    rest, faces = grid(9)
    for trial in range(6):
        guard = OrientationGuard(rest, faces, min_area=0.2, rounds=2 + trial % 3)
        pos = np.ascontiguousarray(rest + rng.normal(scale=0.15, size=rest.shape))
        guard.apply(pos)
        moved = rng.choice(len(rest), 4, replace=False)
        pos[moved] += rng.normal(scale=0.3, size=(4, 3))
        fresh = OrientationGuard(rest, faces, min_area=0.2, rounds=guard.rounds)
        ref = pos.copy()
        assert guard.apply(pos, moved) == fresh.apply(ref)
        assert np.array_equal(pos, ref)
    # what the last apply may have moved: every other vertex kept its bits
    pos[moved] += rng.normal(scale=0.3, size=(4, 3))
    before = pos.copy()
    assert guard.apply(pos, moved) > 0
    still = np.setdiff1d(np.arange(len(rest)), guard.touched)
    assert len(still) and np.array_equal(pos[still], before[still])
    assert np.any(pos[guard.touched] != before[guard.touched])
    # another array, or no last verdict: a full test
    other = np.ascontiguousarray(rest + rng.normal(scale=0.15, size=rest.shape))
    ref = other.copy()
    assert guard.apply(other, np.zeros(0, np.int64)) == OrientationGuard(
        rest, faces, min_area=0.2, rounds=guard.rounds).apply(ref)
    assert np.array_equal(other, ref)


def test_a_folded_sheet_is_unfolded_and_the_rest_of_it_left_alone():
    rest, faces = grid(6)
    guard = OrientationGuard(rest, faces, min_area=0.1)
    pos = rest.copy()
    pos[14] += [0.5, 0.0, 0.0]                       # an inner vertex dragged across two neighbours
    before = inverted_faces(rest, pos[None], faces)[0]
    assert before.any()
    moved = guard.apply(pos)
    assert moved > 0
    assert not inverted_faces(rest, pos[None], faces)[0].any()
    t = pos[faces]
    signed = 0.5 * np.einsum("ij,ij->i", np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), guard.normal0)
    assert np.all(signed >= guard.floor * (1 - 1e-9))
    # only the fold moves: vertices away from it keep their positions exactly
    far = np.linalg.norm(rest - rest[14], axis=1) > 0.45
    assert np.array_equal(pos[far], rest[far])


def test_rest_and_moderate_rotations_are_fixed_points():
    rest, faces = grid(5)
    guard = OrientationGuard(rest, faces)
    pos = rest.copy()
    assert guard.apply(pos) == 0 and np.array_equal(pos, rest)
    a = np.radians(50.0)                              # below the 60-degree watch angle
    rot = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    turned = np.ascontiguousarray(rest @ rot.T + [0.3, -0.2, 0.1])
    copy = turned.copy()
    assert guard.apply(turned) == 0 and np.array_equal(turned, copy)
    # a stretched (not turned) sheet is above the floor: left alone too
    stretched = np.ascontiguousarray(rest * [2.0, 0.5, 1.0])
    assert guard.apply(stretched.copy()) == 0


def test_degenerate_rest_triangles_and_bad_arrays():
    rest = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0]])
    faces = np.array([[0, 1, 2], [0, 1, 3]])         # the first has no area, no orientation
    guard = OrientationGuard(rest, faces)
    assert guard.active.tolist() == [False, True]
    with pytest.raises(ValueError):
        guard.apply(rest.astype(np.float32))
    with pytest.raises(ValueError):
        OrientationGuard(rest, faces, min_area=1.0)


def test_play_applies_the_rigs_finish_to_the_weighted_frames():
    rest, faces = grid(6)
    guard = OrientationGuard(rest, faces)
    flipped = rest.copy()
    flipped[14] += [0.5, 0.0, 0.0]                    # folds the triangles around vertex 14

    def skin(bones, muscles, dt):
        return flipped

    rig = Rig(skull=lambda jaw: None, muscles=lambda c, b, dt: None, skin=skin, rest=rest,
              influence=np.ones(len(rest)))
    raw = play(rig, np.zeros((1, 0)), np.zeros((1, 3)), fps=25)
    assert inverted_faces(rest, raw, faces).any()
    rig.finish = guard.apply
    out = play(rig, np.zeros((1, 0)), np.zeros((1, 3)), fps=25)
    assert not inverted_faces(rest, out, faces).any()


def test_config_turns_the_guard_off_with_zero_rounds():
    from faceforge.exceptions import ConfigError
    from faceforge.io.config import load_config

    assert load_config().get("animate.orientation_guard.rounds") >= 1
    assert load_config(sets=["animate.orientation_guard.rounds=0"]).get("animate.orientation_guard.rounds") == 0
    with pytest.raises(ConfigError):
        load_config(sets=["animate.orientation_guard.min_area=1.5"])
