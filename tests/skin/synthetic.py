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


def lipped_head(mouth_half_angle: float = 0.7):
    """A synthetic head: a UV-sphere skin (radius 1.2, poles on the y axis) whose
    latitude ring at y ~ -0.371 is the lip line (a shared ring over the front
    +-``mouth_half_angle`` rad), a unit-icosphere skull cut at y = -0.31 into
    cranium and mandible, and the jaw pivot.

    Returns ``dict(skin=(v, f), cranium=(v, f), mandible=(v, f), landmarks={fdp: (3,)},
    pivot=(3,))``.
    """
    import trimesh

    m = trimesh.creation.uv_sphere(radius=1.2, count=[16, 24])
    v = np.asarray(m.vertices) @ np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])  # (x, y, z) -> (x, z, -y)
    f = np.asarray(m.faces, np.int64)
    ring_y = np.unique(np.round(v[:, 1], 3))
    y0 = ring_y[np.argmin(np.abs(ring_y + 0.371))]
    ring = np.flatnonzero(np.abs(v[:, 1] - y0) < 1e-3)
    ang = np.arctan2(v[ring, 0], v[ring, 2])  # 0 at the front, + toward +x (subject's left)
    front = ring[np.abs(ang) <= mouth_half_angle + 1e-9]
    front = front[np.argsort(np.arctan2(v[front, 0], v[front, 2]))]  # right corner -> left corner
    k = len(front)
    lm = {"2.5": v[front[0]], "2.4": v[front[-1]], "2.2": v[front[k // 2]], "2.3": v[front[k // 2]],
          "2.7": v[front[k // 4]], "2.9": v[front[k // 4]], "2.6": v[front[3 * k // 4]],
          "2.8": v[front[3 * k // 4]], "2.1": np.array([0.0, -1.2, 0.0]),
          "10.9": np.array([1.2, 0.0, -0.3]), "10.10": np.array([-1.2, 0.0, -0.3]),
          "11.6": np.array([0.0, 0.0, -1.2])}
    sv, sf = sphere(1.0, 3)
    upper = sv[sf].mean(axis=1)[:, 1] > -0.31

    def sub(mask):
        used, local = np.unique(sf[mask], return_inverse=True)
        return sv[used].copy(), local.reshape(-1, 3)

    return {"skin": (v, f), "cranium": sub(upper), "mandible": sub(~upper), "landmarks": lm,
            "pivot": np.array([0.0, -0.1, -0.4])}


def jaw_matrix(pitch_rad: float, pivot) -> np.ndarray:
    """Rigid 4x4: rotation about the x axis through ``pivot``; positive opens (chin down)."""
    c, s = np.cos(pitch_rad), np.sin(pitch_rad)
    R = np.array([[1.0, 0, 0], [0, c, -s], [0, s, c]])  # y -> c y - s z: the front goes down
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = pivot - R @ pivot
    return T
