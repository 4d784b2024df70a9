"""How far does each expressive muscle move the skin where it acts? (issues 4 and 7)

Usage::

    PYTHONPATH=. python tools/probe_coupling.py WORKDIR [--c 0.5] [--frames 40] [--json OUT]

WORKDIR holds a ``fit`` and a ``bind`` stage (``faceforge --workdir WORKDIR fit MESH && ...
bind``). Prints the fraction of the face-front skin anchored to muscles (bind/report.json)
and, for every active muscle contracted alone at ``c`` (static pose: reset, hold ``frames``
frames, influence-weighted skin as ``animate`` writes it), the displacement of the FDP it
acts on along the direction it should pull, in the FAPU of that region, with the same FDP
of the other side for comparison. Real faces move ~100 MW at the lip corners, ~150 MNS at
the lips and ~100 ENS at the brows (tests/animate/test_reference_magnitudes.py).
Also counts folded muscle faces and inverted skin triangles in each pose.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

#: muscle (left or midline name) -> (FDP on the left, direction (+x = the muscle's own
#: lateral side), FAPU); the right muscle uses the mirrored FDP and direction
ACTS = {
    "zygomaticus_major": ("8.3", (1.0, 1.0, 0.0), "MW"),
    "risorius": ("8.3", (1.0, 0.0, 0.0), "MW"),
    "depressor_anguli": ("8.3", (0.0, -1.0, 0.0), "MW"),
    "levator_labii_inner": ("8.1", (0.0, 1.0, 0.0), "MNS"),
    "levator_labii_outer": ("8.5", (0.0, 1.0, 0.0), "MNS"),
    "depressor_labii_inferioris": ("8.7", (0.0, -1.0, 0.0), "MNS"),
    "mentalis": ("8.2", (0.0, 1.0, 0.0), "MNS"),
    "frontalis_inner": ("4.1", (0.0, 1.0, 0.0), "ENS"),
    "frontalis_outer": ("4.5", (0.0, 1.0, 0.0), "ENS"),
    "corrugator_supercilii": ("4.1", (-1.0, 0.0, 0.0), "ENS"),
    "orbicularis_oris": ("8.3", (-1.0, 0.0, 0.0), "MW"),
}
#: left FDP -> right FDP (MPEG-4: odd = left, even = right, within a group)
MIRROR_FDP = {"8.3": "8.4", "8.5": "8.6", "8.7": "8.8", "4.1": "4.2", "4.3": "4.4", "4.5": "4.6",
              "8.1": "8.1", "8.2": "8.2"}
#: what a real face reaches, per FAPU (for the "ok" column)
REAL = {"MW": 100.0, "MNS": 150.0, "ENS": 100.0}


def plan(muscle: str):
    """(FDP, unit direction (3,), FAPU, other-side FDP) for a muscle name, or None."""
    side = muscle[-2:] if muscle[-2:] in ("_L", "_R") else ""
    base = muscle[: -2] if side else muscle
    if base not in ACTS:
        return None
    fdp, d, unit = ACTS[base]
    d = np.asarray(d, float) / np.linalg.norm(d)
    other = MIRROR_FDP[fdp]
    if side == "_R":
        fdp, other = other, fdp
        d = d * [-1.0, 1.0, 1.0]
    return fdp, d, unit, other


def probe(workdir: Path, c: float = 0.5, frames: int = 40, muscles=None, sets=()) -> dict:
    """Coverage and per-muscle FDP displacement (see the module docstring) as a dict."""
    from faceforge.animation.checks import inverted_triangles
    from faceforge.animation.playback import static_poses
    from faceforge.io.config import load_config
    from faceforge.animation.rig import BoundHead

    cfg = load_config(sets=list(sets))
    head = BoundHead(workdir / "fit", workdir / "bind", cfg)
    report = json.loads((workdir / "bind" / "report.json").read_text())
    front = report["regions"]["face_front"]["fraction"]
    names = list(head.muscle_names)
    active = [n for n in names if head.system.muscles[n].active]
    rows = []
    for m in muscles or active:
        p = plan(m)
        if p is None:
            continue
        fdp, d, unit, other = p
        ctr = np.zeros((1, len(names)))
        ctr[0, names.index(m)] = c
        pose = static_poses(head.rig, ctr, np.zeros((1, 3)), 25.0, settle=frames)[0]
        # the muscle state of the same pose, for the fold count
        head.rig.reset()
        for _ in range(frames):
            head.system.step(dict(zip(names, ctr[0])), None, 1 / 25.0)
        folded = head.system.folded_faces()
        head.rig.reset()
        u = head.fapu.unit(unit)
        dv = pose[head.fdp_vertex[fdp]] - head.rest[head.fdp_vertex[fdp]]
        do = pose[head.fdp_vertex[other]] - head.rest[head.fdp_vertex[other]]
        d_other = d * ([-1.0, 1.0, 1.0] if other != fdp else 1.0)
        inv = int(inverted_triangles(head.rest, pose[None], head.faces).sum())
        rows.append(dict(muscle=m, fdp=fdp, fapu=unit, along=float(dv @ d / u),
                         total=float(np.linalg.norm(dv) / u), other_fdp=other,
                         other_along=float(do @ d_other / u), other_total=float(np.linalg.norm(do) / u),
                         folded_muscle_faces=int(sum(folded.values())), inverted_skin=inv))
    return dict(workdir=str(workdir), contraction=c, frames=frames,
                face_front_bound_to_muscle=float(front["muscle"]),
                face_front_bound_to_cranium=float(front["cranium"]), rows=rows)


def print_table(res: dict, out=sys.stdout) -> None:
    print(f"{res['workdir']}: face-front skin bound to muscles {100 * res['face_front_bound_to_muscle']:.1f} %"
          f" (cranium {100 * res['face_front_bound_to_cranium']:.1f} %); c = {res['contraction']}", file=out)
    print(f"{'muscle':30s} {'FDP':>4s} {'FAPU':>4s} {'along':>7s} {'|d|':>7s}   {'other':>5s} {'along':>7s}"
          f" {'|d|':>7s} {'real':>5s} {'fold':>4s} {'inv':>4s}", file=out)
    for r in res["rows"]:
        ok = "ok" if r["along"] >= REAL[r["fapu"]] else "-"
        print(f"{r['muscle']:30s} {r['fdp']:>4s} {r['fapu']:>4s} {r['along']:7.1f} {r['total']:7.1f}   "
              f"{r['other_fdp']:>5s} {r['other_along']:7.1f} {r['other_total']:7.1f} {ok:>5s} "
              f"{r['folded_muscle_faces']:4d} {r['inverted_skin']:4d}", file=out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("workdir", type=Path)
    ap.add_argument("--c", type=float, default=0.5)
    ap.add_argument("--frames", type=int, default=40)
    ap.add_argument("--muscles", nargs="*")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    res = probe(args.workdir, args.c, args.frames, args.muscles)
    print_table(res)
    if args.json:
        args.json.write_text(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
