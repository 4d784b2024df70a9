"""A small synthetic fitted + bound head for the animate tests (no sample files, ~1 s).

Skin: a UV sphere (radius 1.2, poles on Y) whose latitude ring at y ~ -0.24 is a shared lip
line over the front (the bind stage cuts it). Skull: a unit icosphere flattened below
y = -0.31 (cranium) and an ellipsoid in the lower front (mandible), both closed. One linear
muscle, ``zygomaticus_major_L``, lies on the cranium from the left cheekbone to the left
lip corner. Jaw axes: pitch about +X through (0, -0.1, -0.1), yaw about +Y, protrusion +Z.
"""

from __future__ import annotations

import numpy as np

SKIN_R = 1.2


def skin_mesh(count=(24, 32)):
    """UV sphere skin; ``count`` (24, 32) gives 1,410 vertices, (44, 58) a Mesh_D-sized 4,874."""
    import trimesh

    m = trimesh.creation.uv_sphere(radius=SKIN_R, count=list(count))
    v = np.asarray(m.vertices) @ np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])
    return v, np.asarray(m.faces, np.int64)


def skull_meshes():
    """(cranium, mandible), both closed: a unit ball flattened below y = -0.31, and an
    ellipsoid in the lower front (the jaw)."""
    import trimesh

    ball = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    cv = np.asarray(ball.vertices).copy()
    cv[:, 1] = np.maximum(cv[:, 1], -0.31)
    jaw = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    mv = np.asarray(jaw.vertices) * [0.62, 0.28, 0.55] + [0.0, -0.62, 0.38]
    return (cv, np.asarray(ball.faces, np.int64)), (mv, np.asarray(jaw.faces, np.int64))


def _near(v, direction):
    d = np.asarray(direction, float)
    return v[np.argmin(np.linalg.norm(v - SKIN_R * d / np.linalg.norm(d), axis=1))]


