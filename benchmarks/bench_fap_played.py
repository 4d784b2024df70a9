"""FAP accuracy as a user plays them: each mapped FAP alone, at the largest magnitude the
Xface files in samples/fap/ use (both signs for a bidirectional FAP the mapping can drive
both ways), written as a FAP file, played by ``faceforge animate -o track.pc2`` (the workdir's
own mapping: its calibration when there is one) and measured on the exported PC2 frames:
the FDP's displacement along the FAP's axis, in the head's FAPU, at the end of a 20-frame
hold after a 10-frame ramp.

Two protocols (issue 25):

* ``signed`` (the magnitudes users play): each sign the files use, at the largest value of that
  sign (raise_b_midlip: -870 and +76 MNS; open_jaw +713), for every sign the mapping drives;
  a sign the files never use is not played;
* ``context``: each of those requests inside the Xface frame where it occurs (every FAP of that
  frame played together, head rotation and eyeballs zeroed): a lower lip lowered 870 MNS rides on
  the open jaw that the files open with it;
The FAP file written gives, as the Xface files do, only the FAPs of the request: a lip FAP's
twin (outer 51-60 / inner 4-13) not given is copied from it by the reader, so the entry they
share is driven fully.

* ``abs`` (the first protocol, kept for comparison; every FAP given in every frame, so a lip
  FAP played alone had its twin at 0 and its entry, driven by the twins' mean, at half): the largest |value| of either sign, played
  with both signs (raise_b_midlip +870 MNS too, which no file asks for: it would push the lower
  lip through the upper one without the jaw).

Usage::

    python benchmarks/bench_fap_played.py WORKDIR [WORKDIR ...] [--half] [--signed]

``--half``: also x0.5; ``--signed``: the signed protocol only (the one issue 25 asks for).

Writes ``benchmarks/results/fap_played.json``: per head and protocol the rows (FAP, requested,
achieved, relative error), the median and worst error, and left/right pairs (how far the two
sides' achieved values differ, relative to the larger).
"""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _util import workdir_args, write_results  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
RAMP, HOLD = 10, 20


def xface_magnitudes(signed: bool = False) -> dict:
    """FAP -> largest |value| any samples/fap/*.fap file gives it (FAPU); ``signed``: FAP ->
    (most negative, most positive) value (0 for a sign never used)."""
    from faceforge.mpeg4 import read_fap

    top = {}
    for path in sorted((ROOT / "samples/fap").glob("*.fap")):
        t = read_fap(path)
        v = np.where(t.mask, t.values, 0.0)
        for k in np.flatnonzero(np.abs(v).max(axis=0)):
            lo, hi = top.get(k + 1, (0.0, 0.0))
            top[k + 1] = (min(lo, float(v[:, k].min())), max(hi, float(v[:, k].max())))
    return top if signed else {k: max(-lo, hi) for k, (lo, hi) in top.items()}


def requests(mapping, probes, top, fraction: float = 1.0, signed: bool = False) -> list[tuple[int, float]]:
    """(FAP, value) pairs to play. ``signed=False``: the Xface magnitude, and its negative where
    the FAP is bidirectional and its entry drives that way; ``signed=True`` (``top`` from
    ``xface_magnitudes(signed=True)``): each sign the files use and the entry drives, at its
    largest value."""
    from faceforge.mpeg4 import fap_record

    out = []
    for e in mapping.entries:
        both = bool(e.negative) or (e.jaw is not None and e.jaw[0] == "yaw")
        for fap in e.faps:
            if fap not in probes or fap not in top:
                continue
            if signed:
                lo, hi = top[fap]
                if hi > 0:
                    out.append((fap, fraction * hi))
                if lo < 0 and both and fap_record(fap).bidirectional:
                    out.append((fap, fraction * lo))
                continue
            out.append((fap, fraction * top[fap]))
            if fap_record(fap).bidirectional and both:
                out.append((fap, -fraction * top[fap]))
    return out


def in_context(mapping, probes) -> list[tuple[int, float, np.ndarray]]:
    """(FAP, value, the whole frame (68,)) for each mapped FAP and sign: the frame of the Xface
    files where that FAP reaches its largest value of that sign, every other FAP of the frame
    kept (the jaw opening that carries a lowered lip, the lids), head rotation and eyeballs
    (23-26, 48-50) zeroed so the face is measured in the head's frame."""
    from faceforge.mpeg4 import read_fap

    best = {}
    for path in sorted((ROOT / "samples/fap").glob("*.fap")):
        t = read_fap(path)
        v = np.where(t.mask, t.values, 0.0)
        for fap in probes:
            for sgn in (1.0, -1.0):
                i = int(np.argmax(sgn * v[:, fap - 1]))
                val = float(v[i, fap - 1])
                if sgn * val > 0 and sgn * val > abs(best.get((fap, sgn), (0.0,))[0]):
                    frame = v[i].copy()
                    frame[[22, 23, 24, 25, 47, 48, 49]] = 0.0
                    best[(fap, sgn)] = (val, frame)
    played = {(fap, float(np.sign(v))) for fap, v in requests(mapping, probes, xface_magnitudes(True), 1.0, True)}
    return [(fap, val, frame) for (fap, sgn), (val, frame) in sorted(best.items()) if (fap, sgn) in played]


