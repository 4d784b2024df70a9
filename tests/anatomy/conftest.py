"""Synthetic fixtures for the muscle model: no template skull is needed.

The "skull" is a unit icosphere cut into a cranium (faces whose centroid lies
above y = -0.3) and a mandible (the rest, with its own copy of the cut's
vertices). The jaw pitches about the x axis through ``PIVOT``, the sphere's
centre, so the mandible slides along the cranium's sphere. (A pivot behind the
cut, like real condyles, moves the mandible off the sphere and opens a step at
the cut larger than the muscles' thickness; the sphincter straddling the cut
then folds one face for a few frames while the jaw moves.) Muscles are drawn on the front (+z) of the sphere:

====================  =====  ==========================  ==========================
name                  layer  lies on                     site
====================  =====  ==========================  ==========================
frontalis             0      skull (cranium only)        forehead
mentalis              0      skull (mandible only)       chin
masseter              0      skull (cranium + mandible)  side, across the cut
zygomaticus           1      skull + frontalis           cheek, partly on frontalis
oris                  1      skull (sphincter)           around the "mouth" at the cut
====================  =====  ==========================  ==========================
"""

from __future__ import annotations

import numpy as np
import pytest

from faceforge.anatomy.muscles.action_line import ActionLine
from faceforge.anatomy.layers import underlying_mesh
from faceforge.anatomy.muscles.muscle import build_linear_muscle, build_sphincter_muscle
from faceforge.anatomy.muscles.sphincter import align_loops
from faceforge.geometry.triangles import concatenate_meshes

PIVOT = np.array([0.0, 0.0, 0.0])
CUT_Y = -0.3

LINEAR_STIFFNESS = dict(latitudinal_up=1.0, longitudinal_up=0.1, connection=1.0, bend=0.4,
                        volume=1.0, position=0.2)
SPHINCTER_STIFFNESS = dict(latitudinal_up=0.2, connection=1.0, shear_up=0.3, shear_low=0.3,
                           bend=1.0, volume=1.0, position=0.2)


def planar_mouth(h=24, tall=1.0):
    """A planar mouth in z = 0 (+Y up), wider than tall: the inner loop round the opening at the origin,
    the outer loop reaching twice as far down (the chin) as up; ``tall`` stretches the outer loop's
    height. (h, 3) inner, (h, 3) outer."""
    ang = 2 * np.pi * np.arange(h) / h
    inner = np.stack([np.cos(ang), 0.3 * np.sin(ang), np.zeros(h)], 1)
    outer = np.stack([2.0 * np.cos(ang), tall * (-0.4 + 1.2 * np.sin(ang)), np.zeros(h)], 1)
    return inner, outer


def jostled(v, rng, trial, turn=0.6):
    """``v (n, 3)`` turned up to ``turn`` rad about a random axis, scaled 0.5-2x, moved, and noised by
    ``0.01 trial`` per vertex: the same muscle seen in another frame, for kernel-against-twin checks."""
    import trimesh

    rot = trimesh.transformations.rotation_matrix(rng.uniform(0, turn), rng.normal(size=3))[:3, :3]
    return v @ rot.T * rng.uniform(0.5, 2.0) + rng.normal(size=3) + rng.normal(scale=0.01 * trial, size=v.shape)


def icosphere(subdivisions=3, radius=1.0):
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    return np.asarray(m.vertices, float), np.asarray(m.faces, np.int64)


def submesh(v, f, mask):
    """Faces ``f[mask]`` with their own compact vertex array."""
    used = np.unique(f[mask])
    remap = np.full(len(v), -1, np.int64)
    remap[used] = np.arange(len(used))
    return v[used].copy(), remap[f[mask]]


def split_skull(subdivisions=3):
    v, f = icosphere(subdivisions)
    upper = v[f].mean(axis=1)[:, 1] > CUT_Y
    return submesh(v, f, upper), submesh(v, f, ~upper)


def jaw_matrix(pitch_rad, pivot=PIVOT):
    """Rigid 4x4: rotation by ``pitch_rad`` about the x axis through ``pivot`` (opens downward)."""
    c, s = np.cos(pitch_rad), np.sin(pitch_rad)
    R = np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = pivot - R @ pivot
    return T


def on_sphere(*xy, z=1.0):
    """Points (x, y) pushed onto the unit sphere's front (+z)."""
    p = np.array([[x, y, z] for x, y in np.asarray(xy, float).reshape(-1, 2)])
    return p / np.linalg.norm(p, axis=1, keepdims=True)


