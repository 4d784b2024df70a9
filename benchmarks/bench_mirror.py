"""Mirror agreement of a symmetric head's rig (issue 25, item 3): does a left unit move the skin
as the mirror image of its right twin?

For each left/right twin (a FAP pair, or a muscle pair alone) the skin displacements ``d_L``
and ``d_R`` are compared through the skin's own vertex mirror map: ``||mirror(d_L) - d_R|| /
||d_L||`` over the skin (0: the two sides move as mirror images; the target is 0.05). Joy's
two mouth corners (FDP 8.3 / 8.4) are compared by their rise in mm.

* FAP pairs and joy are measured **on the exported frames**: one FAP file (each FAP alone,
  a 10-frame ramp, a 20-frame hold, 15 frames back at rest) and ``--expression joy`` are
  played by ``faceforge animate -o x.pc2`` (the workdir's own mapping: its calibration when
  there is one), and the PC2 is read back.
* Muscle pairs (contraction 0.6 alone, no mapping) are settled in-process as ``faceforge
  expressions`` settles a pose (:func:`faceforge.animation.playback.static_poses`): no
  command plays a single muscle.

Usage::

    python benchmarks/bench_mirror.py WORKDIR [WORKDIR ...] [--fast] [--out NAME]

``--fast`` settles the FAP pairs and joy in-process too (seconds, for iterating on the rig).
WORKDIR has been fitted and bound. Writes ``benchmarks/results/<NAME>.json`` (default
``mirror``).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _util import write_results  # noqa: E402
import expr_measure as em  # noqa: E402

RAMP, HOLD, GAP = 10, 20, 15
CONTRACTION = 0.6
#: left/right FAP twins (name, left FAP, right FAP, value in FAPU)
FAP_PAIRS = em.MIRROR_FAPS


def differs(dl: np.ndarray, dr: np.ndarray, partner: np.ndarray, plane) -> float:
    """``||mirror(d_L) - d_R|| / ||d_L||`` for displacements (n, 3), partner (n,) the vertex
    mirror map (``partner[i]``: the vertex at vertex i's mirror image)."""
    ml = plane.direction(dl[partner])
    return float(np.linalg.norm(ml - dr) / max(np.linalg.norm(dl), 1e-30))


def vertex_mirror(rest: np.ndarray, plane, es0: float) -> tuple[np.ndarray, float]:
    """(partner (n,), worst distance in ES0) of each vertex's mirror image to its nearest vertex."""
    j, d = plane.partners(rest)
    return j, float(d.max() / es0)


def _row(name: str, dl, dr, partner, plane, mm: float) -> dict:
    pl, pr = np.linalg.norm(dl, axis=1).max() / mm, np.linalg.norm(dr, axis=1).max() / mm
    return {"name": name, "differs": round(differs(dl, dr, partner, plane), 4),
            "peak_left_mm": round(float(pl), 3), "peak_right_mm": round(float(pr), 3)}


def muscle_rows(head, partner, plane, mm: float) -> list[dict]:
    """Each muscle twin alone at CONTRACTION, settled."""
    from faceforge.animation.playback import static_poses

    active = {n for n, m in head.system.muscles.items() if m.active}   # passive tissue does not contract
    names = [n for n in head.controls if n.endswith("_L") and n[:-2] + "_R" in head.controls and n in active]
    c = np.zeros((2 * len(names), len(head.controls)))
    for k, n in enumerate(names):
        c[2 * k, head.controls.index(n)] = CONTRACTION
        c[2 * k + 1, head.controls.index(n[:-2] + "_R")] = CONTRACTION
    skins = static_poses(head.rig, c, np.zeros((len(c), 3)), 25.0)
    return [_row(n[:-2], skins[2 * k] - head.rest, skins[2 * k + 1] - head.rest, partner, plane, mm)
            for k, n in enumerate(names)]


def _fap_track(values: list[np.ndarray]):
    """A FapTrack playing each FAP row (68,) alone: ramp, hold, back to rest; the hold ends."""
    from faceforge.mpeg4 import FapTrack

    per = RAMP + HOLD + GAP
    n = 2 + per * len(values)
    out, ends = np.zeros((n, 68)), []
    for k, row in enumerate(values):
        s = 2 + k * per
        w = np.concatenate([np.linspace(0, 1, RAMP + 1)[1:], np.ones(HOLD), np.zeros(GAP)])
        out[s:s + per] = w[:, None] * row[None]
        ends.append(s + RAMP + HOLD - 1)
    mask = np.zeros((n, 68), dtype=bool)
    mask[:, 2:] = True
    return FapTrack.from_given(25.0, mask, out, name="bench_mirror"), ends


def _played(workdir: Path, head, args: list[str], out: Path) -> np.ndarray:
    """Frames (k, n, 3) in head space (working vertices) of ``faceforge animate ARGS -o OUT``."""
    from faceforge.io.export_cache import read_pc2

    subprocess.run([sys.executable, "-c", "from faceforge.cli import main; main()", "-q", "--workdir",
                    str(workdir), "animate", *args, "-o", str(out)], check=True)
    frames, _, _ = read_pc2(out)
    internal = np.zeros(len(head.rest), dtype=np.int64)
    internal[head.user_index[::-1]] = np.arange(len(head.user_index))[::-1]
    return frames[:, internal].astype(float) @ np.asarray(head.user_rotation).T


def fap_rows(workdir: Path, head, mapping, partner, plane, mm: float, fast: bool) -> tuple[list, dict]:
    """FAP twins and joy's corners, from the exported frames (or settled in-process: ``fast``)."""
    from faceforge.mpeg4 import write_fap

    rows = []
    for name, left, right, value in FAP_PAIRS:
        for fap in (left, right):
            r = np.zeros(68)
            r[fap - 1] = value
            rows.append(r)
    joy = np.asarray(mapping.expressions["joy"], dtype=float)
    if fast:
        skins, _, _ = em.settle(head, mapping, np.vstack(rows + [joy]))
        poses, joy_frames = skins[:-1], skins[-1:]
    else:
        track, ends = _fap_track(rows)
        write_fap(workdir / "bench_mirror.fap", track)
        frames = _played(workdir, head, ["--fap", str(workdir / "bench_mirror.fap")], workdir / "bench_mirror.pc2")
        poses = frames[ends]
        joy_frames = _played(workdir, head, ["--expression", "joy"], workdir / "bench_mirror_joy.pc2")
    rest = head.rest if fast else frames[0]
    out = [_row(f"{name} ({left}/{right}, {value:g})", poses[2 * k] - rest, poses[2 * k + 1] - rest, partner,
                plane, mm) for k, (name, left, right, value) in enumerate(FAP_PAIRS)]
    up = {side: float((joy_frames[:, head.fdp_vertex[f], 1] - rest[head.fdp_vertex[f], 1]).max() / mm)
          for side, f in (("left_8.3_mm", "8.3"), ("right_8.4_mm", "8.4"))}
    a, b = up.values()
    return out, {**{k: round(v, 3) for k, v in up.items()},
                 "differs": round(abs(a - b) / max(abs(a), abs(b), 1e-30), 4)}


def head_figures(workdir: Path, fast: bool, sets=()) -> dict:
    """All figures of one head (``sets``: config overrides, KEY=VALUE, in-process only)."""
    from faceforge.anatomy import tissue as fit_tissue
    from faceforge.fit.symmetry import mirror_plane

    t0 = time.perf_counter()
    head, mapping, _ = em.load_head(workdir, sets=sets)
    mm = fit_tissue.units_per_mm(head.landmarks)
    plane, es0 = mirror_plane(head.landmarks)
    partner, worst = vertex_mirror(head.rest, plane, es0)
    muscles = muscle_rows(head, partner, plane, mm)
    faps, joy = fap_rows(workdir, head, mapping, partner, plane, mm, fast)
    return {"mapping": str(mapping.source), "frames": "settled in-process" if fast else "exported PC2",
            "skin_mirror_worst_es0": round(worst, 6), "muscles": muscles, "faps": faps, "joy_corners": joy,
            "worst_muscle": max(muscles, key=lambda r: r["differs"])["name"] if muscles else None,
            "worst_fap": max(faps, key=lambda r: r["differs"])["name"],
            "seconds": round(time.perf_counter() - t0, 1)}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("workdir", type=Path, nargs="+")
    ap.add_argument("--fast", action="store_true", help="settle the FAPs and joy in-process (no export)")
    ap.add_argument("--out", default="mirror", help="results name (benchmarks/results/NAME.json)")
    ap.add_argument("--set", action="append", default=[], help="KEY=VALUE config override (with --fast)")
    args = ap.parse_args(argv)
    results = {}
    for d in args.workdir:
        r = results[d.name] = head_figures(d, args.fast, args.set)
        print(f"{d.name} ({r['frames']}, {Path(r['mapping']).name}): skin mirror worst {r['skin_mirror_worst_es0']} ES0")
        print("  muscles", " ".join(f"{m['name']} {m['differs']:.3f}" for m in r["muscles"]))
        print("  faps   ", " ".join(f"{m['name'].split()[0]} {m['differs']:.3f}" for m in r["faps"]))
        print("  joy corners", r["joy_corners"])
    write_results(args.out, {"heads": results})


if __name__ == "__main__":
    main()
