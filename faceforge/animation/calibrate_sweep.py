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
            skin = pose(_frames(entry.faps, np.array([d]))[0], warm)
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
                break                                # held: the side is saturated
            d = step
        out[j] = best_sampled(np.asarray(chain.drives), np.asarray(chain.mean), np.array([r]),
                              np.array([chain.drives[-1]]), tolerance)[0]
    return out, chain


def _invert(chain: Chain, r: float) -> float:
    """The drive the chain's samples (one per distinct drive: repeats averaged) put at ``r``
    (:func:`invert_monotone`; NaN when they never moved the FDP that way)."""
    d = np.asarray(chain.drives[1:])
    a = np.asarray(chain.mean[1:])
    u, inv = np.unique(d, return_inverse=True)
    mean = np.bincount(inv, weights=a) / np.bincount(inv)
    return float(invert_monotone(u, mean, np.array([r]))[0])


def calibrate_sweep(mapping, pose_for, rest, probes: dict, requested: dict, tolerance: float = 0.02,
                    max_steps: int = 4, max_drive: float = 20.0, progress=None):
    """Fit every entry's response curve on warm chains of converged poses.

    mapping : FapMapping (its response curves are ignored)
    pose_for : callable (mapping, faps (68,) float, warm bool) -> settled skin (n, 3) float
    rest : (n, 3) float; probes : FAP -> Probe; requested : lead FAP -> requested values (FAPU)
    tolerance : relative error at which a request counts as met (default 2 %)
    max_steps : poses per request at most
    Returns (calibrated FapMapping, list of CalibrationRow), as
    :func:`faceforge.animation.calibrate.calibrate_mapping`. ``achieved_before`` (uncalibrated)
    is read off the sampled curve at drive = request (linear interpolation of the chain).
    """
    rows, calibrated = [], mapping
    indices = range(len(mapping.entries))
    for idx in (progress(indices) if progress else indices):
        entry = mapping.entries[idx]
        lead = entry.faps[0]
        if lead not in probes or lead not in requested:
            continue
        req = np.asarray(requested[lead], dtype=float)
        req = req[req != 0.0]
        if len(req) == 0:
            continue
        identity = with_entry(calibrated, idx, response=None)

        def pose(faps, warm, identity=identity):
            return pose_for(identity, faps, warm)
        drive = np.full(len(req), np.nan)
        chains = {}
        cap = drive_cap(entry, req, max_drive, calibrated.max_contraction)
        for sense in (1.0, -1.0):
            sel = np.flatnonzero(np.sign(req) == sense)
            if len(sel) == 0:
                continue
            knee = full_drive(entry, sense, calibrated.max_contraction)
            drive[sel], chains[sense] = fit_side(entry, pose, probes, rest, req[sel], cap[sel], knee,
                                                 tolerance, max_steps)
        ok = np.isfinite(drive)
        knots = _monotone_knots(np.column_stack([req, np.where(ok, drive, 0.0)]))
        calibrated = with_entry(calibrated, idx, response=knots)
        rows += _rows(entry, calibrated, req, drive, ok, knots, chains, probes)
    return calibrated, rows


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