def linear_on(name, v, f, origin, insertion, h=6, w=3, thickness=0.04, layer=0, lies_on=("skull",),
              active=True, project="closest"):
    """Linear muscle from origin/insertion point lists (x, y pairs on the sphere front)."""
    o, i = on_sphere(*origin), on_sphere(*insertion)
    A3 = ActionLine.from_points(o, v, f, project=project)
    A1 = ActionLine.from_points(i, v, f, project=project)
    A0 = ActionLine.from_points([o[0], i[0]], v, f, project=project)
    A2 = ActionLine.from_points([o[-1], i[-1]], v, f, project=project)
    return build_linear_muscle(name, A3, A1, A0, A2, v, f, h, w, thickness, LINEAR_STIFFNESS,
                               lies_on=lies_on, layer=layer, active=active)


def sphincter_on(name, v, f, centre, inner_axes, outer_axes, h=16, w=3, thickness=0.03, layer=1,
                 lies_on=("skull",)):
    ang = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    cx, cy = centre
    inner = on_sphere(*np.stack([cx + inner_axes[0] * np.cos(ang), cy + inner_axes[1] * np.sin(ang)], 1))
    outer = on_sphere(*np.stack([cx + outer_axes[0] * np.cos(ang), cy + outer_axes[1] * np.sin(ang)], 1))
    inner, outer = align_loops(inner, outer)
    L1 = ActionLine.from_points(inner, v, f, closed=True)
    L3 = ActionLine.from_points(outer, v, f, closed=True)
    return build_sphincter_muscle(name, L1, L3, v, f, h, w, thickness, SPHINCTER_STIFFNESS,
                                  lies_on=lies_on, layer=layer)


def chin_mouth_on(v, f, **kw):
    """A sphincter on the sphere ``v, f`` whose outer loop reaches further down than up (a chin);
    ``kw`` goes to :func:`build_sphincter_muscle` (``closure_centre``, ``protrusion``, ...)."""
    ang = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    inner = on_sphere(*np.stack([0.15 * np.cos(ang), -0.3 + 0.05 * np.sin(ang)], 1))
    outer = on_sphere(*np.stack([0.32 * np.cos(ang), -0.38 + 0.2 * np.sin(ang)], 1))
    inner, outer = align_loops(inner, outer)
    return build_sphincter_muscle("oris", ActionLine.from_points(inner, v, f, closed=True),
                                  ActionLine.from_points(outer, v, f, closed=True), v, f, 16, 3, 0.03,
                                  SPHINCTER_STIFFNESS, lies_on=("skull",), layer=1, **kw)


def ring_with_pair(name, origin, insertion, inner_axes, centre=(0.0, -0.3), outer_axes=(0.32, 0.17)):
    """(cranium, mandible, muscles) of the split sphere: a linear pair ``name_L`` / ``name_R``
    (layer 0, on the bone; ``origin`` / ``insertion``: the left one's (x, y) points, the right
    one mirrored in x) and the orbicularis oris (layer 1, on the bone only: nothing ties the
    pair to it unless a test does)."""
    cranium, mandible = split_skull(3)
    v, f, _ = concatenate_meshes([cranium, mandible])
    muscles = [linear_on(name + suffix, v, f, [(s * x, y) for x, y in origin],
                         [(s * x, y) for x, y in insertion], h=5)
               for s, suffix in ((1.0, "_L"), (-1.0, "_R"))]
    muscles.append(sphincter_on("orbicularis_oris", v, f, centre, inner_axes, outer_axes, layer=1))
    return cranium, mandible, muscles


def synthetic_head(subdivisions=3):
    """``(cranium, mandible, muscles)`` of the table in the module docstring."""
    cranium, mandible = split_skull(subdivisions)
    sv, sf, _ = concatenate_meshes([cranium, mandible])
    frontalis = linear_on("frontalis", sv, sf, [(-0.1, 0.75), (0.25, 0.75)], [(-0.1, 0.25), (0.25, 0.25)])
    mentalis = linear_on("mentalis", sv, sf, [(-0.15, -0.5), (0.15, -0.5)], [(-0.15, -0.85), (0.15, -0.85)],
                         h=4)
    masseter = linear_on("masseter", sv, sf, [(0.55, 0.0), (0.8, 0.0)], [(0.55, -0.6), (0.8, -0.6)])
    # zygomaticus lies on the skull and on the top of frontalis
    zv, zf = underlying_mesh(("skull", "frontalis"), cranium, mandible, [frontalis])
    zygomaticus = linear_on("zygomaticus", zv, zf, [(0.2, 0.45), (0.35, 0.45)], [(0.2, 0.0), (0.35, 0.0)],
                            h=5, layer=1, lies_on=("skull", "frontalis"), project="outermost")
    oris = sphincter_on("oris", sv, sf, (0.0, -0.3), (0.15, 0.07), (0.32, 0.17))
    return cranium, mandible, [frontalis, mentalis, masseter, zygomaticus, oris]


@pytest.fixture(scope="session")
def head():
    return synthetic_head()


@pytest.fixture(scope="session")
def skull_mesh(head):
    cranium, mandible, _ = head
    v, f, _ = concatenate_meshes([cranium, mandible])
    return v, f
