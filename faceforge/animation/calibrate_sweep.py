"""Calibration as a sweep of warm-started, converged static poses (issue 25, items 1 and 2).

:func:`faceforge.animation.calibrate.calibrate_mapping` settles every probe from rest for a
fixed 30 frames (~110 s on the MakeHuman sample). This module fits the same response curves
in far fewer frames:

* **one chain per entry and sign**: the requested values of a side are met in increasing
  order, and each pose continues from the one before (:func:`faceforge.animation.statics.settle`
  with ``warm=True``): the drive moves a little, the skin follows in a few frames;
* **statics that stop at convergence**: a pose is held until the skin stops moving
  (``animate.statics.tolerance``), not for a fixed frame count;
* **secant steps on the samples so far**: the first pose of a chain is the uncalibrated
  drive, every later guess inverts the monotone curve of all samples of that chain
  (:func:`faceforge.animation.calibrate.invert_monotone`); a value stops once within
  ``tolerance`` of its request, when its drive is held (a saturated side) or after
  ``max_steps`` poses, keeping the best drive sampled;
* **no verification pass**: the knots are the sampled drives, so the achieved values are the
  ones measured at them.
* **stalled probes again, alone**: two lanes (:func:`face_lanes`) are probed in one
  simulation; a pairing can cancel a probe (with the frontalis in thirds, MakeHuman's lowered
  outer brow 35 and squeeze 37 read 0.4 and -0.3 ENS at every request, the sweep's fallback
  left them at 98-100 % error; alone they reach -34 and 63). An entry whose FDP moved less than
  :data:`STALL_FRACTION` of its smallest request on a chain (one sense) is probed again in a lane
  of its own.

The requests are the magnitudes users play (``animate.calibrate.magnitudes``, from the Xface
files' largest values per sign; :func:`requested_values`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from faceforge.animation.calibrate import (
    CalibrationRow, _frames, _monotone_knots, best_sampled, drive_cap, fap_group, full_drive,
    invert_monotone, measure, saturated)
from faceforge.animation.fap_mapping import with_entry


@dataclass
class Chain:
    """Samples of one entry on one side: drives (FAPU) and, per drive, each FAP's displacement
    (FAPU) and their mean (what the entry's one drive is fitted to)."""

    drives: list
    mean: list
    per_fap: list          # list of {fap: achieved}

    @classmethod
    def start(cls, faps):
        return cls([0.0], [0.0], [{f: 0.0 for f in faps}])


def fit_side(entry, pose, probes, rest, req: np.ndarray, caps: np.ndarray, knee: float,
             tolerance: float, max_steps: int):
    """Meet the requests ``req`` (r,) of one sign, in increasing size, on one warm chain.

    pose : callable (faps (68,) float, warm bool) -> settled skin (n, 3) with the entry's
        identity response (drive = FAP value)
    caps : (r,) float largest |drive| per request (:func:`drive_cap`); knee : the |drive| that
        puts every muscle of the side at full contraction (:func:`full_drive`)
    Returns (drives (r,) float, NaN where unreachable; the :class:`Chain` of samples).
    """
    return _run(_side_steps(entry, probes, rest, req, caps, knee, tolerance, max_steps), pose)


def _run(steps, pose):
    """Drive a generator of poses (it yields ``(faps, warm)``, is sent the settled skin) with
    ``pose``; its return value."""
    try:
        asked = next(steps)
        while True:
            asked = steps.send(pose(*asked))
    except StopIteration as stop:
        return stop.value


def _side_steps(entry, probes, rest, req, caps, knee, tolerance, max_steps):
    """:func:`fit_side` as a generator: yields ``(faps (68,), warm)``, is sent the skin."""
    observed = [f for f in entry.faps if f in probes]
    chain = Chain.start(observed)
    out = np.full(len(req), np.nan)
    warm = False
    for j in np.argsort(np.abs(req)):
        r = float(req[j])
        lim = min(float(caps[j]), knee)
        if len(chain.drives) == 1:
            d = r                                    # the uncalibrated drive
        else:
            d = _invert(chain, r)
        if not np.isfinite(d):
            continue                                 # this side never moved the FDP the asked way
        d = float(np.clip(d, -lim, lim))
        for _ in range(max_steps):
            skin = yield _frames(entry.faps, np.array([d]))[0], warm
            warm = True
            got = {f: float(measure(rest, skin, probes[f])) for f in observed}
            chain.drives.append(d)
            chain.per_fap.append(got)
            chain.mean.append(float(np.mean(list(got.values()))))
            if abs(chain.mean[-1] - r) <= tolerance * abs(r):
                break
            step = _invert(chain, r)
            if not np.isfinite(step):
                break
            step = float(np.clip(step, -lim, lim))
            if np.isclose(step, d, rtol=1e-6, atol=0.0):
                step = _past_stall(chain.mean[-1], d, r, lim)
            if np.isclose(step, d, rtol=1e-6, atol=0.0):
                break                                # held: the side is saturated
            d = step
        out[j] = best_sampled(np.asarray(chain.drives), np.asarray(chain.mean), np.array([r]),
                              np.array([chain.drives[-1]]), tolerance)[0]
    return out, chain


def _past_stall(got: float, d: float, r: float, lim: float) -> float:
    """The next drive when the chain's curve looks flat at drive ``d`` (FAPU, the FDP moved
    ``got`` of the request ``r``) but the side is not at full contraction (``|d| < lim``): the
    drive scaled by ``r / got`` (the secant through rest), at most ``lim``; ``d`` itself (held)
    when at ``lim`` or when ``got`` is not on ``r``'s side. A flat stretch between two samples
    is not saturation when other motion shifts them: on a mask the jaw and lip probes played
    beside the brows' (lanes) move the brow FDPs by up to 22 ENS (MediaPipe, open_jaw 713), and
    the brow raise 33/34 stopped at 27 of 100 ENS with its muscles at c = 0.24."""
    if abs(d) >= lim * (1.0 - 1e-9) or got * r <= 0.0 or abs(got) >= abs(r):
        return d
    return float(np.clip(d * r / got, -lim, lim))


def _invert(chain: Chain, r: float) -> float:
    """The drive the chain's samples (one per distinct drive: repeats averaged) put at ``r``
    (:func:`invert_monotone`; NaN when they never moved the FDP that way)."""
    d = np.asarray(chain.drives[1:])
    a = np.asarray(chain.mean[1:])
    u, inv = np.unique(d, return_inverse=True)
    mean = np.bincount(inv, weights=a) / np.bincount(inv)
    return float(invert_monotone(u, mean, np.array([r]))[0])


def calibrate_sweep(mapping, pose_for, rest, probes: dict, requested: dict, tolerance: float = 0.02,
                    max_steps: int = 4, max_drive: float = 20.0, lanes=None, skip=(), progress=None):
    """Fit every entry's response curve on warm chains of converged poses.

    mapping : FapMapping (its response curves are ignored)
    pose_for : callable (mapping, faps (68,) float, warm bool) -> settled skin (n, 3) float
    rest : (n, 3) float; probes : FAP -> Probe; requested : lead FAP -> requested values (FAPU)
    tolerance : relative error at which a request counts as met (default 2 %)
    max_steps : poses per request at most
    lanes : lists of entry indices whose entries do not interact (far apart on the face, no
        muscle in common: :func:`face_lanes`); one entry of each lane is probed in the same
        simulation, the lanes' FAPs played together (default: one lane, one entry at a time)
    skip : entry indices not probed (their responses are left as they are)
    Returns (calibrated FapMapping, list of CalibrationRow), as
    :func:`faceforge.animation.calibrate.calibrate_mapping`. ``achieved_before`` (uncalibrated)
    is read off the sampled curve at drive = request (linear interpolation of the chain).
    """
    todo = [i for i, e in enumerate(mapping.entries)
            if i not in skip and e.faps[0] in probes and np.any(np.asarray(requested.get(e.faps[0], []), dtype=float) != 0.0)]
    lanes = [todo] if lanes is None else [[i for i in lane if i in todo] for lane in lanes]
    done = {}
    tick = progress(range(len(todo))) if progress else None
    ticks = iter(tick) if tick is not None else None
    gens = [_lane(lane, mapping, probes, rest, requested, tolerance, max_steps, max_drive, done, ticks)
            for lane in lanes if lane]
    _play_lanes(gens, mapping, pose_for)
    stalled = [i for i in sorted(done) if len(gens) > 1 and _stalled(*done[i])]
    if stalled:   # probed again alone (lanes' pairings can cancel a probe; module docstring)
        _play_lanes([_lane(stalled, mapping, probes, rest, requested, tolerance, max_steps, max_drive, done,
                           None)], mapping, pose_for)
    rows, calibrated = [], mapping
    for idx in sorted(done):
        req, drive, chains = done[idx]
        ok = np.isfinite(drive)
        knots = _monotone_knots(np.column_stack([req, np.where(ok, drive, 0.0)]))
        reach, knots = muscle_reach(mapping.entries[idx], chains, knots)
        calibrated = with_entry(calibrated, idx, response=knots, muscle_reach=reach)
        rows += _rows(mapping.entries[idx], calibrated, req, drive, ok, knots, chains, probes)
    return calibrated, rows


def _play_lanes(gens, mapping, pose_for) -> None:
    """Run the lanes' generators (:func:`_lane`) to the end, one simulation per step: every
    lane's current entry, their FAPs played together."""
    asked = {}
    for k, g in enumerate(gens):
        try:
            asked[k] = next(g)
        except StopIteration:
            pass
    while asked:
        identity, faps, warm = mapping, np.zeros(68), True
        for idx, f, w in asked.values():
            identity = with_entry(identity, idx, response=None, muscle_reach=None)   # the muscles alone
            faps, warm = faps + f, warm and w
        skin = pose_for(identity, faps, warm)
        for k in list(asked):
            try:
                asked[k] = gens[k].send(skin)
            except StopIteration:
                del asked[k]


#: a probe whose FDP moved less than this fraction of its smallest request (of one sense) at
#: every drive of that sense was cancelled, not probed (:func:`_stalled`)
STALL_FRACTION = 0.1


def _stalled(req, drive, chains) -> bool:
    """Whether an entry's probes of one sense moved its FDP less than :data:`STALL_FRACTION`
    of that sense's smallest |request| (req (k,) FAPU) at every drive (chains: sense -> chain
    with ``mean``, FAPU)."""
    req = np.asarray(req, float)
    for sense, chain in chains.items():
        r = np.abs(req[np.sign(req) == sense])
        if chain is None or not len(chain.mean) or not len(r):
            continue
        if np.max(np.abs(np.asarray(chain.mean, float))) < STALL_FRACTION * float(np.min(r)):
            return True
    return False


def _lane(indices, mapping, probes, rest, requested, tolerance, max_steps, max_drive, done, ticks):
    """The entries of one lane, one after the other, as a generator of poses: yields
    ``(entry index, faps (68,), warm)``, is sent the skin; puts ``(requests, drives, chains)``
    into ``done[index]``."""
    for idx in indices:
        entry = mapping.entries[idx]
        req = np.asarray(requested[entry.faps[0]], dtype=float)
        req = req[req != 0.0]
        drive, chains = np.full(len(req), np.nan), {}
        cap = drive_cap(entry, req, max_drive, mapping.max_contraction)
        for sense in (1.0, -1.0):
            sel = np.flatnonzero(np.sign(req) == sense)
            if len(sel) == 0:
                continue
            knee = full_drive(entry, sense, mapping.max_contraction)
            steps = _side_steps(entry, probes, rest, req[sel], cap[sel], knee, tolerance, max_steps)
            try:
                faps, warm = next(steps)
                while True:
                    skin = yield idx, faps, warm
                    faps, warm = steps.send(skin)
            except StopIteration as stop:
                drive[sel], chains[sense] = stop.value
        done[idx] = (req, drive, chains)
        if ticks is not None:
            next(ticks, None)


def muscle_reach(entry, chains: dict, knots: np.ndarray):
    """(reach, knots) for an entry the jaw helps (``entry.muscle_reach`` set): the farthest its
    muscles moved the FDP on the chain of the jaw's sense (the sign of its coupling ratio), in
    FAPU, and the knots with ``(sense x reach, the drive that got there)`` added, so that the
    remainder :func:`~faceforge.animation.fap_mapping.jaw_assisted` leaves to the muscles (at
    most the reach) drives them as far as they went. Other entries: (their reach, knots)."""
    if entry.muscle_reach is None or not entry.coupling:
        return entry.muscle_reach, knots
    sense = float(np.sign(next(iter(entry.coupling.values()))))
    chain = chains.get(sense)
    if chain is None or len(chain.mean) < 2:
        return entry.muscle_reach, knots
    got = sense * np.asarray(chain.mean[1:])
    k = int(np.argmax(got))
    if got[k] <= 0.0:
        return 0.0, knots
    reach = float(got[k])
    if not np.any(np.isclose(knots[:, 0], sense * reach)):
        knots = _monotone_knots(np.vstack([knots, [sense * reach, chain.drives[1 + k]]]))
    return reach, knots


def face_lanes(mapping) -> list:
    """Two lanes of entries that do not interact: the brows (the upper face), and everything
    else (the jaw, which carries the lower lip and enters the lip entries' couplings, the lips,
    the cheeks). Entry indices per lane. (The cheek lift 41/42 was tried in the brows' lane
    (cheek5): with the other branches of 2026-11-28 merged it paired MakeHuman's middle-brow
    lowering 33/34 with another probe that cancelled it, 0.3 ENS at every request, and the
    played -35 came out -0.7; in this lane 33 reaches -42, 35 -34 and 37 60 of 80.)
    """
    from faceforge.animation.calibrate import EYEBROW_FAPS

    upper = [i for i, e in enumerate(mapping.entries) if set(e.faps) <= set(EYEBROW_FAPS)]
    return [upper, [i for i in range(len(mapping.entries)) if i not in upper]]


def _rows(entry, calibrated, req, drive, ok, knots, chains, probes):
    """Report rows for every FAP of ``entry`` and request: achieved at the knot's drive (the
    sample taken there; a knot the monotone pass moved off its samples is read off the chain's
    curve), and uncalibrated (the chain's curve at drive = request)."""
    rows = []
    for fap in entry.faps:
        if fap not in probes:
            continue
        for j, r in enumerate(req):
            chain = chains.get(float(np.sign(r)))
            knot = float(np.interp(r, knots[:, 0], knots[:, 1]))
            achieved, before = (np.nan, np.nan) if chain is None else _read(chain, fap, knot, r)
            if not ok[j]:
                achieved = 0.0 if chain is None else achieved
            rows.append(CalibrationRow(fap, entry.name, fap_group(fap), float(r), before, achieved,
                                       float(drive[j]) if ok[j] else float("nan"),
                                       saturated(entry, knot, calibrated.max_contraction)))
    return rows


def _read(chain: Chain, fap: int, knot: float, r: float):
    """(achieved at drive ``knot``, achieved at drive ``r``) of ``fap`` on ``chain``: the sample
    itself where one was taken, else linear interpolation along the sampled drives."""
    d = np.asarray(chain.drives)
    a = np.asarray([p.get(fap, 0.0) for p in chain.per_fap])
    order = np.argsort(np.abs(d))
    d, a = d[order], a[order]

    def at(x):
        hit = np.flatnonzero(np.isclose(d, x, rtol=1e-9, atol=0.0))
        if len(hit):
            return float(a[hit[-1]])
        return float(np.interp(abs(x), np.abs(d), a))
    return at(knot), at(r)
