"""The bake on a symmetric rig (issue 27): only one side is solved.

On a head whose rig is symmetric by construction (fit.npz stores the mirror plane and each right
muscle is built as the mirror image of its left twin), a ``_Right`` shape is the mirror image
of its ``_Left`` partner. The bake therefore solves the left shape and settles the right one at
the mirrored pose (:func:`mirror_pose`: each contraction moved to its twin column, named by
:func:`faceforge.anatomy.muscles.muscle_map.mirrored_name`, the jaw's yaw negated); the baked
right field then mirrors the left within the rig's own symmetry (measured, not assumed).

A midline shape (``browInnerUp``, ``mouthFunnel``, ...) that names both twins of a pair solves
them as one unknown (:class:`TiedSpace`), so that its pose is symmetric too.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from faceforge.anatomy.muscles.muscle_map import mirrored_name
from faceforge.blendshapes.solve import JAW_DOFS, ControlSpace


def mirror_columns(columns) -> np.ndarray:
    """(m,) int: for each contraction column of ``columns`` the column of its mirror twin (itself
    for a midline control or a twin the head lacks)."""
    index = {n: i for i, n in enumerate(columns)}
    return np.array([index.get(mirrored_name(str(n)), i) for i, n in enumerate(columns)], dtype=np.int64)


def mirror_pose(contractions: np.ndarray, jaw: np.ndarray, twins: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The mirror image of a pose: contractions (m,) or (k, m) moved to their twin columns
    (``twins`` from :func:`mirror_columns`), jaw (3,) or (k, 3) with the yaw negated (pitch and
    protrusion are symmetric)."""
    c = np.asarray(contractions, dtype=float)
    out = np.zeros_like(c)
    out[..., twins] = c
    j = np.array(jaw, dtype=float, copy=True)
    j[..., JAW_DOFS.index("yaw")] *= -1.0
    return out, j


@dataclass(frozen=True)
class TiedSpace:
    """A :class:`~faceforge.blendshapes.solve.ControlSpace` whose mirror-twin controls move as
    one: ``groups`` lists, per unknown, the indices into ``base.names`` it sets (one or two).
    Offers what :func:`~faceforge.blendshapes.solve.solve_activations` uses: ``names``,
    ``lower``, ``upper``, ``probe``, ``pose``; ``tie (q_base, q)`` maps unknowns to controls."""

    base: ControlSpace
    groups: tuple

    @property
    def names(self) -> tuple:
        return tuple("+".join(self.base.names[i] for i in g) for g in self.groups)

    def _first(self, arr) -> np.ndarray:
        return np.asarray([np.asarray(arr, dtype=float)[g[0]] for g in self.groups])

    @property
    def lower(self) -> np.ndarray:
        return self._first(self.base.lower)

    @property
    def upper(self) -> np.ndarray:
        return self._first(self.base.upper)

    @property
    def probe(self) -> np.ndarray:
        return self._first(self.base.probe)

    @property
    def tie(self) -> np.ndarray:
        T = np.zeros((len(self.base.names), len(self.groups)))
        for k, g in enumerate(self.groups):
            T[list(g), k] = 1.0
        return T

    def pose(self, x: np.ndarray):
        """(k, q) or (q,) unknowns -> contractions (k, m) and jaw (k, 3) of the base space."""
        return self.base.pose(np.atleast_2d(np.asarray(x, dtype=float)) @ self.tie.T)

    def expand(self, x: np.ndarray) -> np.ndarray:
        """(q,) unknowns -> (q_base,) control values."""
        return self.tie @ np.asarray(x, dtype=float)


def tie_twins(space: ControlSpace) -> TiedSpace | None:
    """The controls of ``space`` with each pair of mirror twins (``X_L`` and ``X_R`` both in it,
    same bounds) as one unknown; None when the space has no such pair (nothing to tie)."""
    names = list(space.names)
    groups, seen = [], set()
    for i, n in enumerate(names):
        if i in seen:
            continue
        twin = mirrored_name(n)
        j = names.index(twin) if twin != n and twin in names else None
        if j is not None and (space.lower[i], space.upper[i]) == (space.lower[j], space.upper[j]):
            groups.append((i, j))
            seen.update((i, j))
        else:
            groups.append((i,))
            seen.add(i)
    if all(len(g) == 1 for g in groups):
        return None
    return TiedSpace(space, tuple(groups))
