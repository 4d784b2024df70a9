"""Pieces of the head mesh that ride a bone rigidly: eyeballs, teeth, a tongue (beyond §8).

A head from a modelling tool often carries, besides its skin, separate pieces inside it: two
eyeballs, the upper and lower teeth, a tongue. §8 binds every vertex of the mesh to what its ray
meets first, so these pieces were bound like skin to the muscles around them: in a smile the
eyeballs of a MakeHuman head with spheres in its sockets were squashed by 5 mm. They are rigid,
and they ride the skull: the eyeballs and the upper teeth the cranium (the maxilla is part of
it), the lower teeth and the tongue the mandible.

:func:`rigid_parts` tells them apart. A *piece* is a connected component of the faces. The pieces
that hold the landmarks are the skin: the one holding most, and any holding a fifth as many (a
landmark may snap onto an eyeball: the pupils 3.5 / 3.6 lie on it, the lids' points beside it).
Another piece is *inner* when the median of its vertices lies inside the convex hull of the fitted
bones (cranium and mandible): an eyeball sits in the orbit and the teeth on the jaws, inside the
hull, while eyelashes, brow or beard cards lie on the skin, outside it (the soft tissue is 3-15 mm
deep), and a piece outside the head is another object. Vertices no face uses (MediaPipe's iris
points) are left to the skin. (The skin's own normals do not tell an eyeball in: in a mesh with
closed sockets the socket's lining faces the eyeball.) An inner piece rides the mandible when its
median lies below the mouth's line (``mouth``: the height of the inner lips, FDPs 2.2 / 2.3, along
``up``), else the cranium; without the mouth's line, the bone whose vertices are nearer (median
distance).

Functions on arrays; any unit, the frame is the fit's (+Y up, +Z forward).
"""

from __future__ import annotations

import numpy as np

from faceforge.constants import INT

__all__ = ["SKIN", "ON_CRANIUM", "ON_MANDIBLE", "rigid_parts", "part_counts"]

#: :func:`rigid_parts` labels: skin (simulated), rigid on the cranium, rigid on the mandible
SKIN, ON_CRANIUM, ON_MANDIBLE = 0, 1, 2

#: a piece holding at least this share of the most landmarks any piece holds is skin
SKIN_SHARE = 0.2


def rigid_parts(vertices, faces, skin_vertices, cranium, mandible, mouth: float | None = None,
                up=(0.0, 1.0, 0.0)) -> np.ndarray:
    """``(n,) int8``: :data:`SKIN`, :data:`ON_CRANIUM` or :data:`ON_MANDIBLE` for each vertex of the
    mesh ``vertices (n, 3)``, ``faces (m, 3)`` (see the module text).

    skin_vertices : ids of the landmarks' vertices; the pieces holding most of them are skin.
    cranium, mandible : (vertices (k, 3), faces) of the fitted bones at rest.
    mouth : the inner lips' height along ``up`` (a unit direction (3,)), or None.
    All :data:`SKIN` when no skin vertex is given or the mesh is one piece.
    """
    from scipy.spatial import ConvexHull, cKDTree

    from faceforge.geometry.triangles import vertex_components

    v = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    f = np.asarray(faces, dtype=INT).reshape(-1, 3)
    out = np.zeros(len(v), np.int8)
    marks = np.asarray([i for i in skin_vertices if 0 <= int(i) < len(v)], dtype=INT)
    label = vertex_components(len(v), f)
    held, count = np.unique(label[marks][label[marks] >= 0], return_counts=True)
    skin_labels = held[count >= max(SKIN_SHARE * count.max(initial=0), 1)]
    others = np.setdiff1d(np.unique(label[label >= 0]), skin_labels)
    if len(skin_labels) == 0 or len(others) == 0:
        return out
    bone_v = [np.asarray(b[0], dtype=np.float64).reshape(-1, 3)[np.unique(np.asarray(b[1], dtype=INT))]
              for b in (cranium, mandible)]                # the vertices their faces use
    hull = ConvexHull(np.concatenate(bone_v)).equations        # rows (normal, offset): inside <= 0
    trees = [cKDTree(b) for b in bone_v]
    up = np.asarray(up, dtype=np.float64) / np.linalg.norm(up)
    for piece in others:
        ids = np.flatnonzero(label == piece)
        centre = np.median(v[ids], axis=0)
        if np.any(hull[:, :3] @ centre + hull[:, 3] > 0.0):
            continue                                   # outside the bones' hull: on the skin, or another object
        if mouth is not None:
            below = float(centre @ up) < float(mouth)
        else:
            below = np.median(trees[1].query(v[ids])[0]) < np.median(trees[0].query(v[ids])[0])
        out[ids] = ON_MANDIBLE if below else ON_CRANIUM
    return out


def part_counts(parts) -> dict:
    """``{"on_cranium": vertices, "on_mandible": vertices}`` of a :func:`rigid_parts` labelling."""
    parts = np.asarray(parts)
    return {"on_cranium": int((parts == ON_CRANIUM).sum()), "on_mandible": int((parts == ON_MANDIBLE).sum())}
