"""pbd.triangle_contact: the one-sided point-vs-triangle contact and its plain-numpy twin."""

import numpy as np
import pytest

from faceforge.pbd.triangle_contact import TriangleContact, signed_depths


def _twin_sheet(p, x, cand, tris, margin):
    """(row, d, bary (3,), unit normal) of the candidate nearest along its normal whose plane holds
    ``p[x]``'s projection inside (barycentrics >= -margin), or None."""
    best = None
    for j in cand:
        a, b, c = p[tris[j]]
        n = np.cross(b - a, c - a)
        # barycentrics of x's projection, by least squares on the two edges
        uv = np.linalg.lstsq(np.stack([b - a, c - a], 1), p[x] - a, rcond=None)[0]
        bary = np.array([1 - uv.sum(), uv[0], uv[1]])
        if (bary < -margin).any():
            continue
        d = np.dot(p[x] - a, n) / np.linalg.norm(n)
        if best is None or abs(d) < abs(best[1]):
            best = (j, d, bary, n / np.linalg.norm(n))
    return best


def twin_contact(p, points, cands, tris, floor, reach, margin=0.0, w=None, sweeps=2, prev=None, lost=0.0):
    """Plain numpy: per point, the candidate whose plane holds its projection inside (barycentrics
    >= -margin) nearest along its normal; behind it past the floor (and within reach), the point and
    the triangle's vertices move along the normal, weighted by w and the (clamped) barycentrics.
    With ``prev``: a point behind past floor - lost in ``prev`` is left, and when the sheet came on
    more than ``lost`` the push is scaled by the point's share of the approach along the normal."""
    p = np.array(p, dtype=float)
    w = np.ones(len(p)) if w is None else np.asarray(w, float)
    floor = np.broadcast_to(np.asarray(floor, float), (len(points),))
    for _ in range(sweeps):
        moved = 0
        for i, x in enumerate(points):
            best = _twin_sheet(p, x, cands[i], tris, margin)
            if best is None:
                continue
            j, d, bary, n = best
            if d >= floor[i] or d < floor[i] - reach:
                continue
            if prev is not None:
                before = _twin_sheet(prev, x, cands[i], tris, margin)
                if before is not None and before[1] < floor[i] - lost:
                    continue
            bary = np.maximum(bary, 0)
            bary /= bary.sum()
            ids = tris[j]
            den = w[x] + np.sum(bary ** 2 * w[ids])
            if den <= 0:
                continue
            share = 1.0
            if prev is not None:
                mine = max(0.0, -np.dot(p[x] - prev[x], n))
                theirs = max(0.0, np.dot(bary @ (p[ids] - prev[ids]), n))
                share = mine / (mine + theirs) if theirs > lost else 1.0
                if share <= 0:
                    continue
            lam = share * (floor[i] - d) / den
            p[x] += w[x] * lam * n
            for k, b in zip(ids, bary):
                p[k] -= b * w[k] * lam * n
            moved += 1
        if not moved:
            break
    return p


def _sheet_and_points(rng, m=12):
    """A bumpy 3 x 3 sheet (8 triangles, front +z) and ``m`` points scattered about it."""
    gx, gy = np.meshgrid(np.arange(3.0), np.arange(3.0))
    sheet = np.c_[gx.ravel(), gy.ravel(), 0.1 * rng.standard_normal(9)]
    tris = []
    for r in range(2):
        for c in range(2):
            a = 3 * r + c
            tris += [[a, a + 1, a + 4], [a, a + 4, a + 3]]
    pts = np.c_[rng.uniform(0, 2, m), rng.uniform(0, 2, m), rng.uniform(-0.4, 0.3, m)]
    return np.r_[sheet, pts], np.array(tris), 9 + np.arange(m)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_kernel_matches_its_plain_twin(seed):
    rng = np.random.default_rng(seed)
    p, tris, pts = _sheet_and_points(rng)
    cands = [np.arange(len(tris))] * len(pts)
    w = rng.uniform(0.0, 1.0, len(p))
    floor = -rng.uniform(0, 0.05, len(pts))
    want = twin_contact(p, pts, cands, tris, floor, reach=0.35, margin=0.01, w=w, sweeps=3)
    got = p.copy()
    TriangleContact(pts, cands, tris, len(p), floor=floor, reach=0.35, margin=0.01, inv_mass=w)(got, sweeps=3)
    assert np.allclose(got, want, atol=1e-12)
    assert not np.allclose(got, p)   # some point was behind


def test_a_point_behind_meets_the_triangle_at_its_floor_and_one_in_front_stays():
    p = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0.25, 0.25, -0.2], [0.25, 0.5, 0.1], [2.0, 2.0, -0.1]], float)
    contact = TriangleContact([3, 4, 5], [[0], [0], [0]], [[0, 1, 2]], len(p), reach=1.0)
    before = p.copy()
    touched = np.zeros(len(p), bool)
    assert contact(p, sweeps=4, touched=touched) >= 1
    d = contact.depths(p)
    assert d[0] >= -1e-12                       # it may touch, not cross
    assert np.array_equal(p[4], before[4])      # in front: untouched
    assert np.array_equal(p[5], before[5])      # beside the triangle: no sheet
    assert np.isnan(d[2])
    assert touched[[0, 1, 2, 3]].all() and not touched[[4, 5]].any()
    # momentum kept: the point and the sheet's vertices moved by equal and opposite amounts
    assert np.allclose((p - before).sum(axis=0), 0.0, atol=1e-12)


