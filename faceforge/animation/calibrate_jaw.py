"""Calibrate how far the jaw helps the lower lip (issue 25): each entry's ``muscle_reach``.

MPEG-4's lower-lip FAPs are absolute displacements of the lip, and the Xface files lower it
1.1-1.3 x open_jaw (-870 MNS with open_jaw 712): more than the lip's depressors can give. The
mapping therefore opens the jaw for a lip asked past its muscles' reach
(:func:`faceforge.animation.fap_mapping.jaw_assisted`): open_jaw becomes the larger of the
file's value and ``(|v| - muscle_reach) / |coupling|``.

The depressors move the lip further on an open jaw than on a closed one (the sweep measures
the closed-jaw reach, :func:`faceforge.animation.calibrate_sweep.muscle_reach`: MakeHuman's
lower lip 128 MNS, but with the jaw open 712 MNS the lip still lands on -870): with the closed
reach the jaw opened too far (the lip 12 % past -870, open_jaw 21 % past 713 in the Xface
frame). :func:`fit_muscle_reach` plays each entry alone at its largest request of the jaw's
sense, with the assist, and moves the reach by the lip's overshoot (less jaw when the lip
goes too far), a secant step on the reach, until the lip lands within ``tolerance``.
"""

from __future__ import annotations

import numpy as np

from faceforge.animation.calibrate import _frames, measure
from faceforge.animation.fap_mapping import with_entry


def fit_muscle_reach(mapping, simulate, rest: np.ndarray, probes: dict, requested: dict,
                     tolerance: float = 0.02, steps: int = 2, log=lambda m: None):
    """``mapping`` with each jaw-assisted entry's ``muscle_reach`` fitted on the head.

    simulate : callable (mapping, faps (k, 68)) -> settled skins (k, n, 3) from rest
    rest : (n, 3) float; probes : FAP -> Probe; requested : lead FAP -> (r,) FAPU requests
    For each entry with a ``muscle_reach`` and a coupling, its largest request ``r`` of the
    coupling's sense is played alone (at most ``steps`` poses): the reach grows by the lip's
    overshoot past ``r`` (FAPU; the jaw opens that much less) and shrinks by its shortfall,
    never below 0. Returns (mapping, {entry name: (reach, achieved FAPU at r)}).
    """
    report = {}
    for idx, e in enumerate(mapping.entries):
        if e.muscle_reach is None or not e.coupling or e.faps[0] not in requested:
            continue
        observed = [probes[f] for f in e.faps if f in probes]
        sense = float(np.sign(next(iter(e.coupling.values()))))
        req = np.asarray(requested[e.faps[0]], dtype=float)
        req = req[np.sign(req) == sense]
        if not observed or len(req) == 0:
            continue
        r = float(req[np.argmax(np.abs(req))])
        reach = float(e.muscle_reach)
        got = np.nan
        for _ in range(steps):
            trial = with_entry(mapping, idx, muscle_reach=reach)
            skin = simulate(trial, _frames(e.faps, np.array([r])))
            got = float(np.mean([measure(rest, skin, p)[0] for p in observed]))
            over = sense * (got - r)              # > 0: the lip went past the request
            if abs(over) <= tolerance * abs(r):
                break
            reach = max(0.0, reach + over)
        mapping = with_entry(mapping, idx, muscle_reach=reach)
        report[e.name] = (reach, got)
        log(f"  {e.name}: muscle reach {reach:.0f} {e.fapu} (the jaw opens for the rest of {r:.0f}; "
            f"last pose {got:.0f})")
    return mapping, report
