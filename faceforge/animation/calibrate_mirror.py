"""Calibration on a symmetric rig: each right entry plays its left twin's response (issue 25).

On a head whose rig is symmetric by construction (the fitted bone, the muscles and the skin's
solver order are mirror images, :mod:`faceforge.fit.symmetry`, :mod:`faceforge.pbd.colouring`),
an entry and its mirror twin (``raise_l_cornerlip`` and ``raise_r_cornerlip``: the mirrored FAPs,
the mirrored muscles at the same gains) move the skin as mirror images. Calibrating both
separately measured the same response twice, and two independent fits of it disagreed: a
right entry whose probe chain stalled played 33 times its twin's motion (squeeze, MakeHuman).
Here only the left entry is probed, at the requests of both twins, and the right one takes its
response curve; the calibration costs one entry less per pair. Whether the two sides then
agree is measured from the exported frames (``benchmarks/bench_fap_played.py``,
``bench_mirror.py``), not assumed.

MPEG-4 defines the left and right FAPs of a pair as mirror images (both corners up, both
outward, ...: the FAP table's directions are mirrored in x for every translation pair).
"""

from __future__ import annotations

import numpy as np

from faceforge.animation.fap_mapping import FapEntry, FapMapping, with_entry


def fap_twins() -> dict[int, int]:
    """Subject-left FAP number -> its right twin's, for the standard's left/right translation
    pairs (``stretch_l_cornerlip`` 6 -> 7, ``raise_b_lip_lm`` 10 -> 11, ...)."""
    from faceforge.mpeg4.tables import FAP_DIRECTIONS, FAP_TABLE

    number = {r.name: i + 1 for i, r in enumerate(FAP_TABLE)}
    twins = {}
    for i, r in enumerate(FAP_TABLE):
        for left, right in (("_l_", "_r_"), ("_lm", "_rm"), ("_l", "_r")):
            other = r.name.replace(left, right, 1)
            if left in r.name and other in number:
                j = number[other] - 1
                d = FAP_DIRECTIONS[i] * np.array([-1.0, 1.0, 1.0])
                if np.all(np.isfinite(d)) and np.allclose(d, FAP_DIRECTIONS[j]):
                    twins[i + 1] = j + 1
                break
    return twins


def _mirrored(entry: FapEntry, twins: dict[int, int]) -> FapEntry:
    """``entry`` as its mirror twin would read: FAPs, muscles, couplings and measured FDPs
    moved to their twins (midline ones stay)."""
    from dataclasses import replace

    from faceforge.anatomy.muscles.muscle_map import mirrored_name
    from faceforge.animation.fap_mapping import Measure
    from faceforge.mpeg4.tables import LEFT_RIGHT_PAIRS

    fdp = {a: b for pair in LEFT_RIGHT_PAIRS for a, b in (pair, pair[::-1])}

    def muscles(d):
        return {mirrored_name(k): v for k, v in d.items()}

    def fap(f):
        return twins.get(int(f), int(f))

    return replace(entry, faps=tuple(fap(f) for f in entry.faps),
                   positive=muscles(entry.positive), negative=muscles(entry.negative),
                   coupling={fap(f): r for f, r in entry.coupling.items()},
                   measure={fap(f): Measure(fdp.get(m.fdp, m.fdp),
                                            None if m.relative_to is None else fdp.get(m.relative_to, m.relative_to))
                            for f, m in entry.measure.items()})


def entry_twins(mapping: FapMapping) -> dict[int, int]:
    """Right entry index -> its left twin's index, for the entries whose mirror image (FAPs,
    muscles and gains, couplings, measured FDPs) is another entry of ``mapping`` exactly. The
    left one is the entry of the subject-left FAP (MPEG-4's ``_l`` names). Jaw entries and
    midline entries have no twin."""
    left = fap_twins()
    twins = {**left, **{r: l for l, r in left.items()}}
    by_faps = {tuple(e.faps): i for i, e in enumerate(mapping.entries)}
    out = {}
    for i, e in enumerate(mapping.entries):
        if e.jaw is not None or not all(f in left for f in e.faps):
            continue
        m = _mirrored(e, twins)
        j = by_faps.get(tuple(m.faps))
        if j is None or j == i:
            continue
        other = mapping.entries[j]
        if (other.positive, other.negative, other.coupling, other.measure, other.jaw) == \
                (m.positive, m.negative, m.coupling, m.measure, m.jaw):
            out[j] = i
    return out


def joint_requests(mapping: FapMapping, twins: dict[int, int], requested: dict) -> dict:
    """``requested`` (lead FAP -> requested values, FAPU) with each left lead FAP asked for its
    own and its right twin's values, so that the left response covers both sides' requests."""
    out = dict(requested)
    for right, left in twins.items():
        a, b = mapping.entries[left].faps[0], mapping.entries[right].faps[0]
        both = np.concatenate([np.atleast_1d(np.asarray(requested.get(a, []), dtype=float)),
                               np.atleast_1d(np.asarray(requested.get(b, []), dtype=float))])
        out[a] = np.unique(both)
    return out


def mirror_responses(calibrated: FapMapping, twins: dict[int, int]) -> FapMapping:
    """Each right entry of ``twins`` with its left twin's response curve."""
    for right, left in twins.items():
        knots = calibrated.entries[left].response
        calibrated = with_entry(calibrated, right, response=None if knots is None else np.array(knots),
                                muscle_reach=calibrated.entries[left].muscle_reach)
    return calibrated
