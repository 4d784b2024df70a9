"""Skin that got inside a bone is put back out (beyond the paper; after the skin's constraints).

:class:`faceforge.anatomy.animate.SkullGuard` holds each skin vertex above the plane of the
bone triangle under it at rest. A vertex that slides over the bone (the lips onto the other
jaw's teeth, the cheek over the cheekbone) meets bone that triangle does not describe and can
end inside it. :class:`BoneCollision` finds such vertices with the same test the animation
check uses (ray parity, :func:`faceforge.anatomy.animate.points_inside`) and moves each out
along the shortest way to ``keep`` times its rest distance above the bone.

Local signs (the closest face's normal, angle-weighted pseudonormals) were tried first and
misjudge the fitted bone where the fit folds it (MakeHuman's orbits and jaw angles): they
pushed skin in. Parity counts crossings of the whole surface and is not misled by a fold.

The bones are rigid: each is tested in its rest pose, the skin brought into the bone's rest
frame, so the ray-casting structures are built once. Only vertices that may be inside are
cast: the distance to a rigid bone is 1-Lipschitz, so a vertex nearer than ``d0`` to where
its rest position went with the bone (``d0`` its rest distance) is still outside.
"""

from __future__ import annotations

import numpy as np

__all__ = ["BoneCollision"]


class BoneCollision:
    """Puts skin vertices found inside a rigid bone back out (see the module docstring).

    Parameters
    ----------
    rest : (n, 3) float, skin at rest (skin units)
    bodies : dict name -> (vertices (v, 3), faces (f, 3)), the bones at rest, closed
    reach : float, skin units: vertices outside a bone and within this of it at rest are guarded
    keep : float in [0, 1): a vertex put back out sits at ``keep * d0`` from the bone

    Attributes
    ----------
    guarded : dict name -> (vertex ids (k,) int, rest positions (k, 3) in the bone's rest frame,
        floor (k,), rest distance (k,))
    """

    def __init__(self, rest: np.ndarray, bodies: dict, reach: float, keep: float = 0.5):
        import trimesh

        rest = np.asarray(rest, dtype=np.float64).reshape(-1, 3)
        self.names, self.guarded, parts = [], {}, []
        self._shift = 0.0
        for name, (v, f) in bodies.items():
            mesh = trimesh.Trimesh(np.asarray(v, np.float64), np.asarray(f, np.int64), process=False)
            if not len(rest) or not len(mesh.faces):
                continue
            _, dist, _ = trimesh.proximity.closest_point(mesh, rest)
            inside = mesh.contains(rest)
            ids = np.flatnonzero((dist < reach) & (dist > 0.0) & ~inside)
            self.names.append(name)
            self.guarded[name] = (ids, rest[ids], keep * dist[ids], dist[ids])
            parts.append(mesh)
        # every bone in one intersector, each moved apart along z so that rays along +-x from
        # one bone's points never meet another: one ray query per pass
        size = max((float(np.ptp(m.vertices, axis=0).max()) for m in parts), default=0.0)
        self._offset = {n: np.array([0.0, 0.0, 4.0 * size * i]) for i, n in enumerate(self.names)}
        self._meshes = {n: m for n, m in zip(self.names, parts)}
        self._all = trimesh.util.concatenate([trimesh.Trimesh(m.vertices + self._offset[n], m.faces, process=False)
                                              for n, m in zip(self.names, parts)]) if parts else None

    def apply(self, positions: np.ndarray, transforms: dict) -> int:
        """Move the guarded vertices of ``positions`` ((n, 3) float, in place) that are inside a
        bone out of it. ``transforms``: name -> (4, 4) rigid transform of that bone from its rest
        pose (missing: identity). Returns how many moved."""
        import trimesh

        from faceforge.anatomy.animate import points_inside

        local, which = [], []
        for name in self.names:
            ids, rest, _, slack = self.guarded[name]
            t = np.asarray(transforms.get(name, np.eye(4)), dtype=np.float64)
            p = (positions[ids] - t[:3, 3]) @ t[:3, :3]          # into the bone's rest frame
            maybe = np.flatnonzero(np.sum((p - rest) ** 2, axis=1) >= slack * slack)
            local.append(p[maybe])
            which.append(maybe)
        if not sum(len(w) for w in which):
            return 0
        probe = np.vstack([p + self._offset[n] for p, n in zip(local, self.names)])
        inside = points_inside(probe, self._all.vertices, self._all.faces, mesh=self._all)
        moved, start = 0, 0
        for name, p, maybe in zip(self.names, local, which):
            hit = inside[start:start + len(p)]
            start += len(p)
            if not hit.any():
                continue
            ids, _, floor, _ = self.guarded[name]
            k = maybe[hit]
            q, d, _ = trimesh.proximity.closest_point(self._meshes[name], p[hit])
            out = q + floor[k, None] * (q - p[hit]) / np.maximum(d, 1e-300)[:, None]
            t = np.asarray(transforms.get(name, np.eye(4)), dtype=np.float64)
            positions[ids[k]] = out @ t[:3, :3].T + t[:3, 3]
            moved += len(k)
        return moved
