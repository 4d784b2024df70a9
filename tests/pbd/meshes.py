"""Test meshes and the §8-style skin constraint set (all kinds) built on them."""

from __future__ import annotations

import numpy as np
import trimesh

from faceforge.pbd import ModelBuilder


def grid_faces(n: int) -> np.ndarray:
    """Triangles ``(2 (n-1)^2, 3)`` of an ``n x n`` vertex grid numbered row by row (two per
    cell, counter-clockwise seen from +Z when rows run along +y)."""
    f = []
    for i in range(n - 1):
        for j in range(n - 1):
            a = i * n + j
            f += [[a, a + 1, a + n + 1], [a, a + n + 1, a + n]]
    return np.array(f)


def sphere(subdivisions: int = 2, radius: float = 1.0):
    m = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    return np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.int64)


def adjacent_quads(faces: np.ndarray) -> np.ndarray:
    """Quads (p0, p1, p2, p3) per interior edge: p0->p1 oriented as in the face holding p2."""
    f = np.asarray(faces, dtype=np.int64)
    half = {}
    for t in f:
        for i in range(3):
            half[(t[i], t[(i + 1) % 3])] = t[(i + 2) % 3]
    quads = [(a, b, c, half[(b, a)]) for (a, b), c in half.items() if a < b and (b, a) in half]
    return np.array(sorted(quads), dtype=np.int64).reshape(-1, 4)


def edges(faces: np.ndarray) -> np.ndarray:
    f = np.asarray(faces, dtype=np.int64)
    e = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    return np.unique(e, axis=0)


def skin_builder(v, f, inv_mass=1.0, stiff=None, anchors=True, extras=True):
    """Builder with a kinematic skull, anchors, attachment and position constraints plus
    the skin constraint set of §8 on ``(v, f)``. Returns ``(builder, info)``."""
    k = {"stretch": 0.15, "bending": 0.95, "area": 0.95, "volume": 1.0, "anchor": 0.2,
         "position": 0.2, "attach": 0.5} | (stiff or {})
    b = ModelBuilder()
    info = {}
    center = v.mean(axis=0)
    if anchors:  # a kinematic inner shell (the skull) and a dynamic skin above it
        skull = b.add_particles(center + 0.8 * (v - center), 0.0)
        info["skull"] = skull
    skin = b.add_particles(v, inv_mass)
    info["skin"] = skin
    fs = f + skin
    q = adjacent_quads(f) + skin
    b.add_distance(edges(f) + skin, k["stretch"])
    b.add_distance(q[:, 2:], k["stretch"])
    b.add_bending(q, k["bending"])
    b.add_area(fs, k["area"])
    b.add_volume(fs, k["volume"])
    if anchors:
        n = len(v)
        b.add_distance(np.c_[np.arange(n) + skin, np.arange(n) + skull], k["anchor"])
    if extras:
        # a free particle attached to a skin face, and one pulled to a target
        tri = fs[0]
        bary = np.array([0.2, 0.3, 0.5])
        p_att = b.add_particles((bary @ v[f[0]])[None], 1.0)
        b.add_attachment([p_att], tri[None], bary[None], k["attach"])
        p_pos = b.add_particles(v[:1] * 1.5, 1.0)
        info["slots"] = b.add_position([p_pos], k["position"])
        info["attached"], info["pulled"], info["tri"] = p_att, p_pos, tri
    return b, info
