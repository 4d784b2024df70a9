"""Calibrate the FAP mapping: make requested and achieved FAP displacements agree (§9).

The paper claims the FAP -> contraction mapping is precise because the contraction ``c``
sets the fibre length (§5.2). This module measures it. For every entry of the mapping it
applies the entry's FAPs alone at a few *drives* on the bound head (through a
``simulate`` callable that returns the settled skin), measures how far the FAP's FDP
moved along the FAP's direction in FAPU, and inverts the sampled (monotone, usually
nonlinear: fibres bunch, contractions clip, skin lags its anchors) drive -> displacement
curve. The inverse becomes the entry's ``response`` knots (requested -> drive). A couple of
secant refinements per requested value correct what linear interpolation misses, and a
final pass measures what the calibrated mapping achieves: that is the report.

Everything here works on arrays and callables; the pipeline stage supplies the head,
the FAP table (direction, unit, FDP of each FAP) and the FAPU.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from faceforge.animation.fap_mapping import FapMapping, with_entry
from faceforge.mpeg4.tables import N_FAPS

#: FAP groups the acceptance criterion is computed over (MPEG-4 FAP numbers)
JAW_FAPS = (3, 14, 15)
LIP_FAPS = (4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 16, 17, 18, 51, 52, 53, 54, 55, 56, 57, 58, 59, 60)
CHEEK_FAPS = (39, 40, 41, 42)
EYEBROW_FAPS = (31, 32, 33, 34, 35, 36, 37, 38)


def fap_group(fap: int) -> str:
    """'jaw' | 'lip' | 'cheek' | 'eyebrow' | 'other' for a FAP number."""
    for name, faps in (("jaw", JAW_FAPS), ("lip", LIP_FAPS), ("cheek", CHEEK_FAPS),
                       ("eyebrow", EYEBROW_FAPS)):
        if fap in faps:
            return name
    return "other"


@dataclass(frozen=True)
class Probe:
    """How to observe one FAP on the skin.

    vertex : skin vertex index of the FAP's FDP
    relative_to : vertex index whose displacement is subtracted, or -1
    direction : (3,) float unit vector of the FAP's positive motion (project frame)
    unit : float, skin length of one FAPU of this FAP (e.g. MNS0 / 1024)
    """

    fap: int
    vertex: int
    relative_to: int
    direction: np.ndarray
    unit: float


def measure(rest: np.ndarray, moved: np.ndarray, probe: Probe) -> np.ndarray:
    """Displacement in FAPU of ``probe``'s FDP along its direction.

    rest : (n, 3) float skin positions at rest; moved : (k, n, 3) or (n, 3) float
    Returns (k,) or scalar float (FAPU).
    """
    moved = np.asarray(moved, dtype=float)
    d = moved[..., probe.vertex, :] - rest[probe.vertex]
    if probe.relative_to >= 0:
        d = d - (moved[..., probe.relative_to, :] - rest[probe.relative_to])
    return (d @ np.asarray(probe.direction, dtype=float)) / probe.unit


def invert_monotone(drives: np.ndarray, achieved: np.ndarray, requested: np.ndarray,
                    knee: float = 0.25) -> np.ndarray:
    """Drives that achieve ``requested`` on the sampled curve ``achieved(drives)``.

    drives : (k,) float, all of one sign, sampled drives (FAPU)
    achieved : (k,) float, displacement measured at each drive (FAPU)
    requested : (r,) float, of the same sign as ``drives``' intended effect

    The curve gets (0, 0) prepended and is made monotone (running max of |achieved|
    along |drive|), then inverted by linear interpolation; beyond the last sample the
    last secant slope extrapolates unless the curve has flattened (last slope < ``knee`` x
    the first: saturation), in which case the drive is held at the last sample. Returns
    (r,) float drives; NaN where the curve never moves the FDP in the requested sense (the
    FAP is unreachable with this mapping).
    """
    drives, achieved, requested = (np.asarray(a, dtype=float) for a in (drives, achieved, requested))
    order = np.argsort(np.abs(drives))
    d = np.concatenate([[0.0], drives[order]])
    a = np.concatenate([[0.0], achieved[order]])
    out = np.full(requested.shape, np.nan)
    for sense in (1.0, -1.0):
        sel = np.sign(requested) == sense
        if not np.any(sel):
            continue
        gain = np.maximum.accumulate(np.maximum(sense * a, 0.0))   # |achieved| in this sense
        if gain[-1] <= 0.0:
            continue
        # strictly increasing support for interpolation: keep the first sample of each plateau
        keep = np.concatenate([[True], np.diff(gain) > 0.0])
        g, dd = gain[keep], d[keep]
        r = np.abs(requested[sel])
        res = np.interp(r, g, dd)
        if len(g) >= 3:
            # extrapolate with the last secant only while the curve has not flattened: past a
            # knee (last response slope < ``knee`` x the first) more drive buys little motion
            # and only drives the muscles into full contraction, so the drive is held there
            first = (g[1] - g[0]) / (dd[1] - dd[0])
            last = (g[-1] - g[-2]) / (dd[-1] - dd[-2])
            if abs(last) >= knee * abs(first):
                res = np.where(r > g[-1], dd[-1] + (r - g[-1]) / last, res)
        elif len(g) == 2:
            res = np.where(r > g[-1], dd[-1] * r / g[-1], res)
        out[sel] = res
    return out


@dataclass
class CalibrationRow:
    fap: int
    name: str
    group: str
    requested: float
    achieved_before: float
    achieved: float
    drive: float
    saturated: bool = False       # every muscle the drive's sign recruits is at full contraction

    @property
    def error(self) -> float:
        """Relative error |achieved - requested| / |requested|."""
        return abs(self.achieved - self.requested) / abs(self.requested)

    def as_dict(self) -> dict:
        def num(x):
            return float(x) if np.isfinite(x) else None       # JSON has no NaN: unreachable = null

        return {"fap": self.fap, "name": self.name, "group": self.group,
                "requested": self.requested, "achieved_uncalibrated": num(self.achieved_before),
                "achieved": num(self.achieved), "drive": num(self.drive),
                "relative_error": num(self.error), "saturated": self.saturated}


def full_drive(entry, sense: float, max_contraction: float) -> float:
    """The |drive| (FAPU) at which every muscle ``entry`` recruits on the side ``sense`` (> 0:
    ``entry.positive``, else ``entry.negative``) is at ``max_contraction``: ``max_contraction /
    min(gain)``. Any larger drive gives the same contractions, hence the same pose. ``inf`` for
    a side without muscles or an entry that also moves the jaw (more drive moves it further).
    """
    muscles = entry.positive if sense > 0 else entry.negative
    if not muscles or entry.jaw is not None:
        return float("inf")
    return max_contraction / min(muscles.values())


def saturated(entry, drive: float, max_contraction: float) -> bool:
    """True when ``drive`` (FAPU, the entry's control after its response) puts every muscle of
    its sign (``entry.positive`` for drive > 0, else ``entry.negative``) at ``max_contraction``:
    more drive cannot move the skin further (:func:`full_drive`). Jaw-only entries (no muscles)
    never saturate here.
    """
    if not np.isfinite(drive) or drive == 0.0:
        return False
    return abs(drive) >= full_drive(entry, drive, max_contraction)


def best_sampled(drives: np.ndarray, achieved: np.ndarray, requested: np.ndarray,
                 current: np.ndarray, tolerance: float = 0.005) -> np.ndarray:
    """The sampled drive that came closest to each request, among those of ``current``'s sign.

    drives, achieved : (k,) float, every drive tried and the FDP displacement it gave (FAPU)
    requested, current : (r,) float, the requests and their drives so far (FAPU)
    Of the samples whose error is within ``tolerance`` x |request| of the smallest, the least
    |drive| wins (a saturated plateau: no more contraction than needed). A request with no
    sample of its drive's sign keeps ``current``. Returns (r,) float drives.
    """
    out = np.array(current, dtype=float)
    for j, (r, d) in enumerate(zip(requested, current)):
        same = np.flatnonzero((np.sign(drives) == np.sign(d)) & (drives != 0.0))
        if len(same) == 0:
            continue
        err = np.abs(achieved[same] - r)
        near = same[err <= err.min() + tolerance * abs(r)]
        out[j] = drives[near[np.argmin(np.abs(drives[near]))]]
    return out


def drive_cap(entry, requested: np.ndarray, max_drive: float, max_contraction: float) -> np.ndarray:
    """Largest |drive| (FAPU) calibration may ask of ``entry`` for each of ``requested`` (r,) FAPU.

    ``max_drive * |requested|`` (an FDP that barely moves must not ask for absurd drives), but
    never less than the drive that puts every muscle of the request's sign (``entry.positive``
    for requested > 0, else ``entry.negative``) at ``max_contraction``, i.e.
    ``max_contraction / min(gain)``: with small first-guess gains (e.g. 0.0005 per FAPU) the
    plain cap stopped the fit with some muscles far below full contraction (c = 0.4), so the
    report showed a shortfall the rig does not have. Beyond that drive nothing moves
    (:func:`saturated`), so the larger cap costs no stability. Returns (r,) float.
    """
    requested = np.asarray(requested, dtype=float)
    cap = max_drive * np.abs(requested)
    for sense in (1.0, -1.0):
        full = full_drive(entry, sense, max_contraction)
        if np.isfinite(full):
            sel = np.sign(requested) == sense
            cap[sel] = np.maximum(cap[sel], full)
    return cap


def _frames(entry_faps, values: np.ndarray) -> np.ndarray:
    f = np.zeros((len(values), N_FAPS))
    for fap in entry_faps:
        f[:, fap - 1] = values
    return f


def calibrate_mapping(mapping: FapMapping, simulate, rest: np.ndarray, probes: dict,
                      requested: dict, refine: int = 2, sample_scale=(0.5, 1.0, 1.5),
                      max_drive=20.0, tolerance: float = 0.005, progress=None):
    """Fit every entry's response curve so requested and achieved FAPU agree.

    Parameters
    ----------
    mapping : FapMapping, the starting mapping (its response curves are ignored)
    simulate : callable (mapping, faps (k, 68) float) -> skin (k, n, 3) float, the settled
        skin of k independent static poses
    rest : (n, 3) float, skin at rest
    probes : dict FAP number -> Probe; entries whose first FAP has no probe are skipped; an
        entry of several FAPs (outer and inner lip twins, driven together) is fitted to the mean
        of its FAPs' probes, and each FAP gets its own report rows
    requested : dict FAP number -> (r,) float requested values (FAPU, nonzero)
    refine : at most this many secant refinements per requested value after the first
        inversion; a value stops early once its achieved mean is within ``tolerance`` (relative)
        of the request, or when its drive no longer changes (held at a saturated curve's knee or
        at ``max_drive``)
    sample_scale : drives sampled for the first curve, as fractions of max |requested|
    max_drive : cap on |drive| / |requested|, raised where the entry's muscles need more drive to
        reach full contraction (:func:`drive_cap`)
    tolerance : relative error at which a requested value counts as met (default 0.5 %)
    progress : optional callable wrapping an iterable (e.g. tqdm)

    Returns
    -------
    (calibrated FapMapping, list of CalibrationRow for every (FAP of the entry, requested))

    Length (119 lines): the per-entry measure-fit-refine loop with its bookkeeping; left as it
    is (issue 24).
    """
    rows = []
    calibrated = mapping
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
        # one drive moves every FAP of the entry (outer and inner lip twins get the same value):
        # fit it to the mean of their FDPs' displacements, so neither twin is favoured
        observed = [probes[f] for f in entry.faps if f in probes]

        def probe(skins, observed=observed):
            return np.mean([measure(rest, skins, p) for p in observed], axis=0)
        identity = with_entry(calibrated, idx, response=None)
        # 1. sample the drive -> displacement curve (identity response: drive = value)
        top = np.abs(req).max()
        signs = np.unique(np.sign(req))
        drives = np.concatenate([s * top * np.asarray(sample_scale, dtype=float) for s in signs])
        drives = np.union1d(drives, req)          # the uncalibrated poses are samples too
        skins = simulate(identity, _frames(entry.faps, drives))
        sampled = probe(skins)
        at_req = np.searchsorted(drives, req)
        before_skin = skins[at_req]
        # 2. invert it, 3. refine each requested value by secant steps on its own samples
        drive = invert_monotone(drives, sampled, req)
        ok = np.isfinite(drive)
        # an FDP that barely moves would ask for absurd drives: cap them (contractions
        # and jaw limits saturate long before, so the report shows the shortfall)
        cap = drive_cap(entry, req, max_drive, calibrated.max_contraction)
        drive = np.clip(drive, -cap, cap)
        d_all, a_all = list(drives), list(sampled)
        todo = ok.copy()
        met = np.zeros(len(req), dtype=bool)
        for _ in range(refine + 1):
            if not np.any(todo):
                break
            got = probe(simulate(identity, _frames(entry.faps, drive[todo])))
            d_all += list(drive[todo])
            a_all += list(got)
            # a value within ``tolerance`` of its request keeps its drive; the others take a
            # secant step on the two nearest samples around them
            met[todo] = np.abs(got - req[todo]) <= tolerance * np.abs(req[todo])
            left = np.flatnonzero(todo)[~met[todo]]
            todo[:] = False
            if len(left) == 0:
                break
            step = invert_monotone(np.asarray(d_all), np.asarray(a_all), req[left])
            step = np.clip(step, -cap[left], cap[left])
            moved = ~np.isclose(step, drive[left], rtol=1e-9, atol=0.0)   # a held drive: saturated
            drive[left] = step
            ok = np.isfinite(drive)
            todo[left[moved & np.isfinite(step)]] = True
        # a request left unmet keeps the best drive measured for it rather than the last secant
        # guess: where the entry's muscles work against each other (an assisting muscle that
        # moves this FDP the other way and wins once the lead saturates) the curve turns back,
        # and the guesses run on to the drive cap, past the peak, to a worse pose
        drive[ok & ~met] = best_sampled(np.asarray(d_all), np.asarray(a_all), req[ok & ~met],
                                        drive[ok & ~met], tolerance)
        # beyond the drive that saturates every muscle of its side the pose no longer changes:
        # a knot past it (the secant ran on to the cap) is the same pose as at the knee, but the
        # curve through it would drive smaller requests of playback to full contraction as well
        # (MakeHuman's left upper lip lowered 55 MNS by Xface fear: orbicularis oris c = 1, at
        # the knee 0.74)
        knee = np.array([full_drive(entry, d, calibrated.max_contraction) for d in drive])
        drive = np.clip(drive, -knee, knee)
        # a request the entry's muscles never move the FDP towards (NaN drive) gets a zero-drive
        # knot: without one, the response would extrapolate the other side's slope through (0, 0)
        # and drive the muscles for that request after all, moving the FDP the wrong way (further
        # than uncalibrated); with it, the FDP stays at rest (100 % error, honestly unreachable)
        knots = _monotone_knots(np.column_stack([req, np.where(ok, drive, 0.0)]))
        calibrated = with_entry(calibrated, idx, response=knots)
        # 4. verify with the calibrated response, every FAP of the entry on its own probe
        #    (all FAPs of an entry get the same values: one simulation serves every probe)
        final_skin = simulate(calibrated, _frames(entry.faps, req))
        for fap in entry.faps:
            if fap not in probes:
                continue
            final = measure(rest, final_skin, probes[fap])
            first = measure(rest, before_skin, probes[fap])
            for j, r in enumerate(req):
                d = float(drive[j]) if ok[j] else float("nan")
                rows.append(CalibrationRow(fap, entry.name, fap_group(fap), float(r), float(first[j]),
                                           float(final[j]), d,
                                           saturated(entry, d, calibrated.max_contraction)))
    return calibrated, rows


def _monotone_knots(knots: np.ndarray) -> np.ndarray:
    """Sort knots by requested value and make the whole curve monotone through (0, 0).

    The curve's sense ``s`` is that of the positive side's drives (else the opposite of the
    negative side's). Positive requests get ``s * drive >= 0`` growing with the request,
    negative ones ``s * drive <= 0`` growing in size outward; a side whose drives went the
    wrong way (that request could not be met) is clamped to zero drive.
    """
    k = knots[np.argsort(knots[:, 0], kind="stable")].copy()
    neg, pos = k[:, 0] < 0.0, k[:, 0] > 0.0
    s = 0.0
    if np.any(pos):
        s = np.sign(np.median(k[pos, 1]))
    if s == 0.0 and np.any(neg):
        s = -np.sign(np.median(k[neg, 1]))
    s = s or 1.0
    if np.any(pos):
        k[pos, 1] = s * np.maximum.accumulate(np.maximum(s * k[pos, 1], 0.0))
    if np.any(neg):
        mag = np.maximum(-s * k[neg, 1][::-1], 0.0)
        k[neg, 1] = (-s * np.maximum.accumulate(mag))[::-1]
    k[k[:, 0] == 0.0, 1] = 0.0
    return k


def summarize(rows) -> dict:
    """Median relative error per group and over lip + jaw + cheek + eyebrow FAPs."""
    out = {}
    for group in ("jaw", "lip", "cheek", "eyebrow"):
        errs = [r.error for r in rows if r.group == group]
        out[group] = {"count": len(errs), "median_relative_error": float(np.median(errs)) if errs else None}
    counted = [r for r in rows if r.group in ("jaw", "lip", "cheek", "eyebrow")]
    errs = [r.error for r in counted]
    out["all"] = {"count": len(errs), "median_relative_error": float(np.median(errs)) if errs else None,
                  "within_10_percent": int(sum(e <= 0.1 for e in errs)),
                  "saturated": int(sum(r.saturated for r in counted))}
    before = [abs(r.achieved_before - r.requested) / abs(r.requested) for r in rows
              if r.group in ("jaw", "lip", "cheek", "eyebrow")]
    out["all_uncalibrated"] = {"count": len(before),
                               "median_relative_error": float(np.median(before)) if before else None}
    return out


def format_table(rows) -> str:
    """A short fixed-width table: FAP, name, requested, achieved, relative error, and "c=max"
    where the entry's muscles are all at full contraction (the rig can do no more)."""
    lines = [f"{'FAP':>4} {'name':<22} {'requested':>10} {'uncalib.':>10} {'achieved':>10} {'error':>7}"]
    for r in rows:
        lines.append(f"{r.fap:>4} {r.name:<22} {r.requested:>10.1f} {r.achieved_before:>10.1f} "
                     f"{r.achieved:>10.1f} {100 * r.error:>6.1f}%" + ("  c=max" if r.saturated else ""))
    return "\n".join(lines)


def measure_coupling(mapping: FapMapping, simulate, rest: np.ndarray, probes: dict,
                     value: float, jaw_fap: int = 3) -> FapMapping:
    """Set each ``coupling[jaw_fap]`` ratio to what open_jaw alone does to the entry's FDP.

    Applies ``jaw_fap`` alone at ``value`` FAPU and, for every entry coupled to it, stores
    (displacement of the first of the entry's FDPs the skin has, in its FAPU) / value. Entries without a probe
    keep their ratio. Units must agree (open_jaw and the lower-lip FAPs are both MNS).
    """
    frames = np.zeros((1, N_FAPS))
    frames[0, jaw_fap - 1] = value
    skin = simulate(mapping, frames)
    out = mapping
    for idx, e in enumerate(mapping.entries):
        seen = [f for f in e.faps if f in probes]
        if jaw_fap in e.coupling and seen:
            ratio = float(measure(rest, skin, probes[seen[0]])[0]) / value
            out = with_entry(out, idx, coupling={**e.coupling, jaw_fap: ratio})
    return out
