"""Action lines (§5.1.1) and their sampling (Eq. 3, Eq. 4)."""

import numpy as np
import pytest
import trimesh

from faceforge.anatomy.muscles.action_line import ActionLine, polyline_parameters, sample_polyline, sample_positions
from faceforge.geometry.surface_points import SurfacePoints

from tests.anatomy.conftest import icosphere, on_sphere


def rotation_x(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def test_action_line_follows_rotating_icosahedron():
    """Fig. 2: the line's points and samples move rigidly with the icosahedron under them."""
    m = trimesh.creation.icosahedron()
    v, f = np.asarray(m.vertices), np.asarray(m.faces, np.int64)
    line = ActionLine(SurfacePoints([0, 3, 7, 11], [[0.2, 0.3, 0.5], [1 / 3] * 3, [0.6, 0.2, 0.2], [0.1, 0.1, 0.8]]))
    p0 = line.positions(v, f)
    s0, n0 = line.sample(v, f, 9)
    for a in np.linspace(0.2, 6.0, 5):
        R = rotation_x(a)
        vr = v @ R.T
        np.testing.assert_allclose(line.positions(vr, f), p0 @ R.T, atol=1e-12)
        s, n = line.sample(vr, f, 9)
        np.testing.assert_allclose(s, s0 @ R.T, atol=1e-12)
        np.testing.assert_allclose(n, n0 @ R.T, atol=1e-12)


def test_sampling_regular_step_and_end_points():
    rng = np.random.default_rng(0)
    pts = np.cumsum(rng.uniform(0.1, 1.0, (7, 3)), axis=0)
    nrm = np.tile([0.0, 0.0, 1.0], (7, 1))
    pos, n, arc = sample_polyline(pts, nrm, 5)
    np.testing.assert_allclose(pos[[0, -1]], pts[[0, -1]], atol=1e-12)  # Eq. 3: corners shared
    np.testing.assert_allclose(np.diff(arc), arc[-1] / 4)
    length = np.linalg.norm(np.diff(pts, axis=0), axis=1).sum()
    assert arc[-1] == pytest.approx(length)
    np.testing.assert_allclose(n, nrm[:5])
    # Eq. 4: step' = step (1 - c): every sample at (1 - c) times its arc length, toward the origin
    c = 0.3
    _, _, arc_c = sample_polyline(pts, nrm, 5, step_scale=1 - c)
    np.testing.assert_allclose(arc_c, (1 - c) * arc)


def test_closed_sampling_step_and_segment_parameters():
    ang = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    circle = np.stack([np.cos(ang), np.sin(ang), np.zeros(40)], 1)
    pos, _, arc = sample_polyline(circle, None, 8, closed=True)
    perimeter = 40 * 2 * np.sin(np.pi / 40)
    np.testing.assert_allclose(np.diff(arc), perimeter / 8)
    # samples fall on every fifth vertex (a segment end, t = 0 or 1 up to round-off)
    np.testing.assert_allclose(pos, circle[::5], atol=1e-12)
    k, t, _ = polyline_parameters(circle, 8, closed=True)
    closed_pts = np.vstack([circle, circle[:1]])
    np.testing.assert_allclose((1 - t)[:, None] * closed_pts[k] + t[:, None] * closed_pts[k + 1], pos)


def test_from_points_hugs_the_surface():
    v, f = icosphere(3)
    a, b = on_sphere((-0.6, 0.2), (0.6, -0.1))
    line = ActionLine.from_points([a, b], v, f)
    p = line.positions(v, f)
    # the straight chord a-b dips 0.1 below the sphere; the projected line stays on the mesh
    assert len(line) > 5
    r = np.linalg.norm(p, axis=1)
    assert np.all(r > 0.98) and np.all(r <= 1 + 1e-9)
    # end points are the projections of the given points
    np.testing.assert_allclose(p[[0, -1]], [a, b], atol=0.02)
    # the line is at least as long as the chord and close to the great-circle arc
    arc = np.arccos(a @ b)
    assert np.linalg.norm(a - b) < line.length(v, f) < arc * 1.02


def test_sample_normals_are_unit_and_outward():
    v, f = icosphere(3)
    line = ActionLine.from_points(on_sphere((-0.3, 0.3), (0.3, 0.3), (0.3, -0.3)), v, f)
    s, n = line.sample(v, f, 11)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1)
    assert np.min(np.einsum("ij,ij->i", n, s / np.linalg.norm(s, axis=1, keepdims=True))) > 0.99


