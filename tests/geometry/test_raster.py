"""The headless z-buffer (against a plain twin) and its orthographic camera."""

from __future__ import annotations

import numpy as np

from faceforge.geometry.raster import View, rasterise


def _twin_rasterise(screen, faces, size):
    """Plain twin of raster._rasterise: pixel centres inside (inclusive), nearest depth wins."""
    depth = np.full((size, size), np.inf)
    fid = np.full((size, size), -1)
    for t, (a, b, c) in enumerate(faces):
        (x0, y0, z0), (x1, y1, z1), (x2, y2, z2) = screen[a], screen[b], screen[c]
        area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        if area == 0:
            continue
        for r in range(size):
            for col in range(size):
                px, py = col + 0.5, r + 0.5
                w0 = ((x1 - px) * (y2 - py) - (x2 - px) * (y1 - py)) / area
                w1 = ((x2 - px) * (y0 - py) - (x0 - px) * (y2 - py)) / area
                w2 = 1 - w0 - w1
                if min(w0, w1, w2) < 0:
                    continue
                z = w0 * z0 + w1 * z1 + w2 * z2
                if z < depth[r, col]:
                    depth[r, col], fid[r, col] = z, t
    return depth, fid


def _front(size=24, scale=10.0):
    return View(np.array([0.0, 0.0, -1.0]), np.array([0.0, 1.0, 0.0]), np.zeros(3), scale, size)


def test_rasteriser_matches_its_twin_and_keeps_the_nearest_triangle():
    rng = np.random.default_rng(3)
    v = rng.uniform(-1.1, 1.1, (12, 3))
    f = rng.integers(0, 12, (10, 3))
    f = f[(f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])]
    view = _front()
    depth, fid, bary = rasterise(v, f, view)
    d2, f2 = _twin_rasterise(view.project(v), f, view.size)
    assert np.array_equal(fid, f2) and np.allclose(depth[np.isfinite(depth)], d2[np.isfinite(d2)])
    hit = fid >= 0
    assert hit.sum() > 20
    # barycentrics give back the pixel centre: project the surface point, land in the pixel
    p = np.einsum("kj,kjd->kd", bary[hit], v[f[fid[hit]]])
    rows, cols = np.nonzero(hit)
    assert np.allclose(view.project(p)[:, :2], np.column_stack([cols + 0.5, rows + 0.5]), atol=1e-9)


def test_view_unproject_inverts_project():
    view = View(np.array([1.0, 0, 0]), np.array([0, 0, 1.0]), np.array([0.3, -0.2, 0.5]), 37.0, 100)
    p = np.random.default_rng(0).normal(size=(20, 3))
    s = view.project(p)
    assert np.allclose(view.unproject(s[:, :2], s[:, 2]), p)
    assert np.allclose(view.right, np.cross(view.direction, view.up))


def _twin_interpolate(values, faces, face_id, bary):
    """Plain twin of raster._interpolate: a pixel's value is its triangle's corners mixed by its
    barycentric coordinates; 0 where no triangle is."""
    out = np.zeros(face_id.shape + values.shape[1:])
    for r in range(face_id.shape[0]):
        for c in range(face_id.shape[1]):
            t = face_id[r, c]
            if t >= 0:
                out[r, c] = sum(bary[r, c, j] * values[faces[t, j]] for j in range(3))
    return out


def test_interpolation_matches_its_twin():
    from faceforge.geometry.raster import interpolate

    rng = np.random.default_rng(5)
    v = rng.uniform(-1.1, 1.1, (12, 3))
    f = rng.integers(0, 12, (10, 3))
    f = f[(f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])]
    _, fid, bary = rasterise(v, f, _front())
    values = rng.normal(size=(12, 2))
    got = interpolate(values, f, fid, bary)
    assert (fid >= 0).sum() > 20 and np.allclose(got, _twin_interpolate(values, f, fid, bary))
    assert np.all(got[fid < 0] == 0.0)
