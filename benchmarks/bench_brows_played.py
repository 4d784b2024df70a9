"""The brow rows of ``bench_fap_played.py --signed`` alone (FAPs 31-38, issue 25): each brow FAP
alone at the largest magnitude of each sign the Xface files use, played by ``faceforge animate``
with the workdir's calibration and measured on the exported PC2, as bench_fap_played measures
every row (the same protocol, only fewer rows: a quarter of the time).

Usage::

    python benchmarks/bench_brows_played.py WORKDIR [WORKDIR ...]

Writes ``benchmarks/results/brows_played.json``: per head the rows (FAP, requested, achieved,
relative error) and the left/right pairs.
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import bench_fap_played as fp  # noqa: E402
from _util import workdir_args, write_results  # noqa: E402

BROWS = range(31, 39)


def main(argv=None) -> None:
    dirs = workdir_args(__doc__, argv).workdirs
    every = fp.requests
    fp.requests = lambda *a, **k: [(f, v) for f, v in every(*a, **k) if f in BROWS]
    results = {}
    try:
        for d in dirs:
            r = results[d.name] = fp.head_rows(d, 1.0, signed=True)
            r.pop("chin_path", None)
            print(f"{d.name}: median {r['median_error']:.1%}, {r['within_10_percent']}/{r['count']} within 10 %, "
                  f"{r['over_30_percent']} over 30 %")
            for row in r["rows"]:
                print(f"  {row['fap']:3d} {row['requested']:7.1f} -> {row['achieved']:7.2f}  "
                      f"{row['relative_error']:.1%}")
            for p in r["left_right"]:
                print(f"  L/R {p['faps']} sign {p['sign']:+d}: {p['left']} / {p['right']} differ {p['differs']:.1%}")
    finally:
        fp.requests = every
    write_results("brows_played", {"heads": results})


if __name__ == "__main__":
    main()