def test_rejects_degenerate_requests():
    v, f = icosphere(1)
    with pytest.raises(ValueError):
        ActionLine.from_points(on_sphere((0, 0)), v, f)
    with pytest.raises(ValueError):
        sample_polyline(np.eye(3), None, 1)
    with pytest.raises(ValueError):
        ActionLine.from_points(on_sphere((0, 0), (0.1, 0)), v, f, project="sideways")


def twin_sample_positions(points, n, closed, scale):
    """Plain-Python twin of the compiled ``_polyline_samples``: walk the segments."""
    pts = [np.asarray(p, float) for p in points]
    if closed:
        pts.append(pts[0])
    lengths = [float(np.linalg.norm(b - a)) for a, b in zip(pts[:-1], pts[1:])]
    total = sum(lengths)
    step = total / (n if closed else n - 1)
    out = []
    for s in range(n):
        arc = min(max(s * step * scale, 0.0), total)
        cum = 0.0
        for k, seg in enumerate(lengths):
            if arc <= cum + seg or k == len(lengths) - 1:
                break
            cum += seg
        t = 0.0 if seg == 0 else min(max((arc - cum) / seg, 0.0), 1.0)
        out.append((1 - t) * pts[k] + t * pts[k + 1])
    return np.array(out)


@pytest.mark.parametrize("closed", [False, True])
@pytest.mark.parametrize("scale", [0.0, 0.35, 1.0])
def test_compiled_sampling_matches_twin_and_reference(closed, scale):
    rng = np.random.default_rng(11)
    for trial in range(5):
        pts = rng.normal(size=(rng.integers(2 if not closed else 3, 9), 3))
        if trial == 0:
            pts = np.vstack([pts[:1], pts[:1], pts[1:]])  # a zero-length segment
        for n in (3, 7):
            fast = sample_positions(pts, n, closed, scale)
            np.testing.assert_allclose(fast, twin_sample_positions(pts, n, closed, scale), atol=1e-12)
            np.testing.assert_allclose(fast, sample_polyline(pts, None, n, closed, scale)[0], atol=1e-12)


def test_outermost_projection_lands_on_the_top_of_a_deeper_muscle():
    """A point drawn on the skull under a deeper muscle: "closest" may pick the skull or the
    muscle's bottom (they touch); "outermost" picks the muscle's top sheet, normal outward."""
    from faceforge.anatomy.layers import underlying_mesh

    from tests.anatomy.conftest import linear_on, split_skull

    cranium, mandible = split_skull(3)
    from faceforge.geometry.triangles import concatenate_meshes

    sv, sf, _ = concatenate_meshes([cranium, mandible])
    deep = linear_on("deep", sv, sf, [(-0.3, 0.6), (0.3, 0.6)], [(-0.3, 0.1), (0.3, 0.1)], thickness=0.08)
    v, f = underlying_mesh(("skull", "deep"), cranium, mandible, [deep])
    pts = on_sphere((-0.1, 0.45), (0.0, 0.35), (0.1, 0.25))
    top = ActionLine.from_points(pts, v, f, project="outermost")
    p, n = top.positions(v, f), top.normals(v, f)
    r = np.linalg.norm(p, axis=1)
    assert np.all(r > 1.06) and np.all(r < 1.081)  # the top sheet (chords of the coarse grid sag)
    assert np.all(np.einsum("ij,ij->i", n, p / r[:, None]) > 0.9)
    low = ActionLine.from_points(pts, v, f, project="closest").positions(v, f)
    assert np.all(np.abs(np.linalg.norm(low, axis=1) - 1.0) < 0.01)