def landmarks(v):
    """FDP -> (3,) position on the skin (vertex positions)."""
    y = np.round(v[:, 1], 4)
    ring_y = np.unique(y)[np.argmin(np.abs(np.unique(y) + 0.24))]
    ring = np.flatnonzero(np.abs(v[:, 1] - ring_y) < 1e-3)
    ang = np.arctan2(v[ring, 0], v[ring, 2])
    front = ring[np.abs(ang) <= 0.45]
    front = front[np.argsort(np.arctan2(v[front, 0], v[front, 2]))]
    k = len(front)
    lm = {"2.5": v[front[0]], "2.4": v[front[-1]], "2.2": v[front[k // 2]], "2.3": v[front[k // 2]],
          "2.7": v[front[k // 4]], "2.9": v[front[k // 4]], "2.6": v[front[3 * k // 4]],
          "2.8": v[front[3 * k // 4]], "8.3": v[front[-1]], "8.4": v[front[0]]}
    dirs = {"2.1": (0, -0.6, 0.8), "3.5": (0.3, 0.25, 0.92), "3.6": (-0.3, 0.25, 0.92),
            "3.1": (0.3, 0.32, 0.9), "3.3": (0.3, 0.1, 0.95), "3.2": (-0.3, 0.32, 0.9),
            "3.4": (-0.3, 0.1, 0.95), "3.7": (0.46, 0.245, 0.86), "3.11": (0.14, 0.245, 0.96),
            "3.12": (-0.46, 0.245, 0.86), "3.8": (-0.14, 0.245, 0.96), "9.15": (0, -0.02, 1.0), "4.1": (0.12, 0.45, 0.88),
            "4.2": (-0.12, 0.45, 0.88), "4.3": (0.3, 0.48, 0.82), "4.4": (-0.3, 0.48, 0.82),
            "4.5": (0.45, 0.45, 0.76), "4.6": (-0.45, 0.45, 0.76), "5.1": (0.55, -0.15, 0.82),
            "5.2": (-0.55, -0.15, 0.82), "5.3": (0.5, 0.0, 0.86), "5.4": (-0.5, 0.0, 0.86),
            "11.6": (0, 0.0, -1.0)}
    for k_, d in dirs.items():
        lm[k_] = _near(v, d)
    return lm


JAW = {"pitch_point": [0.0, -0.1, -0.1], "pitch_direction": [1.0, 0.0, 0.0],
       "yaw_point": [0.0, -0.1, -0.1], "yaw_direction": [0.0, 1.0, 0.0],
       "protrusion_direction": [0.0, 0.0, 1.0]}


def write_fit(fit_dir, count=(24, 32), extra_muscles: int = 0):
    """fit.npz of the synthetic head (the keys of the fit stage's contract)."""
    from faceforge.io.stagefiles import save_npz

    v, f = skin_mesh(count)
    (cv, cf), (mv, mf) = skull_meshes()
    lm = landmarks(v)
    fit_dir.mkdir(parents=True, exist_ok=True)
    from faceforge.io.config import load_config
    from faceforge.pbd import SolverSettings

    system = muscle_system(None, (cv, cf), (mv, mf), SolverSettings(), load_config(), None,
                           extra=extra_muscles)
    names = [n for n in system.names if n not in ("cranium", "mandible")]
    muscles = [(system.rest_positions(n), system.faces(n)) for n in names]
    vstart = np.cumsum([0] + [len(a) for a, _ in muscles])
    fstart = np.cumsum([0] + [len(b) for _, b in muscles])
    save_npz(fit_dir / "fit.npz", skin_vertices=v, skin_faces=f, skin_user_to_internal=np.arange(len(v)),
             muscle_names=np.array(names), muscle_layers=np.array([1] * len(names)),
             muscle_vertex_start=vstart, muscle_vertices=np.concatenate([a for a, _ in muscles]),
             muscle_face_start=fstart, muscle_faces=np.concatenate([b for _, b in muscles]),
             cranium_vertices=cv, cranium_faces=cf, mandible_vertices=mv, mandible_faces=mf,
             skin_landmark_ids=np.array(list(lm)), skin_landmark_positions=np.array(list(lm.values())),
             landmark_ids=np.array(["2.1"]), landmark_positions=np.array([[0.0, -0.75, 0.66]]),
             **{f"jaw_{k}": np.asarray(val, float) for k, val in JAW.items()})
    return v, f, lm


def muscle_system(fit, cranium, mandible, settings, config, log, extra: int = 0, cache=None):
    """Stand-in for the fit stage's muscle rebuild: a zygomaticus on the cranium, plus
    ``extra`` passive sheets (h 6, w 3) around the upper skull (for timing a full map); ``cache``
    (the real one's folder of built muscles) is not used."""
    from faceforge.anatomy.muscles.action_line import ActionLine
    from faceforge.anatomy.layers import MusculoskeletalSystem
    from faceforge.anatomy.muscles.muscle import build_linear_muscle

    cv, cf = cranium
    stiff = {k: float(v) for k, v in config.get("muscle.linear.stiffness").items()}

    def line(a, b):
        pts = np.linspace(a, b, 5)
        pts = pts / np.linalg.norm(pts, axis=1, keepdims=True)
        return ActionLine.from_points(pts, cv, cf)

    def sheet(name, o0, o1, i0, i1, h, w, t, active=True):
        return build_linear_muscle(name, line(o0, o1), line(i0, i1), line(o0, i0), line(o1, i1),
                                   cv, cf, h, w, t, stiff, lies_on=("cranium",), layer=1, active=active)

    muscles = [sheet("zygomaticus_major_L", np.array([0.55, 0.2, 0.8]), np.array([0.75, 0.05, 0.65]),
                     np.array([0.25, -0.2, 0.92]), np.array([0.45, -0.2, 0.84]), 6, 4, 0.08)]
    for k in range(extra):
        a = -2.4 + 4.8 * (k + 0.5) / extra                   # azimuth around the skull, rad
        y0 = 0.45 + 0.15 * (k % 2)
        d = lambda az, y: np.array([np.sin(az), y, np.cos(az)])  # noqa: E731
        muscles.append(sheet(f"sheet_{k}", d(a, y0 + 0.25), d(a + 0.12, y0 + 0.25), d(a, y0),
                             d(a + 0.12, y0), 6, 3, 0.04, active=False))
    return MusculoskeletalSystem.from_parts(cranium, mandible, muscles, settings)


MAPPING = {
    "jaw_limits": {"pitch": [-0.02, 0.45], "yaw": [-0.1, 0.1], "protrusion": [-0.04, 0.1]},
    "entries": [
        {"fap": 3, "name": "open_jaw", "fapu": "MNS", "jaw": {"dof": "pitch", "gain": 1.0},
         "measure": {3: {"fdp": "2.3", "relative_to": "2.2"}}},
        {"fap": [59, 12], "name": "raise_l_cornerlip", "fapu": "MNS",
         "positive": {"zygomaticus_major_L": 0.003}},
        {"fap": [52, 5], "name": "raise_b_midlip", "fapu": "MNS", "coupling": {3: -0.8}},
    ],
    "expressions": {"joy": {"id": 1, "faps": {59: 150, 12: 150, 3: 60, 19: 128, 20: 128, 21: 64, 22: 64}}},
}