def head_rows(workdir: Path, fraction: float = 1.0, signed: bool = False, context: bool = False) -> dict:
    from faceforge.animation.calibrate import measure
    from faceforge.animation.calibrate_head import calibration_probes
    from faceforge.io.export_cache import read_pc2
    from faceforge.mpeg4 import FapTrack, write_fap

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import expr_measure as em

    head, mapping, _ = em.load_head(workdir)
    probes = calibration_probes(mapping, head)
    if context:
        asked = [(fap, fraction * v, fraction * frame) for fap, v, frame in in_context(mapping, probes)]
    else:
        asked = [(fap, v, np.eye(68)[fap - 1] * v)
                 for fap, v in requests(mapping, probes, xface_magnitudes(signed), fraction, signed)]
    per = RAMP + HOLD + 5
    n = 2 + per * len(asked)
    values, mask = np.zeros((n, 68)), np.zeros((n, 68), dtype=bool)
    ends = []
    for k, (fap, v, frame) in enumerate(asked):
        s = 2 + k * per
        ramp = np.concatenate([np.linspace(0, 1.0, RAMP + 1)[1:], np.ones(HOLD), np.zeros(5)])
        values[s:s + per] = ramp[:, None] * frame[None]
        if signed or context:   # given as a file gives them: the FAPs of the request, the rest held at 0,
            mask[s:s + per] = frame[None] != 0.0   # a lip twin not given copied from its partner
        ends.append(s + RAMP + HOLD - 1)
    mask[:2, 2:] = True
    if not (signed or context):
        mask[:, 2:] = True      # the first protocol: every FAP given, a lip twin's partner at 0
    track = FapTrack.from_given(25.0, mask, values, name="bench_fap_played")
    fap_path = workdir / "bench_fap_played.fap"
    out = workdir / "bench_fap_played.pc2"
    write_fap(fap_path, track)
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", "from faceforge.cli import main; main()", "-q", "--workdir",
                    str(workdir), "animate", "--fap", str(fap_path), "-o", str(out)], check=True)
    seconds = time.perf_counter() - t0
    frames, _, _ = read_pc2(out)
    internal = np.zeros(len(head.rest), dtype=np.int64)
    internal[head.user_index[::-1]] = np.arange(len(head.user_index))[::-1]   # first user vertex
    skins = frames[:, internal].astype(float) @ np.asarray(head.user_rotation).T
    rest = skins[0]
    rows = []
    for (fap, v, _), end in zip(asked, ends):
        got = float(measure(rest, skins[end], probes[fap]))
        rows.append({"fap": fap, "requested": v, "achieved": round(got, 2),
                     "relative_error": round(abs(got - v) / abs(v), 4)})
    chin = chin_from_frames(head, skins, rest, asked, ends)
    err = np.array([r["relative_error"] for r in rows])
    by = {(r["fap"], np.sign(r["requested"])): r["achieved"] for r in rows}
    lr = []
    from faceforge.animation.calibrate_mirror import fap_twins

    for a, b in sorted(fap_twins().items()):  # the standard's left/right twins; those played
        for sgn in (1.0, -1.0):
            if (a, sgn) in by and (b, sgn) in by:
                x, y = abs(by[(a, sgn)]), abs(by[(b, sgn)])
                lr.append({"faps": f"{a}/{b}", "sign": int(sgn), "left": by[(a, sgn)], "right": by[(b, sgn)],
                           "differs": round(abs(x - y) / max(x, y, 1e-9), 4)})
    worst = rows[int(np.argmax(err))] if rows else None
    return {"rows": rows, "median_error": float(np.median(err)) if len(err) else None,
            "within_10_percent": int((err <= 0.1).sum()), "over_30_percent": int((err > 0.3).sum()),
            "count": len(rows), "worst": worst, "left_right": lr,
            "left_right_within_10_percent": int(sum(p["differs"] <= 0.1 for p in lr)),
            "animate_seconds": round(seconds, 1), "mapping": mapping.source, "chin_path": chin}


def chin_from_frames(head, skins, rest, asked, ends) -> list[dict]:
    """open_jaw's chin path on the exported frames (issue 25): for each request that opens
    the jaw, how far the skin chin (FDP 2.1) moved down and back at the end of its hold, in
    MNS units (head frame: +y up, +z forward)."""
    v = head.fdp_vertex.get("2.1")
    if v is None:
        return []
    mns = head.fapu.unit("MNS")
    out = []
    for (fap, value, frame), end in zip(asked, ends):
        if frame[2] > 0.0:
            d = (skins[end, v] - rest[v]) / mns
            out.append({"fap": fap, "open_jaw": float(frame[2]), "down_mns": round(float(-d[1]), 1),
                        "back_mns": round(float(-d[2]), 1),
                        "back_per_down": round(float(-d[2] / max(-d[1], 1e-9)), 3)})
    return out


def main(argv=None) -> None:
    args = workdir_args(__doc__, argv, {"--signed": "each FAP alone at the largest magnitude of each sign "
                                                    "the Xface files use (the issue's protocol) only",
                                        "--half": "also at half those magnitudes"})
    fractions = (1.0, 0.5) if args.half else (1.0,)
    protocols = ("signed",) if args.signed else ("signed", "context", "abs")
    dirs = args.workdirs
    results = {}
    for protocol in protocols:
        for fraction in fractions:
            for d in dirs:
                r = results[f"{d.name} {protocol} x{fraction:g}"] = head_rows(d, fraction, protocol == "signed",
                                                                            protocol == "context")
                print(f"{d.name} {protocol} x{fraction:g} Xface magnitude: median {r['median_error']:.1%}, "
                      f"{r['within_10_percent']}/{r['count']} within 10 %, {r['over_30_percent']} over 30 %, "
                      f"worst {r['worst']}; L/R within 10 %: "
                      f"{r['left_right_within_10_percent']}/{len(r['left_right'])}")
    write_results("fap_played", {"heads": results})


if __name__ == "__main__":
    main()
