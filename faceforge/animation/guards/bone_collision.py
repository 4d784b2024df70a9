"""Skin that got inside a bone is put back out (beyond the paper; after the skin's constraints).

:class:`faceforge.animation.guards.skull.SkullGuard` holds each skin vertex above the plane of the
bone triangle under it at rest. A vertex that slides over the bone (the lips onto the other
jaw's teeth, the cheek over the cheekbone) meets bone that triangle does not describe and can
end inside it. :class:`BoneCollision` finds such vertices with the same test the animation
check uses (ray parity, :class:`faceforge.geometry.parity.ParityGrid`) and moves each out
along the shortest way to ``keep`` times its rest distance above the bone.

Local signs (the closest face's normal, angle-weighted pseudonormals) were tried first and
misjudge the fitted bone where the fit folds it (MakeHuman's orbits and jaw angles): they
pushed skin in. Parity counts crossings of the whole surface and is not misled by a fold.

The bones are rigid: each is tested in its rest pose, the skin brought into the bone's rest
frame, so each bone's parity grid is built once. Only vertices that may be inside are
cast: the distance to a rigid bone is 1-Lipschitz, so a vertex nearer than ``d0`` to where
its rest position went with the bone (``d0`` its rest distance) is still outside.

A bone that moves (the mandible) reaches skin that was far from it at rest: opening with the
condylar glide carries the mandible's front 1.2 cm forward-down at 0.16 rad on MediaPipe, into
the upper lip's inner midline, 1.3 cm (beyond ``reach``) from the bone at rest; that vertex was
not guarded and ended inside (the Xface sweep's fear.fap). ``sweeps`` gives a bone's poses over
its range: skin within ``reach`` of the bone in any of them is guarded too.
"""

from __future__ import annotations

import numba
import numpy as np

from faceforge.constants import NUMBA_OPTIONS

__all__ = ["BoneCollision"]

_EYE4 = np.eye(4)


class BoneCollision:
    """Puts skin vertices found inside a rigid bone back out (see the module docstring).

    Parameters
    ----------
    rest : (n, 3) float, skin at rest (skin units)
    bodies : dict name -> (vertices (v, 3), faces (f, 3)), the bones at rest, closed
    reach : float, skin units: vertices outside a bone and within this of it at rest are guarded
    keep : float in [0, 1): a vertex put back out sits at ``keep * d0`` from the bone
    sweeps : optional dict name -> (p, 4, 4) rigid transforms of that bone from its rest pose
        over its range of motion: vertices within ``reach`` of the bone in any of them (brought
        into its rest frame) are guarded as well

    Attributes
    ----------
    guarded : dict name -> (vertex ids (k,) int, rest positions (k, 3) in the bone's rest frame,
        floor (k,), rest distance (k,))
    """

    def __init__(self, rest: np.ndarray, bodies: dict, reach: float, keep: float = 0.5,
                 sweeps: dict | None = None):
        import trimesh

        from faceforge.geometry.parity import ParityGrid
        from faceforge.geometry.surface_points import projector

        rest = np.asarray(rest, dtype=np.float64).reshape(-1, 3)
        self.names, self.guarded, self._grids, self._trees = [], {}, {}, {}
        for name, (v, f) in bodies.items():
            mesh = trimesh.Trimesh(np.asarray(v, np.float64), np.asarray(f, np.int64), process=False)
            if not len(rest) or not len(mesh.faces):
                continue
            proj = projector(mesh.vertices, mesh.faces)
            _, dist, _ = proj.closest(rest)
            grid = ParityGrid(mesh.vertices, mesh.faces)
            near = dist < reach
            for t in np.asarray((sweeps or {}).get(name, np.zeros((0, 4, 4))), dtype=np.float64):
                # the skin in the bone's rest frame with the bone at pose t: R^T (x - t)
                near |= proj.closest((rest - t[:3, 3]) @ t[:3, :3])[1] < reach
            ids = np.flatnonzero(near & (dist > 0.0) & ~grid.contains(rest))
            self.names.append(name)
            self.guarded[name] = (ids, rest[ids], keep * dist[ids], dist[ids])
            self._grids[name] = grid
            self._trees[name] = proj.tree
        self._all = {name: np.arange(len(self.guarded[name][0])) for name in self.names}

    def apply(self, positions: np.ndarray, transforms: dict, only=None) -> int:
        """Move the guarded vertices of ``positions`` ((n, 3) float, in place) that are inside a
        bone out of it. ``transforms``: name -> (4, 4) rigid transform of that bone from its rest
        pose (missing: identity). ``only`` (optional, (p,) int): test just these vertices (the
        others were found outside with the bones where they are now and have not moved since).
        Returns how many moved; :attr:`moved` holds their ids ((k,) int, repeats allowed)."""
        # every bone sees the positions as they came in (a vertex pushed out of one bone is not
        # re-tested against the other in the same pass)
        passes = []
        if only is not None:
            listed = np.zeros(len(positions), dtype=bool)
            listed[np.asarray(only, dtype=np.int64)] = True
        for name in self.names:
            t = np.asarray(transforms.get(name, _EYE4), dtype=np.float64)
            ids, rest, _, slack = self.guarded[name]
            rows = self._all[name] if only is None else np.flatnonzero(listed[ids])
            p, kept = np.empty((len(rows), 3)), np.empty_like(rows)
            maybe = kept[:_maybe_inside(positions, ids, rows, rest, slack, t, p, kept)]
            passes.append((name, t, p[:len(maybe)], maybe))
        moved = []
        for name, t, p, maybe in passes:
            hit = self._grids[name].contains(p)
            if not hit.any():
                continue
            ids, _, floor, _ = self.guarded[name]
            k = maybe[hit]
            q, face = self._trees[name].closest(p[hit])
            out = q + floor[k, None] * _outward(q - p[hit], self._trees[name].normals[face])
            positions[ids[k]] = out @ t[:3, :3].T + t[:3, 3]
            moved.append(ids[k])
        self.moved = np.concatenate(moved) if moved else np.zeros(0, dtype=np.int64)
        return len(self.moved)



