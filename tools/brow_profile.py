"""Where a brow unit's solved field misses the MakeHuman unit, by height (issue 25 item 2).

Run::

    python benchmarks/bench_units.py --workdir W --fields fields.npz [--brows --local 0]
    python tools/brow_profile.py fields.npz W [UNIT ...]

For each unit (default: the left brow units in the file) prints the vertical profile of the unit
and of the solved field (mm; the front vertices within 3 mm of FDP 4.1 / 4.3 / 4.5's x, in 5 mm
bins of height over the FDP: mean |d|, dy, dz), then the residual at the solved field's best scale
by height band (upper lids -25..-5 mm, brow -5..+25, forehead above; heights over the lowest of the
three FDPs), split into the unit's support (vertices moving over 5 % of its peak) and off it, then
linear what-ifs: the cosine of the best non-negative combination of the Jacobian's columns with
them zeroed on the lids (the eyes' FDP group below the brow line), above +25 / +35 mm, or everywhere off the unit's support (a region held
still). The notes: docs/notes/brows15.md. Not a test.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
UNITS = ROOT / "tests" / "data" / "mh_head_expression_units_caucasian.npz"
BROW = ("4.1", "4.3", "4.5")


def cosine_nnls(J: np.ndarray, y: np.ndarray) -> float:
    """Cosine of the best non-negative combination of the columns of J (n, 3, q) with y (n, 3)."""
    from scipy.optimize import nnls

    A = J.reshape(-1, J.shape[-1])
    x, _ = nnls(A, y.ravel())
    r = A @ x
    n = float(np.linalg.norm(r))
    return float(r @ y.ravel()) / (n * float(np.linalg.norm(y))) if n > 0 else 0.0


def main(argv=None) -> None:
    import yaml

    from faceforge.anatomy.tissue import units_per_mm

    args = list(sys.argv[1:] if argv is None else argv)
    f = np.load(args[0])
    marks = yaml.safe_load(open(Path(args[1]) / "landmarks" / "landmarks.fdp.yaml"))["landmarks"]
    pos = {k: np.asarray(v["position"], float) for k, v in marks.items() if v.get("position") is not None}
    mm = units_per_mm(pos)
    units = np.load(UNITS)
    names = [str(n) for n in units["names"]]
    solved = [str(n) for n in f["names"]]
    P = f["user_rest"]
    J = f["J"].reshape(len(P), 3, -1)
    sys.path.insert(0, str(ROOT / "tools"))
    from units_residuals import fdp_groups

    h = (P[:, 1] - min(pos[k][1] for k in BROW)) / mm
    lids = (h >= -25) & (h < -5)
    eyes = (fdp_groups(P, marks) == "3") & (h < 0)   # the what-ifs' lids, as units_residuals.py's
    for name in args[2:] or [n for n in solved if n.startswith("eyebrows-left")]:
        Y = units["deltas"][names.index(name)].astype(float)
        F = f["solved"][solved.index(name)]
        print(f"{name}: cosine {(F * Y).sum() / np.linalg.norm(F) / np.linalg.norm(Y):.3f}, "
              f"ratio {np.linalg.norm(F) / np.linalg.norm(Y):.3f}")
        for fdp in BROW:
            p = pos[fdp]
            col = (np.abs(P[:, 0] - p[0]) < 3 * mm) & (P[:, 2] > p[2] - 15 * mm)
            hc = (P[:, 1] - p[1]) / mm
            print(f"  over FDP {fdp} (mm over it: n, |unit| |solved|, dy unit solved, dz unit solved; mm)")
            for a in np.arange(-30, 60, 5.0):
                q = col & (hc >= a) & (hc < a + 5)
                if q.any():
                    m = [np.linalg.norm(Y[q], axis=1).mean(), np.linalg.norm(F[q], axis=1).mean(),
                         Y[q, 1].mean(), F[q, 1].mean(), Y[q, 2].mean(), F[q, 2].mean()]
                    print("    %+4.0f %3d  %5.2f %5.2f  %+5.2f %+5.2f  %+5.2f %+5.2f" % (a, q.sum(), *np.array(m) / mm))
        s = (F * Y).sum() / (F * F).sum()
        R, E = s * F - Y, float((Y * Y).sum())
        sup = np.linalg.norm(Y, axis=1) > 0.05 * np.linalg.norm(Y, axis=1).max()
        bands = (("lids", lids), ("brow", (h >= -5) & (h < 25)), ("forehead", h >= 25), ("below", h < -25))
        print(f"  residual at x{s:.2f} {np.sum(R ** 2) / E:.3f}, on / off the support ({sup.sum()} v): "
              + "; ".join(f"{b} {np.sum(R[q & sup] ** 2) / E:.3f} / {np.sum(R[q & ~sup] ** 2) / E:.3f}"
                          for b, q in bands))
        ifs = []
        for label, z in (("as is", np.zeros(len(P), bool)), ("lids held", eyes), ("above +25 held", h > 25),
                         ("above +35 held", h > 35), ("off the support held", ~sup)):
            Jz = J.copy()
            Jz[z] = 0.0
            ifs.append(f"{label} {cosine_nnls(Jz, Y):.3f}")
        print("  linear: " + "; ".join(ifs))


if __name__ == "__main__":
    main()
