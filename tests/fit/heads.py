"""Shared fixtures of the fit tests (registered for the whole suite by tests/conftest.py): a small
synthetic head and the sample heads, fitted once per session."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
SAMPLES = {
    "makehuman": ROOT / "samples/makehuman/mh_head_default.obj",
    "ict": ROOT / "samples/ict/ict_face_headneck_neutral.obj",
    "mediapipe": ROOT / "samples/mediapipe/face_model_with_iris.obj",
}


def ellipsoid_head(n_lat: int = 24, n_lon: int = 32, radii=(0.8, 1.1, 0.95)):
    """Closed UV ellipsoid: (vertices (n,3) float64, faces (m,3) int64), outward winding."""
    lat = np.linspace(0.0, np.pi, n_lat + 1)[1:-1]
    lon = np.linspace(0.0, 2 * np.pi, n_lon, endpoint=False)
    th, ph = np.meshgrid(lat, lon, indexing="ij")
    ring = np.stack([np.sin(th) * np.sin(ph), np.cos(th), np.sin(th) * np.cos(ph)], -1).reshape(-1, 3)
    v = np.vstack([[0, 1, 0], ring, [0, -1, 0]]) * np.asarray(radii)
    faces = []
    idx = lambda i, j: 1 + i * n_lon + (j % n_lon)
    for j in range(n_lon):
        faces.append([0, idx(0, j), idx(0, j + 1)])
        faces.append([len(v) - 1, idx(n_lat - 2, j + 1), idx(n_lat - 2, j)])
    for i in range(n_lat - 2):
        for j in range(n_lon):
            a, b, c, d = idx(i, j), idx(i, j + 1), idx(i + 1, j), idx(i + 1, j + 1)
            faces += [[a, c, b], [b, c, d]]
    return v.astype(np.float64), np.asarray(faces, dtype=np.int64)


@pytest.fixture(scope="session")
def ellipsoid():
    return ellipsoid_head()


def face_landmarks_on(vertices, faces):
    """A plausible FDP set on an ellipsoid head facing +Z: {fdp: point on the surface}."""
    import trimesh

    mesh = trimesh.Trimesh(vertices, faces, process=False)
    dirs = {
        "2.1": (0, -0.75, 0.65), "2.10": (0, -0.6, 0.8), "3.7": (0.45, 0.25, 0.85), "3.12": (-0.45, 0.25, 0.85),
        "3.11": (0.15, 0.25, 0.96), "3.8": (-0.15, 0.25, 0.96), "4.3": (0.3, 0.4, 0.87), "4.4": (-0.3, 0.4, 0.87),
        "8.3": (0.25, -0.35, 0.9), "8.4": (-0.25, -0.35, 0.9), "9.3": (0, 0.0, 1.0), "9.15": (0, -0.12, 0.99),
    }
    out = {}
    for k, d in dirs.items():
        d = np.asarray(d, float) / np.linalg.norm(d)
        loc, _, _ = mesh.ray.intersects_location([[0, 0, 0]], [d])
        out[k] = loc[np.argmax(loc @ d)]
    return out


@pytest.fixture(scope="session")
def template():
    """The repository's template skull and muscle map (muscles from the disk cache)."""
    from faceforge.fit.template import load_template

    return load_template(ROOT / "templates/skull", ROOT / "templates/muscle_map.yaml")


class _Fits:
    """One fit per sample head for the whole session (fits are deterministic)."""

    def __init__(self, template):
        self.template, self.cache = template, {}

    def __call__(self, name):
        if name not in self.cache:
            from faceforge.fit.files import fit_files

            mesh = SAMPLES[name]
            self.cache[name] = fit_files(mesh, mesh.with_name(mesh.stem + ".fdp.yaml"), self.template, {})
        return self.cache[name]


@pytest.fixture(scope="session")
def fitted(template):
    """``fitted(name) -> (FitResult, report, extra)`` for a sample head, computed once."""
    return _Fits(template)
