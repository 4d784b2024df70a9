"""The modiolus and the lips' ties: the orbicularis oris' loop points ride on the muscles that
insert into them (the corners on the modiolus, a lip on its depressor or levator).

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

:class:`LipTie` does the same for a lip and one muscle pair inserting into it (issue 25): the
depressor labii inferioris inserts into the lower lip's skin and the orbicularis' lower fibres,
but in the layered map the lower lip's skin is bound to the ring, whose loop points lie on the
mentalis and the bone, so the depressor at full contraction moved the lower lip 1.9 mm at most
(its column 1/80 of the depressor anguli's; docs/notes/mouthunits12.md). Its ties use the same
pull ``d_mod`` and ramp ``g``; the points tied are those of the lip the insertions lie on
(:func:`lip_arc`: the loop split at its corners by the loop's order, since the inner loop's two
lips touch when the mouth is closed) within ``R`` of the lip's point nearest each side's
insertion end, with the same fall-off, ``R = radius x`` the outer loop's width. The shared
machinery is :class:`LoopTie`; the system applies a ring's ties in the order they were added
(the modiolus first), each moving its points from where the previous left them.
"""

from __future__ import annotations

import numpy as np

from faceforge.constants import FLOAT, INT

#: default muscles inserting at the modiolus (a pair by its name without ``_L`` / ``_R``)
MODIOLUS_MUSCLES = ("zygomaticus_major", "risorius", "depressor_anguli", "levator_anguli")


def falloff(r) -> np.ndarray:
    """``(1 - r^2)^2`` for ``r (...)`` < 1, else 0: the ties' smooth fall-off over the rest
    distance ``r`` in units of the reach."""
    r = np.asarray(r, FLOAT)
    return np.clip(1.0 - r * r, 0.0, 1.0) ** 2


class LoopTie:
    """Loop points of one sphincter tied to the insertion ends of the muscles inserting into
    them, one group per side (module docstring); the subclasses choose which points and how
    much (:meth:`_weights`).

    Parameters
    ----------
    rest_lines : dict[str, (k, 3) float]
        The sphincter's loop points ("A1", "A3") at rest, world units.
    sides : list of (columns (m,) int, ends list of (p,) int)
        Per side: the inserting muscles' columns in the contraction array and the world vertex
        ids of each one's insertion end.
    rest_world : (N, 3) float
        The world vertices at rest.
    radius : float
        ``R`` as a fraction of the mouth's width (:meth:`_weights`).
    ramp : float
        Summed contraction at which the tie is full (``g = 1``).
    """

    def __init__(self, rest_lines: dict, sides: list, rest_world, radius: float, ramp: float):
        self.rest_lines = {k: np.asarray(v, FLOAT).copy() for k, v in rest_lines.items()}
        self.sides = [(np.asarray(cols, INT), [np.asarray(e, INT) for e in ends]) for cols, ends in sides]
        rest_world = np.asarray(rest_world, FLOAT)
        self.rest_ends = [np.array([rest_world[e].mean(axis=0) for e in ends]) for _, ends in self.sides]
        self.ramp = float(ramp)
        #: key -> (sides, k) share of each side's pull per loop point
        self.weights = self._weights([r.mean(axis=0) for r in self.rest_ends], float(radius))

    def _weights(self, centres: list, radius: float) -> dict:   # pragma: no cover - abstract
        raise NotImplementedError

    def displacement(self, side: int, world, contractions) -> tuple[np.ndarray, float]:
        """``(d_mod (3,), g)`` of side ``side`` for the current ``world (N, 3)`` vertices and
        ``contractions`` (the system's control array); ``g = 0``: not tied this frame."""
        cols, ends = self.sides[side]
        c = np.clip(np.asarray(contractions, FLOAT)[cols], 0.0, None)
        total = float(c.sum())
        if total <= 0.0:
            return np.zeros(3), 0.0
        d = np.array([world[e].mean(axis=0) for e in ends]) - self.rest_ends[side]
        return (c[:, None] * d).sum(axis=0) / total, min(1.0, total / self.ramp)

    def apply(self, lines: dict, world, contractions) -> dict:
        """The loop points ``lines`` (key -> (k, 3), current) with the tied points moved toward
        their sides' pull (new arrays; ``lines`` is not written). Where both sides reach a point
        (a lip's middle) it moves toward their weighted mean, ``d_i' = d_i + sum_s g_s w_si (d_s
        - d_i) / max(1, sum_s g_s w_si)``: the same for either side's order, so a symmetric rig
        stays symmetric; where one side alone reaches it, the module docstring's formula."""
        out = {k: np.array(v, FLOAT) for k, v in lines.items()}
        pulls = [self.displacement(side, world, contractions) for side in range(len(self.sides))]
        if all(g <= 0.0 for _, g in pulls):
            return out
        for key, pts in out.items():
            if key not in self.weights:
                continue
            own = pts - self.rest_lines[key]
            step = np.zeros_like(pts)
            total = np.zeros(len(pts))
            for side, (d_mod, g) in enumerate(pulls):
                if g <= 0.0:
                    continue
                gw = g * self.weights[key][side]
                step += gw[:, None] * (d_mod[None] - own)
                total += gw
            pts += step / np.maximum(total, 1.0)[:, None]
        return out


