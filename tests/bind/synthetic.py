"""Small synthetic meshes for the bind tests (no sample files)."""

from __future__ import annotations

import numpy as np


def grid(nx: int, ny: int, width: float = 1.0, height: float = 1.0):
    """A flat (nx+1) x (ny+1) vertex grid in the z = 0 plane, two triangles per cell.

    Returns ``(vertices (n, 3), faces (2 nx ny, 3))``; vertex ``(i, j)`` has id
    ``j * (nx + 1) + i`` and lies at ``(i / nx * width, j / ny * height, 0)``.
    """
    xs = np.linspace(0, width, nx + 1)
    ys = np.linspace(0, height, ny + 1)
    X, Y = np.meshgrid(xs, ys)
    v = np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], axis=1)
    faces = []
    for j in range(ny):
        for i in range(nx):
            a = j * (nx + 1) + i
            b, c, d = a + 1, a + nx + 1, a + nx + 2
            faces += [[a, b, d], [a, d, c]]
    return v, np.asarray(faces, np.int64)


def sphere(radius: float = 1.0, subdivisions: int = 2, center=(0.0, 0.0, 0.0)):
    """An icosphere ``(vertices, faces)`` with outward normals."""
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    return np.asarray(m.vertices) + np.asarray(center), np.asarray(m.faces, np.int64)


def mouth_grid(n: int = 8, gap: float = 0.0):
    """A flat face with a horizontal lip line on the middle row.

    Row ``n // 2`` (y = 0.5) is the lip line: its interior vertices are where the
    lips meet; corners are its vertices at columns 1 and n - 1. With ``gap > 0``
    rows above the line are lifted by ``gap`` (the geometry only; topology is the
    same). Returns ``(vertices, faces, lip_vertices {fdp: id})``.
    """
    v, f = grid(n, n)
    row = n // 2
    vid = lambda i, j: j * (n + 1) + i  # noqa: E731
    v[v[:, 1] > 0.5 + 1e-9, 1] += gap
    mid = n // 2
    lips = {
        "2.4": vid(n - 1, row), "2.5": vid(1, row),
        "2.2": vid(mid, row), "2.3": vid(mid, row),
        "2.6": vid((mid + n - 1) // 2, row), "2.8": vid((mid + n - 1) // 2, row),
        "2.7": vid((mid + 1) // 2, row), "2.9": vid((mid + 1) // 2, row),
    }
    return v, f, lips
