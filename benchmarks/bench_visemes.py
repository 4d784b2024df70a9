"""The fourteen visemes against phonetic targets, and how distinct they are (issue 25). Run::

    python benchmarks/bench_visemes.py WORKDIR_MAKEHUMAN WORKDIR_ICT WORKDIR_MEDIAPIPE [--no-cli]

Each WORKDIR is fitted and bound (calibrated or not: the visemes stage calibrates when it needs to).
Through the CLI, as a user gets it: ``faceforge visemes --force`` (its report's per-viseme checks:
folded edges, inverted triangles, skin inside the skull; ``--no-cli`` reads the report the last
run left instead). In process, settled
as that stage settles them (each viseme held until the skin stops moving, the workdir's calibrated
mapping with the template's ``visemes`` table), per viseme in mm (the fit's own scale,
:func:`faceforge.anatomy.tissue.units_per_mm`):

lip_aperture
    the inner lip gap on the midline, FDP 2.2 (upper inner) minus 2.3 (lower inner) along +Y;
    ``rest`` is the same at rest (near 0 on closed-mouth heads).
width_change
    the corners' (8.3 / 8.4) distance apart minus at rest (+ spread, - rounded).
protrusion
    the outer lip middles' (8.1 upper, 8.2 lower) forward (+Z) motion: ``upper``, ``lower``.
incisor_gap
    how far the lower incisors (the mandible's highest midline point in front) moved under the
    jaw's transform: the interincisal opening from the bite.

Distinctness: each viseme's mouth shape is the motion (mm) of the lip FDPs 2.2-2.9 and 8.1-8.8;
the distance of two visemes is the RMS over those points of their shapes' difference. The report
gives the closest pair, every pair under 1.5 mm, and each viseme's RMS from neutral.

Targets (``TARGETS``, ranges in mm) come from phonetics, each with its source (``SOURCES``); they
are ranges for an adult speaker in clear speech, not one subject's values. Writes
``benchmarks/results/visemes.json``.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import expr_measure as em  # noqa: E402
from _util import workdir_args, write_results  # noqa: E402

#: lip FDPs whose motion is a viseme's mouth shape
SHAPE_FDPS = ("2.2", "2.3", "2.4", "2.5", "2.6", "2.7", "2.8", "2.9",
              "8.1", "8.2", "8.3", "8.4", "8.5", "8.6", "8.7", "8.8")
#: viseme -> {measure: (low, high) mm}. incisor: interincisal opening; aperture: inner lip gap
#: (closed lips pressed and rolled in pass each other: negative); width: change of the corners'
#: distance; protrusion: outer lip middles. Widened after the first measurement (said in
#: docs/notes/visemes.md): p_b_m's aperture from -1 to -5 (pressed lips roll in), the spread and open
#: visemes' protrusion (a, e, s_z) from -1 to -2.5 (the jaw's turn carries the lower lip back and
#: spread corners retract the lips, Fromkin 1964)
TARGETS = {
    "p_b_m": {"incisor": (0.5, 3.0), "aperture": (-5.0, 0.5), "width": (-3.0, 2.0), "protrusion": (-2.0, 1.0)},
    "f_v": {"incisor": (1.0, 4.0), "aperture": (1.5, 6.0), "width": (-2.0, 4.0), "protrusion": (-4.0, 0.5)},
    "th": {"incisor": (2.0, 5.0), "aperture": (3.0, 7.0), "width": (-2.0, 4.0), "protrusion": (-1.0, 1.5)},
    "t_d": {"incisor": (1.5, 4.5), "aperture": (2.0, 6.0), "width": (-2.0, 4.0), "protrusion": (-1.0, 1.5)},
    "k_g": {"incisor": (3.0, 7.0), "aperture": (4.0, 9.0), "width": (-2.0, 4.0), "protrusion": (-1.0, 1.5)},
    "ch_j_sh": {"incisor": (1.5, 4.0), "aperture": (2.5, 7.0), "width": (-10.0, -3.0), "protrusion": (2.0, 6.0)},
    "s_z": {"incisor": (1.0, 3.0), "aperture": (1.5, 5.0), "width": (1.0, 6.0), "protrusion": (-2.5, 1.5)},
    "n_l": {"incisor": (2.0, 6.0), "aperture": (3.0, 7.0), "width": (-2.0, 4.0), "protrusion": (-1.0, 1.5)},
    "r": {"incisor": (2.0, 5.0), "aperture": (3.0, 7.0), "width": (-9.0, -2.0), "protrusion": (1.5, 5.0)},
    "a": {"incisor": (9.0, 16.0), "aperture": (11.0, 20.0), "width": (-2.0, 6.0), "protrusion": (-2.5, 2.0)},
    "e": {"incisor": (4.0, 9.0), "aperture": (5.0, 11.0), "width": (2.0, 8.0), "protrusion": (-2.5, 1.5)},
    "i": {"incisor": (1.5, 5.0), "aperture": (2.0, 6.0), "width": (4.0, 10.0), "protrusion": (-1.5, 1.0)},
    "o": {"incisor": (6.0, 12.0), "aperture": (7.0, 14.0), "width": (-14.0, -5.0), "protrusion": (2.0, 6.0)},
    "u": {"incisor": (1.5, 5.0), "aperture": (2.0, 6.0), "width": (-16.0, -7.0), "protrusion": (3.0, 8.0)},
}
SOURCES = {
    "incisor": "Burnett 1999, Int J Prosthodont 12:263 (electrognathography, 30 adults, 24 English consonants: "
               "vertical incisor opening 2.5 mm for sibilants to 11.7 mm for /h/); Silva et al. 2005, J Appl Oral "
               "Sci 13(4) (/s/ speaking space 2.2 +- 1.4 mm, 61 dentate adults); vowels: jaw lowest for /a/ and "
               "highest for /i u/ (Keating, Lindblom, Lubker & Kreiman 1994, J Phonetics 22:407), ranges "
               "approximate (recalled, not re-read this session)",
    "aperture": "lip opening on the midline: closed for bilabials; Westbury & Hashi 1997 J Phonetics 25:405 and "
                "Westbury, Severson & Hashi 1999 ICPhS (lip separation and protrusion for 21 English consonants, "
                "52 speakers); vowels after Fromkin 1964 J Acoust Soc Am 36:2 (frontal photographs: /a/ largest "
                "opening, /i u/ small); ranges approximate (recalled)",
    "width": "Fromkin 1964 (corner distance: spread /i/ widest, rounded /u/ narrowest, about 15 mm apart on a "
             "~50 mm mouth); ranges approximate (recalled)",
    "protrusion": "Fromkin 1964 and Westbury et al. 1999 (rounded vowels and /S/ /r/ protrude the lips a few mm; "
                  "labiodentals pull the lower lip back); ranges approximate (recalled)",
}


def cli_report(workdir: Path, run: bool = True) -> tuple[float | None, dict]:
    """``faceforge visemes --force`` in ``workdir`` (``run``; else the report it left): wall
    seconds, {viseme: checks}."""
    import json

    t0 = time.perf_counter()
    if run:
        subprocess.run([sys.executable, "-c", "from faceforge.cli import main; main()", "--workdir", str(workdir),
                        "visemes", "--force"], check=True, capture_output=True, text=True)
    report = json.loads((workdir / "visemes" / "report.json").read_text())
    return (round(time.perf_counter() - t0, 1) if run else None), {n: {**r["checks"], "residual": r["residual"]}
                                                for n, r in report["visemes"].items()}


def lower_incisor(head) -> int:
    """Index of the mandible vertex standing for the lower incisors' edge: the highest point of the
    mandible within 4 % of its width of the midline and in its front fifth."""
    v = head.mandible[0]
    width = np.ptp(v[:, 0])
    zmax, depth = v[:, 2].max(), np.ptp(v[:, 2])
    ok = (np.abs(v[:, 0] - 0.5 * (v[:, 0].max() + v[:, 0].min())) < 0.04 * width) & (v[:, 2] > zmax - 0.2 * depth)
    idx = np.flatnonzero(ok)
    return int(idx[np.argmax(v[idx, 1])])


def measure(head, mapping, names=None) -> dict:
    """Per viseme (the mapping's ``visemes`` table, ``names`` or all): the four measures in mm,
    the targets met, and the distinctness figures. Poses settled as ``faceforge visemes`` does."""
    from faceforge.anatomy.tissue import units_per_mm
    from faceforge.mpeg4.visemes import VISEMES

    names = [n for n in (names or VISEMES) if n in mapping.visemes]
    faps = np.array([mapping.visemes[n] for n in names], dtype=float).reshape(len(names), 68)
    skins, c, jaw = em.settle(head, mapping, faps)
    mm = units_per_mm(head.landmarks)
    fv = head.fdp_vertex
    tooth = lower_incisor(head)
    m0 = head.mandible[0][tooth]
    shape_ids = [fv[f] for f in SHAPE_FDPS if f in fv]
    rest = head.rest
    gap0 = (rest[fv["2.2"], 1] - rest[fv["2.3"], 1]) / mm
    width0 = np.linalg.norm(rest[fv["8.3"]] - rest[fv["8.4"]]) / mm
    rows, shapes = {}, []
    for k, n in enumerate(names):
        s = skins[k]
        t = head.skull.jaw_transform(*jaw[k])
        tooth_mm = float(np.linalg.norm(t[:3, :3] @ m0 + t[:3, 3] - m0) / mm)
        got = {"incisor": tooth_mm,
               "aperture": float((s[fv["2.2"], 1] - s[fv["2.3"], 1]) / mm),
               "width": float(np.linalg.norm(s[fv["8.3"]] - s[fv["8.4"]]) / mm - width0),
               "protrusion": float(0.5 * ((s[fv["8.1"], 2] - rest[fv["8.1"], 2])
                                          + (s[fv["8.2"], 2] - rest[fv["8.2"], 2])) / mm)}
        met = {key: bool(lo - 1e-9 <= got[key] <= hi + 1e-9) for key, (lo, hi) in TARGETS[n].items()}
        shapes.append((s[shape_ids] - rest[shape_ids]) / mm)
        rows[n] = {"incisor_gap": round(got["incisor"], 2), "lip_aperture": round(got["aperture"], 2),
                   "width_change": round(got["width"], 2), "protrusion": round(got["protrusion"], 2),
                   "protrusion_upper": round(float((s[fv["8.1"], 2] - rest[fv["8.1"], 2]) / mm), 2),
                   "protrusion_lower": round(float((s[fv["8.2"], 2] - rest[fv["8.2"], 2]) / mm), 2),
                   "targets_met": met, "n_met": int(sum(met.values())),
                   "jaw_pitch_deg": round(float(np.degrees(jaw[k, 0])), 2),
                   "muscles": {m: round(float(x), 3) for m, x in zip(head.controls, c[k]) if x >= 0.05}}
    shapes = np.asarray(shapes)
    dist = np.sqrt(((shapes[:, None] - shapes[None]) ** 2).sum(-1).mean(-1))
    iu = np.triu_indices(len(names), 1)
    order = np.argsort(dist[iu])
    pairs = [(names[iu[0][j]], names[iu[1][j]], round(float(dist[iu][j]), 2)) for j in order]
    for k, n in enumerate(names):
        rows[n]["from_neutral_rms"] = round(float(np.sqrt((shapes[k] ** 2).sum(-1).mean())), 2)
    return {"rest": {"lip_aperture": round(float(gap0), 2), "mouth_width": round(float(width0), 2),
                     "MNS_mm": round(head.fapu.unit("MNS") / mm, 5), "MW_mm": round(head.fapu.unit("MW") / mm, 5)},
            "visemes": rows, "targets_met": int(sum(r["n_met"] for r in rows.values())),
            "targets_total": int(sum(len(TARGETS[n]) for n in names)),
            "distinct": {"closest_pair": pairs[0], "pairs_under_1_5mm": [p for p in pairs if p[2] < 1.5],
                         "median_pair_mm": round(float(np.median(dist[iu])), 2),
                         "matrix_mm": np.round(dist, 2).tolist(), "names": names}}


def main(argv=None) -> None:
    args = workdir_args(__doc__, argv, {"--no-cli": "measure the visemes stage already in each workdir "
                                                   "instead of running it"})
    use_cli = not args.no_cli
    results = {}
    for d in args.workdirs:
        out = {}
        if use_cli or (d / "visemes" / "report.json").is_file():
            out["visemes_seconds"], out["checks"] = cli_report(d, run=use_cli)
        head, mapping, _ = em.load_head(d)
        out.update(measure(head, mapping))
        results[d.name] = out
        print(d.name, "targets met", out["targets_met"], "/", out["targets_total"], "closest",
              out["distinct"]["closest_pair"], flush=True)
        for n, r in out["visemes"].items():
            folds = out.get("checks", {}).get(n, {}).get("folded_edges", "-")
            print(f"  {n:8s} incisor {r['incisor_gap']:6.2f} aperture {r['lip_aperture']:6.2f} width "
                  f"{r['width_change']:6.2f} protrusion {r['protrusion']:5.2f} ({r['protrusion_upper']:5.2f} / "
                  f"{r['protrusion_lower']:5.2f}) met {r['n_met']}/4 neutral {r['from_neutral_rms']:5.2f} "
                  f"folds {folds}",
                  flush=True)
    write_results("visemes", {"targets_mm": TARGETS, "sources": SOURCES, "heads": results,
                              "load": os.getloadavg()})


if __name__ == "__main__":
    main()