def test_a_pinned_sheet_does_not_move_and_a_point_past_reach_is_left():
    p = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0.2, 0.2, -0.3], [0.3, 0.3, -2.0]], float)
    w = np.array([0, 0, 0, 1, 1], float)
    q = p.copy()
    TriangleContact([3, 4], [[0], [0]], [[0, 1, 2]], len(p), reach=1.0, inv_mass=w)(q)
    assert np.array_equal(q[:3], p[:3])
    assert q[3, 2] == pytest.approx(0.0, abs=1e-12)
    assert np.array_equal(q[4], p[4])


def test_the_floor_lets_a_point_stay_as_deep_as_it_was_and_no_deeper():
    p = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0.2, 0.2, -0.3]], float)
    w = np.array([0, 0, 0, 1], float)
    q = p.copy()
    c = TriangleContact([3], [[0]], [[0, 1, 2]], len(p), floor=-0.1, reach=1.0, inv_mass=w)
    c(q)
    assert q[3, 2] == pytest.approx(-0.1)
    assert signed_depths(q, c.points, c.start, c.cand, c.tris)[0] == pytest.approx(-0.1)
    with pytest.raises(ValueError):
        TriangleContact([3], [[0]], [[0, 1, 2]], len(p), floor=0.1)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_kernel_matches_its_plain_twin_with_the_steps_history(seed):
    rng = np.random.default_rng(seed + 10)
    p, tris, pts = _sheet_and_points(rng, m=16)
    prev = p + 0.15 * rng.standard_normal(p.shape)   # where everything was at the step's start
    cands = [np.arange(len(tris))] * len(pts)
    w = rng.uniform(0.2, 1.0, len(p))
    floor = -rng.uniform(0, 0.05, len(pts))
    want = twin_contact(p, pts, cands, tris, floor, reach=0.35, margin=0.01, w=w, sweeps=3, prev=prev, lost=0.05)
    got = p.copy()
    c = TriangleContact(pts, cands, tris, len(p), floor=floor, reach=0.35, margin=0.01, inv_mass=w)
    c(got, sweeps=3, previous=np.ascontiguousarray(prev), lost=0.05)
    assert np.allclose(got, want, atol=1e-12)
    assert not np.allclose(got, p)
    # the history changes the answer: without it every point behind is pushed out fully
    assert not np.allclose(got, twin_contact(p, pts, cands, tris, floor, reach=0.35, margin=0.01, w=w, sweeps=3))


def test_with_history_a_sheet_that_moved_through_a_still_point_does_not_drag_it():
    """The lower lip springing back up through the upper lip's vertex (sheet pinned, as the lips'
    contact has it): the vertex stays, not dragged with it; a vertex that moved down through a still sheet is pushed out;
    one already behind at the step's start is left."""
    tri = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    still = np.array([0.25, 0.25, 0.1])
    w = np.array([0, 0, 0, 1, 1, 1], float)
    prev = np.r_[tri - [0, 0, 1.0], [still], [[0.25, 0.5, 0.05]], [[0.5, 0.25, -0.5]]]
    p = np.r_[tri + [0, 0, 0.3], [still], [[0.25, 0.5, 0.05]], [[0.5, 0.25, -0.4]]]
    prev[4, 2] = 1.5   # the second point came down 1.45 onto the sheet as it rose 1.3: 0.25 behind,
    # its share of the approach 1.45 / 2.75
    contact = TriangleContact([3, 4, 5], [[0], [0], [0]], [[0, 1, 2]], len(p), reach=1.0, inv_mass=w)
    q = p.copy()
    contact(q, sweeps=1, previous=np.ascontiguousarray(prev), lost=0.05)   # (each sweep allows as much)
    assert np.array_equal(q[3], p[3])           # the sheet jumped 1.3 onto it: not dragged
    assert q[4, 2] == pytest.approx(0.05 + 0.25 * 1.45 / 2.75)   # pushed out by its share of the crossing
    assert np.array_equal(q[5], p[5])           # behind already at the step's start: left
    r = p.copy()
    contact(r)                                   # no history: every one within reach pushed out
    assert np.allclose(contact.depths(r)[:2], 0.0, atol=1e-12) and r[5, 2] == pytest.approx(0.3)
    with pytest.raises(ValueError):
        contact(p.copy(), previous=np.zeros((2, 3)))


def test_with_history_a_point_behind_at_the_steps_start_is_left_until_it_comes_out():
    p = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0.25, 0.25, -0.2], [0.5, 0.25, -0.02]], float)
    prev = p.copy()
    prev[3, 2], prev[4, 2] = -0.3, 0.1   # the first was behind already, the second crossed in this step
    w = np.array([0, 0, 0, 1, 1], float)
    contact = TriangleContact([3, 4], [[0], [0]], [[0, 1, 2]], len(p), reach=1.0, inv_mass=w)
    q = p.copy()
    contact(q, previous=prev, lost=0.05)
    assert np.array_equal(q[3], p[3])
    assert q[4, 2] == pytest.approx(0.0)
    contact(r := p.copy())
    assert r[3, 2] == pytest.approx(0.0)   # without the history it is pushed out
