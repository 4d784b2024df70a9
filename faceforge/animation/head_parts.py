"""Which pieces of a skin mesh belong to the landmarked head.

A mesh may hold more than one head (two scanned people side by side, a copy of the head
beside it): the fit notes the separate pieces, and every stage works on the whole mesh. The
head turn (FAPs 48-50) turns the landmarked head about its neck; a piece that holds no
landmark and lies wholly outside the landmarked pieces' box is another object, and must not
swing with it (issue 28). Eyeballs, teeth, iris points hold no landmark either but lie
inside the head's box, so they still turn with it.
"""

from __future__ import annotations

import numpy as np


def detached_vertices(rest: np.ndarray, faces: np.ndarray, landmark_vertices) -> np.ndarray:
    """``(n,) bool``: vertices of ``rest (n, 3)`` (faces ``(m, 3)``) on a piece that holds no
    vertex of ``landmark_vertices`` (ids) and whose bounding box does not meet the box of the
    pieces that do. Vertices no face references are judged by position alone (outside the box:
    detached). All False when no landmark lies on the mesh."""
    from faceforge.io.mesh_check import face_components

    rest = np.asarray(rest, dtype=np.float64).reshape(-1, 3)
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    n = len(rest)
    marks = np.asarray([i for i in landmark_vertices if 0 <= int(i) < n], dtype=np.int64)
    out = np.zeros(n, bool)
    if len(marks) == 0 or len(faces) == 0:
        return out
    label_f = face_components(faces, n)
    label_v = np.full(n, -1, np.int64)
    label_v[faces.reshape(-1)] = np.repeat(label_f, 3)
    head = np.isin(label_v, np.unique(label_v[marks][label_v[marks] >= 0]))
    head[marks] = True
    lo, hi = rest[head].min(axis=0), rest[head].max(axis=0)
    for label in np.unique(label_v):
        piece = label_v == label if label >= 0 else (label_v == -1)
        if label >= 0 and head[piece].any():
            continue
        if label < 0:
            p = rest[piece]
            out[np.flatnonzero(piece)[np.any((p < lo) | (p > hi), axis=1)]] = True
            continue
        p = rest[piece]
        if np.any(p.max(axis=0) < lo) or np.any(p.min(axis=0) > hi):
            out[piece] = True
    return out