class Modiolus(LoopTie):
    """The corners of one sphincter tied to the muscles inserting at the modiolus: the loop
    points within ``R`` of each corner (the loop point nearest the side's insertion ends), ``R =
    radius x`` the rest distance between the two outer corners (module docstring)."""

    def _weights(self, centres: list, radius: float) -> dict:
        outer = self.rest_lines.get("A3", next(iter(self.rest_lines.values())))
        corner_pts = [outer[int(np.argmin(np.linalg.norm(outer - c, axis=1)))] for c in centres]
        width = float(np.linalg.norm(corner_pts[0] - corner_pts[-1])) if len(corner_pts) > 1 else 1.0
        reach = max(radius * width, 1e-12)
        weights = {}
        for key, pts in self.rest_lines.items():
            w = []
            for cp in corner_pts:
                corner = pts[int(np.argmin(np.linalg.norm(pts - cp, axis=1)))]
                w.append(falloff(np.linalg.norm(pts - corner, axis=1) / reach))
            weights[key] = np.array(w)
        return weights


def lip_arc(points, axis, lower: bool) -> np.ndarray:
    """``(k,)`` float mask of the closed loop ``points (k, 3)`` (in loop order): 1 on the open arc
    between its two extremes along ``axis (3,)`` (the mouth's corners) whose mean lies lower
    (``lower``) or higher along +Y (up, the frame's convention), 0 on the other arc and at the
    two corners. A loop's upper and lower lip by the loop's order, not by each point's height:
    the inner loop's two lips touch when the mouth is closed."""
    p = np.asarray(points, FLOAT)
    k = len(p)
    s = p @ np.asarray(axis, FLOAT)
    i0, i1 = int(np.argmin(s)), int(np.argmax(s))
    idx = np.arange(k)
    first = (idx - i0) % k < (i1 - i0) % k      # from i0 (included) toward i1 (excluded) in loop order
    first[i0] = False
    second = ~first
    second[[i0, i1]] = False
    if not first.any() or not second.any():
        return np.zeros(k)
    below = p[first, 1].mean() < p[second, 1].mean()
    return (first if below == bool(lower) else second).astype(FLOAT)


class LipTie(LoopTie):
    """One lip of a sphincter tied to a muscle pair inserting into it (a depressor labii
    inferioris into the lower lip, a levator labii into the upper one): on each loop, the points
    of that lip (:func:`lip_arc`, split across the axis between the two sides' insertions)
    within ``R`` of the lip's point nearest each side's insertion end, ``R = radius x`` the
    outer loop's width along that axis. ``lower``: the lower lip (else the upper one); the
    other parameters as :class:`LoopTie`'s. Which lip is not guessed from where the insertions
    lie: on MakeHuman the outer loop reaches the chin, and the upper lip's arc lay nearer the
    depressor's insertion than the lower lip's (the tie pulled the upper lip down 6.5 mm)."""

    def __init__(self, rest_lines: dict, sides: list, rest_world, radius: float, ramp: float,
                 lower: bool = True):
        self.lower = bool(lower)
        super().__init__(rest_lines, sides, rest_world, radius, ramp)

    def _weights(self, centres: list, radius: float) -> dict:
        if len(centres) > 1:
            axis = centres[0] - centres[-1]
            axis = axis / max(float(np.linalg.norm(axis)), 1e-300)
        else:
            axis = np.array([1.0, 0.0, 0.0])
        outer = self.rest_lines.get("A3", next(iter(self.rest_lines.values())))
        reach = max(radius * float(np.ptp(outer @ axis)), 1e-12)
        weights = {}
        for key, pts in self.rest_lines.items():
            arc = lip_arc(pts, axis, self.lower)
            w = []
            for c in centres:
                on = np.flatnonzero(arc > 0.0)
                if not len(on):
                    w.append(np.zeros(len(pts)))
                    continue
                anchor = pts[on[int(np.argmin(np.linalg.norm(pts[on] - c, axis=1)))]]
                w.append(arc * falloff(np.linalg.norm(pts - anchor, axis=1) / reach))
            weights[key] = np.array(w)
        return weights


