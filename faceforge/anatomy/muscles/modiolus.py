"""The modiolus: the orbicularis oris' corners ride on the muscles that insert there.

Beyond the paper (§5.2.2, §6.2). At each mouth corner the zygomaticus major, the risorius,
the depressor anguli oris (and, where a map has it, the levator anguli oris) insert into a
knot of fibres, the modiolus, which the orbicularis oris' corner fibres run through: the
corner moves with whichever of them pulls. In the layered map the sphincter's loops are
surface points on the muscles under them, so a corner sample follows only the one body its
closest point lies on: on MakeHuman the outer corner sits on the zygomaticus, so the depressor
anguli at full contraction moved its own insertion 511 MNS down but the ring's corner 47-74
(issue 25: the corners pulled down saturated at a quarter of the request); on ICT and
MediaPipe the corner lies on other bodies and the zygomaticus' 747-905 MNS reached the ring's
corner as 20-38.

:class:`Modiolus` ties the loops' points near each corner to the modiolus of that side: the
activation-weighted mean displacement of the inserting muscles' insertion ends (their last
row of particles, both sheets, already solved this frame: every one lies in a deeper layer),

    d_mod = sum_k c_k d_k / sum_k c_k,

and each loop point ``i`` of that side moves from its own surface point's displacement
``d_i`` towards it,

    d_i' = d_i + w_i g (d_mod - d_i),    g = min(1, sum_k c_k / ramp),

``w_i`` a smooth fall-off ``(1 - (r / R)^2)^2`` of the point's rest distance ``r`` from its
loop's corner (the loop point nearest the side's insertion ends), ``R = radius x`` the rest
distance between the two outer corners. With no inserting muscle active (the jaw alone, the
lips' own muscles) ``g = 0`` and the ring rides on what it lies on, as in the paper; ``g``
reaches 1 at ``sum c = ramp`` so the corner does not jump to a muscle whose contraction just
started. Everything is read from the rest and current world vertices: a symmetric rig (mirror
twin muscles) gets a symmetric modiolus.
"""

from __future__ import annotations

import numpy as np

from faceforge.constants import FLOAT, INT

#: default muscles inserting at the modiolus (a pair by its name without ``_L`` / ``_R``)
MODIOLUS_MUSCLES = ("zygomaticus_major", "risorius", "depressor_anguli", "levator_anguli")


class Modiolus:
    """The corners of one sphincter tied to the muscles that insert there (module docstring).

    Parameters
    ----------
    rest_lines : dict[str, (k, 3) float]
        The sphincter's loop points ("A1", "A3") at rest, world units.
    sides : list of (columns (m,) int, ends list of (p,) int)
        Per mouth corner: the inserting muscles' columns in the contraction array and the
        world vertex ids of each one's insertion end.
    rest_world : (N, 3) float
        The world vertices at rest.
    radius : float
        ``R`` as a fraction of the rest distance between the two outer corners.
    ramp : float
        Summed contraction at which the tie is full (``g = 1``).
    """

    def __init__(self, rest_lines: dict, sides: list, rest_world, radius: float, ramp: float):
        self.rest_lines = {k: np.asarray(v, FLOAT).copy() for k, v in rest_lines.items()}
        self.sides = [(np.asarray(cols, INT), [np.asarray(e, INT) for e in ends]) for cols, ends in sides]
        rest_world = np.asarray(rest_world, FLOAT)
        self.rest_ends = [np.array([rest_world[e].mean(axis=0) for e in ends]) for _, ends in self.sides]
        self.ramp = float(ramp)
        centres = [r.mean(axis=0) for r in self.rest_ends]
        outer = self.rest_lines.get("A3", next(iter(self.rest_lines.values())))
        corner_pts = [outer[int(np.argmin(np.linalg.norm(outer - c, axis=1)))] for c in centres]
        width = float(np.linalg.norm(corner_pts[0] - corner_pts[-1])) if len(corner_pts) > 1 else 1.0
        reach = max(radius * width, 1e-12)
        self.weights = {}
        for key, pts in self.rest_lines.items():
            w = []
            for cp in corner_pts:
                corner = pts[int(np.argmin(np.linalg.norm(pts - cp, axis=1)))]
                r = np.linalg.norm(pts - corner, axis=1) / reach
                w.append(np.clip(1.0 - r * r, 0.0, 1.0) ** 2)
            self.weights[key] = np.array(w)

    def displacement(self, side: int, world, contractions) -> tuple[np.ndarray, float]:
        """``(d_mod (3,), g)`` of corner ``side`` for the current ``world (N, 3)`` vertices and
        ``contractions`` (the system's control array); ``g = 0``: not tied this frame."""
        cols, ends = self.sides[side]
        c = np.clip(np.asarray(contractions, FLOAT)[cols], 0.0, None)
        total = float(c.sum())
        if total <= 0.0:
            return np.zeros(3), 0.0
        d = np.array([world[e].mean(axis=0) for e in ends]) - self.rest_ends[side]
        return (c[:, None] * d).sum(axis=0) / total, min(1.0, total / self.ramp)

    def apply(self, lines: dict, world, contractions) -> dict:
        """The loop points ``lines`` (key -> (k, 3), current) with the corners tied to the
        modiolus (new arrays; ``lines`` is not written)."""
        out = {k: np.array(v, FLOAT) for k, v in lines.items()}
        for side in range(len(self.sides)):
            d_mod, g = self.displacement(side, world, contractions)
            if g <= 0.0:
                continue
            for key, pts in out.items():
                if key not in self.weights:
                    continue
                own = pts - self.rest_lines[key]
                pts += (g * self.weights[key][side])[:, None] * (d_mod[None] - own)
        return out


def insertion_end(muscle) -> np.ndarray:
    """(2 w,) muscle-local particle ids of a linear muscle's insertion end: row ``h - 1`` of the
    bottom and the top sheet."""
    t = muscle.topology
    j = np.arange(t.w)
    return np.concatenate([t.bottom(t.h - 1, j), t.top(t.h - 1, j)]).astype(INT)


def attach_modiolus(system, sphincter: str = "orbicularis_oris", muscles=MODIOLUS_MUSCLES,
                    radius: float = 0.3, ramp: float = 0.1) -> Modiolus | None:
    """Tie ``sphincter``'s corners in ``system`` (a :class:`MusculoskeletalSystem`) to the
    ``muscles`` inserting at the modiolus (names without ``_L`` / ``_R``; those the map lacks
    are skipped). Returns the :class:`Modiolus` (also kept by the system, which applies it every
    frame), or None when the system has no such sphincter or no such muscle on both sides."""
    ms = system.muscles
    if sphincter not in ms or not muscles or radius <= 0.0:
        return None
    sides = []
    for suffix in ("_L", "_R"):
        names = [n + suffix for n in muscles if n + suffix in ms and ms[n + suffix].kind == "linear"]
        if not names:
            return None
        cols = [system.controls.index(n) for n in names]
        ends = [system.vertex_range(n).start + insertion_end(ms[n]) for n in names]
        sides.append((cols, ends))
    rest, _ = system.world(rest=True)
    lines = system.sphincter_lines(sphincter, rest)
    mod = Modiolus(lines, sides, rest, radius, ramp)
    system.set_modiolus(sphincter, mod)
    return mod
