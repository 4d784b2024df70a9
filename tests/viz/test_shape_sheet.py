"""The bake's smooth-shaded sheet."""

from __future__ import annotations

import numpy as np

from faceforge.viz.shape_sheet import shape_sheet


def _sphere(n=12):
    th, ph = np.meshgrid(np.linspace(0.1, np.pi - 0.1, n), np.linspace(0, 2 * np.pi, 2 * n, endpoint=False))
    v = np.stack([np.sin(th) * np.cos(ph), np.cos(th), np.sin(th) * np.sin(ph)], -1).reshape(-1, 3)
    from scipy.spatial import ConvexHull

    f = ConvexHull(v).simplices
    # outward orientation
    c = v[f].mean(axis=1)
    nrm = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    flip = (nrm * c).sum(axis=1) < 0
    f[flip] = f[flip][:, ::-1]
    return v, f


def test_sheet_is_written(tmp_path):
    v, f = _sphere()
    frames = np.stack([v, v * 1.1])
    out = shape_sheet(tmp_path / "s.png", frames, f, ["a", "b"], cols=2, panel=1.5, dpi=50)
    assert out.exists() and out.stat().st_size > 1000


def test_dimmed_vertices_are_drawn_darker(tmp_path):
    """``dim`` (the mouth's inside in the bake's sheet) darkens the panel where it is 1."""
    from PIL import Image

    v, f = _sphere(16)
    frames = v[None]
    plain = shape_sheet(tmp_path / "a.png", frames, f, ["a"], cols=1, panel=2.0, dpi=60)
    dim = (v[:, 0] > 0.0).astype(float)                  # the subject's left half (image right)
    dark = shape_sheet(tmp_path / "b.png", frames, f, ["a"], cols=1, panel=2.0, dpi=60, dim=dim)
    a = np.asarray(Image.open(plain).convert("L"), dtype=float)
    b = np.asarray(Image.open(dark).convert("L"), dtype=float)
    assert a.shape == b.shape
    q = a.shape[1] // 3                                  # outer thirds (the seam's triangles blend)
    left, right = np.abs(a - b)[:, :q], np.abs(a - b)[:, -q:]
    assert right.mean() > 10.0 * max(left.mean(), 0.1)  # only the dimmed side changed
    assert (b[:, -q:] <= a[:, -q:] + 1.0).all()          # and only darker
