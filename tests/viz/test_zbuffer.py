"""The sheets' z-buffer drawing: the nearest surface at each pixel, values interpolated across
triangles, light in range."""

from __future__ import annotations

import numpy as np

from faceforge.viz.zbuffer import interpolate, lit, panel_buffers


def _grid(n=9, z=lambda x, y: 0.0 * x):
    g = np.linspace(-1.0, 1.0, n)
    x, y = np.meshgrid(g, g)
    v = np.stack([x.ravel(), y.ravel(), z(x.ravel(), y.ravel())], axis=1)
    f = [[i * n + j, i * n + j + 1, i * n + j + n + 1] for i in range(n - 1) for j in range(n - 1)]
    f += [[i * n + j, i * n + j + n + 1, i * n + j + n] for i in range(n - 1) for j in range(n - 1)]
    return v, np.asarray(f)


def test_a_linear_field_is_interpolated_exactly_at_each_pixels_surface_point():
    v, f = _grid(z=lambda x, y: 0.2 * x - 0.1 * y)
    face_id, bary, extent = panel_buffers(v, f, ((-1.0, -1.0), (1.0, 1.0)), 40)
    assert extent == (-1.0, 1.0, -1.0, 1.0) and (face_id >= 0).mean() > 0.9
    field = v @ np.array([1.0, 2.0, -3.0]) + 0.5
    got = interpolate(field[:, None], f, face_id, bary)[:, :, 0]
    point = interpolate(v, f, face_id, bary)                 # the surface point under each pixel
    hit = face_id >= 0
    assert np.allclose(got[hit], point[hit] @ np.array([1.0, 2.0, -3.0]) + 0.5)
    cols, rows = np.meshgrid(np.arange(40) + 0.5, np.arange(40) + 0.5)
    assert np.allclose(point[hit][:, 0], (-1.0 + cols / 20.0)[hit])      # the pixel's centre, x
    assert np.allclose(point[hit][:, 1], (1.0 - rows / 20.0)[hit])       # rows grow downwards


def test_the_nearest_surface_shows_where_painting_by_centroid_gets_it_wrong():
    """Two touching sheets, as pressed lips: a long triangle leaning back (its centroid in front)
    and a small one just in front of it at the seam (its centroid behind the long one's). Painted
    back to front by centroid the long triangle covers the small one; the z-buffer shows the
    small one where it is nearer."""
    v = np.array([[-1.0, -0.2, 0.0], [1.0, -0.2, 0.0], [0.0, 1.0, 1.2],      # long, leaning toward the viewer
                  [-0.2, -0.1, 0.3], [0.2, -0.1, 0.3], [0.0, 0.1, 0.3]])      # small, at the seam
    f = np.array([[0, 1, 2], [3, 4, 5]])
    assert v[f[1]].mean(axis=0)[2] < v[f[0]].mean(axis=0)[2]                  # painting would draw it first
    face_id, bary, _ = panel_buffers(v, f, ((-1.0, -1.0), (1.0, 1.0)), 64)
    col, row = 32, int((1.0 - (-0.05)) * 32)                                  # x = 0, y = -0.05: inside both
    assert face_id[row, col] == 1
    tag = interpolate(np.array([[0.0], [0.0], [0.0], [1.0], [1.0], [1.0]]), f, face_id, bary)[:, :, 0]
    assert tag[row, col] == 1.0 and (tag[face_id == 0] == 0.0).all()


def test_light_is_in_range_two_sided_and_varies_over_a_dome():
    v, f = _grid(17, z=lambda x, y: 0.6 * (1.0 - x ** 2 - y ** 2))
    face_id, bary, _ = panel_buffers(v, f, ((-1.0, -1.0), (1.0, 1.0)), 48)
    light_dir = np.array([0.0, 0.0, 1.0])
    front = lit(v, f, face_id, bary, light_dir, 0.3)
    hit = face_id >= 0
    assert front[hit].min() >= 0.3 - 1e-12 and front[hit].max() <= 1.0 + 1e-12
    assert np.ptp(front[hit]) > 0.2 and front[24, 24] > 0.99                  # brightest facing the light
    inside_out = f[:, ::-1]
    fid, b, _ = panel_buffers(v, inside_out, ((-1.0, -1.0), (1.0, 1.0)), 48)
    assert np.allclose(lit(v, inside_out, fid, b, light_dir, 0.3)[hit], front[hit])   # two-sided