def insertion_end(muscle) -> np.ndarray:
    """(2 w,) muscle-local particle ids of a linear muscle's insertion end: row ``h - 1`` of the
    bottom and the top sheet."""
    t = muscle.topology
    j = np.arange(t.w)
    return np.concatenate([t.bottom(t.h - 1, j), t.top(t.h - 1, j)]).astype(INT)


def _sides(system, muscles) -> list | None:
    """Per side (``_L``, ``_R``) of ``system``: the columns and world insertion-end vertex ids of
    the linear ``muscles`` (names without the suffix) it has; None when a side has none."""
    ms = system.muscles
    sides = []
    for suffix in ("_L", "_R"):
        names = [n + suffix for n in muscles if n + suffix in ms and ms[n + suffix].kind == "linear"]
        if not names:
            return None
        cols = [system.controls.index(n) for n in names]
        ends = [system.vertex_range(n).start + insertion_end(ms[n]) for n in names]
        sides.append((cols, ends))
    return sides


def attach_modiolus(system, sphincter: str = "orbicularis_oris", muscles=MODIOLUS_MUSCLES,
                    radius: float = 0.3, ramp: float = 0.1) -> Modiolus | None:
    """Tie ``sphincter``'s corners in ``system`` (a :class:`MusculoskeletalSystem`) to the
    ``muscles`` inserting at the modiolus (names without ``_L`` / ``_R``; those the map lacks
    are skipped). Returns the :class:`Modiolus` (also kept by the system, which applies it every
    frame), or None when the system has no such sphincter or no such muscle on both sides."""
    if sphincter not in system.muscles or not muscles or radius <= 0.0:
        return None
    sides = _sides(system, muscles)
    if sides is None:
        return None
    rest, _ = system.world(rest=True)
    mod = Modiolus(system.sphincter_lines(sphincter, rest), sides, rest, radius, ramp)
    system.add_loop_tie(sphincter, mod)
    return mod


#: default muscles whose lip rides on their insertion (``muscle.sphincter.lip_ties.lower``)
LIP_TIE_LOWER = ("depressor_labii_inferioris",)


def attach_lip_ties(system, sphincter: str = "orbicularis_oris", lower=LIP_TIE_LOWER, upper=(),
                    radius: float = 0.25, ramp: float = 0.1) -> list:
    """Tie the lower lip of ``sphincter`` in ``system`` to each muscle pair of ``lower`` and its
    upper lip to each pair of ``upper`` (names without ``_L`` / ``_R``; :class:`LipTie`, one per
    pair, applied after the modiolus in that order). Returns the ties (also kept by the system).
    A pair the muscle map lacks (a linear ``name_L`` and ``name_R``) is a
    :class:`faceforge.exceptions.ConfigError`: the user named it."""
    if sphincter not in system.muscles or radius <= 0.0:
        return []
    from faceforge.exceptions import ConfigError

    rest, _ = system.world(rest=True)
    lines = system.sphincter_lines(sphincter, rest)
    ties = []
    for names, is_lower in ((lower, True), (upper, False)):
        for name in names:
            sides = _sides(system, (name,))
            if sides is None:
                key = f"muscle.sphincter.lip_ties.{'lower' if is_lower else 'upper'}"
                raise ConfigError(f"{key}: the muscle map has no linear pair {name}_L / {name}_R")
            tie = LipTie(lines, sides, rest, radius, ramp, lower=is_lower)
            system.add_loop_tie(sphincter, tie)
            ties.append(tie)
    return ties
