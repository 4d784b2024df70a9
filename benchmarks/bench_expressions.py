"""Issue 25 figures on the three sample heads: open_jaw's chin path, left/right mirror
agreement, joy's two corners, and per expression the muscles used and the peak displacement
(mm) at brows, lids, cheeks, nose, mouth corners and lips.

Usage::

    python benchmarks/bench_expressions.py WORKDIR_MAKEHUMAN WORKDIR_ICT WORKDIR_MEDIAPIPE

Each WORKDIR has been fitted and bound (``faceforge --workdir W fit MESH && faceforge
--workdir W bind``); a workdir with a calibration (``faceforge calibrate``) plays it, as
``animate`` does. Poses are settled as ``faceforge expressions`` settles them. Writes
``benchmarks/results/expressions.json``.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _util import workdir_args, write_results  # noqa: E402
import expr_measure as em  # noqa: E402


def head_figures(workdir: Path) -> dict:
    """All figures of one head."""
    from faceforge.anatomy import tissue as fit_tissue
    from faceforge.fit.symmetry import mirror_plane

    t0 = time.perf_counter()
    head, mapping, _ = em.load_head(workdir)
    mm = fit_tissue.units_per_mm(head.landmarks)
    plane, _ = mirror_plane(head.landmarks)
    out = {"mapping": mapping.source, "chin_path": em.chin_path(head, mapping),
           "mirror_agreement": em.mirror_agreement(head, mapping, plane),
           "expressions": em.expression_rows(head, mapping, mm)}
    joy = np.zeros((1, 68))
    joy[0] = mapping.expressions["joy"]
    skins, _, _ = em.settle(head, mapping, joy)
    up = {side: float((skins[0, head.fdp_vertex[f], 1] - head.rest[head.fdp_vertex[f], 1]) / mm)
          for side, f in (("left_8.3", "8.3"), ("right_8.4", "8.4"))}
    out["joy_corners_up_mm"] = {**up, "ratio": min(up.values()) / max(max(up.values()), 1e-30)}
    for r in out["mirror_agreement"]:
        r["peak_left"], r["peak_right"] = round(r["peak_left"] / mm, 3), round(r["peak_right"] / mm, 3)
    out["seconds"] = round(time.perf_counter() - t0, 1)
    return out


def main(argv=None) -> None:
    dirs = workdir_args(__doc__, argv).workdirs
    results = {d.name: head_figures(d) for d in dirs}
    for name, r in results.items():
        print(name, "chin path", [(c["open_jaw"], c["down_mns"], c["back_mns"]) for c in r["chin_path"]])
        print("  mirror differs", [(m["name"], m["differs"]) for m in r["mirror_agreement"]])
        print("  joy corners", r["joy_corners_up_mm"])
        for e in r["expressions"]:
            print("  ", e["expression"], e["peak_mm"], sorted(e["muscles"]))
    write_results("expressions", {"heads": results})


if __name__ == "__main__":
    main()