def _outward(v: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Unit directions ``(k, 3)`` out of the bone at closest points: the closest triangle's
    normal ``normal (k, 3)`` (unit, or 0 when degenerate), turned to the side of ``v = q - p``
    (p inside, q its closest point). Not ``v / |v|``: for skin just inside (|v| << the floor)
    that direction is ill-conditioned (a vertex 1e-6 inside, moved by 1e-12, lands
    1e-12 x floor / 1e-6 further off); the normal does not move with p. A degenerate triangle
    falls back to ``v / |v|``. (Calibrated MakeHuman joy still grows 1e-13 of round-off to
    ~1e-2 within 20 frames with either direction: the collision and orientation passes
    together do that; with either of them off it stays below 1e-6.)"""
    side = np.einsum("ij,ij->i", normal, v)
    out = np.where(side[:, None] < 0.0, -normal, normal)
    flat = ~np.any(normal != 0.0, axis=1)
    if flat.any():
        d = np.linalg.norm(v[flat], axis=1)
        out[flat] = v[flat] / np.maximum(d, 1e-300)[:, None]
    return out


@numba.njit(**NUMBA_OPTIONS)
def _maybe_inside(x, ids, rows, rest, slack, t, p, kept):  # pragma: no cover - numba
    """The guarded ``rows`` whose vertex ``x[ids[row]]``, brought into the bone's rest frame
    (``R^T (x - t)`` with ``t (4, 4)``), is at least ``slack[row]`` from where its rest position
    went: writes them in order into ``kept[:k]`` and their rest-frame positions into ``p[:k]``
    (``kept``, ``p``: as long as ``rows``); returns k."""
    k = 0
    for j in range(rows.shape[0]):
        r = rows[j]
        i = ids[r]
        dx = x[i, 0] - t[0, 3]
        dy = x[i, 1] - t[1, 3]
        dz = x[i, 2] - t[2, 3]
        px = dx * t[0, 0] + dy * t[1, 0] + dz * t[2, 0]
        py = dx * t[0, 1] + dy * t[1, 1] + dz * t[2, 1]
        pz = dx * t[0, 2] + dy * t[1, 2] + dz * t[2, 2]
        ex = px - rest[r, 0]
        ey = py - rest[r, 1]
        ez = pz - rest[r, 2]
        if ex * ex + ey * ey + ez * ez >= slack[r] * slack[r]:
            p[k, 0] = px
            p[k, 1] = py
            p[k, 2] = pz
            kept[k] = r
            k += 1
    return k
