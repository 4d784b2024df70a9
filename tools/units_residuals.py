"""Where a unit's solved field differs from the MakeHuman unit (issue 25 item 2).

Run::

    python benchmarks/bench_units.py --workdir W --fields fields.npz
    python tools/units_residuals.py fields.npz W [UNIT ...]

For each unit (default: every unit in the file) prints, per region of the face (the vertices
nearest each FDP group: 2 chin and inner lips, 3 eyes and lids, 4 brows, 5 cheeks, 8 outer lips,
9 nose, 10 ears, 11 head), the share of the unit's energy ``sum |d|^2`` there, the solved field's
and the residual's (each over the unit's total), the residual split into x / y / z (user frame:
x the subject's left, y up, z forward). Then the linear what-if: the best non-negative fit of
the Jacobian's muscle columns to the unit (the projection the solve starts from) with every
column as bound, and with the columns zeroed on the lids and canthi (FDP group 3 below the
lowest brow FDP): how much the lid skin that moves with the brow costs. Also the outer lips (FDP 8)
by thirds of the mouth's width (the gain ``F.Y / Y.Y`` there), and each control the solve used:
its field ``J_j x_j``'s energy, the share of it where the unit hardly moves, and ``Y.(J_j x_j)``.
Not a test.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
UNITS = ROOT / "tests" / "data" / "mh_head_expression_units_caucasian.npz"


def fdp_groups(points: np.ndarray, landmarks: dict) -> np.ndarray:
    """(n,) str: the FDP group ("2", "3", ...) of the landmark nearest each point (n, 3)."""
    from scipy.spatial import cKDTree

    keys = [k for k, v in landmarks.items() if v.get("position") is not None]
    pts = np.array([landmarks[k]["position"] for k in keys], float)
    near = cKDTree(pts).query(points)[1]
    return np.array([keys[i].split(".")[0] for i in near])


def cosine_nnls(A: np.ndarray, y: np.ndarray) -> float:
    """Cosine of the best non-negative combination of A's columns (d, q) with y (d,)."""
    from scipy.optimize import nnls

    x, _ = nnls(A, y)
    r = A @ x
    n = float(np.linalg.norm(r))
    return float(r @ y) / (n * float(np.linalg.norm(y))) if n > 0 else 0.0


def main(argv=None) -> None:
    import yaml

    args = list(sys.argv[1:] if argv is None else argv)
    f = np.load(args[0])
    landmarks = yaml.safe_load(open(Path(args[1]) / "landmarks" / "landmarks.fdp.yaml"))["landmarks"]
    units = np.load(UNITS)
    names = [str(n) for n in units["names"]]
    solved_names = [str(n) for n in f["names"]]
    P = f["user_rest"]
    groups = fdp_groups(P, landmarks)
    controls = [str(c) for c in f["controls"]]
    muscles = [j for j, c in enumerate(controls) if not c.startswith("jaw.")]
    J = f["J"]
    brow_y = min(landmarks[k]["position"][1] for k in ("4.1", "4.3", "4.5"))
    lids = (groups == "3") & (P[:, 1] < brow_y)      # the eyes' skin below the brow line
    held = J.reshape(len(P), 3, -1).copy()
    held[lids] = 0.0
    held = held.reshape(J.shape)
    for name in args[2:] or solved_names:
        Y = units["deltas"][names.index(name)].astype(float)
        F = f["solved"][solved_names.index(name)]
        R, E = F - Y, float(np.sum(Y * Y))
        cos = float((F * Y).sum()) / (np.linalg.norm(F) * np.linalg.norm(Y))
        print(f"{name}: cosine {cos:.3f}, ratio {np.linalg.norm(F) / np.linalg.norm(Y):.3f}")
        for g in sorted(set(groups), key=int):
            q = groups == g
            parts = " ".join(f"{a} {np.sum(R[q, i] ** 2) / E:.3f}" for i, a in enumerate("xyz"))
            print(f"  FDP {g:>2s} ({q.sum():4d} v): unit {np.sum(Y[q] ** 2) / E:.3f} solved "
                  f"{np.sum(F[q] ** 2) / E:.3f} residual {np.sum(R[q] ** 2) / E:.3f} ({parts})")
        lips = groups == "8"                              # the outer lips by thirds of the mouth's width
        for lab, q in (("lips |x| < 1 cm", lips & (np.abs(P[:, 0]) < 0.1)),
                       ("lips 1-2.5 cm", lips & (np.abs(P[:, 0]) >= 0.1) & (np.abs(P[:, 0]) < 0.25)),
                       ("lips > 2.5 cm", lips & (np.abs(P[:, 0]) >= 0.25))):
            yy = float(np.sum(Y[q] ** 2))
            print(f"  {lab:15s} ({q.sum():4d} v): unit {yy / E:.3f} gain F.Y/Y.Y "
                  f"{float(np.sum(F[q] * Y[q])) / max(yy, 1e-30):.2f}, mean unit {np.round(Y[q].mean(0) * 100, 2)} "
                  f"solved {np.round(F[q].mean(0) * 100, 2)} mm (the frame is in dm)")
        if "x" in f.files:                                # each used column's share: its field J_j x_j
            x = f["x"][solved_names.index(name)]
            small = np.linalg.norm(Y, axis=1) < 0.1 * np.linalg.norm(Y, axis=1).max()
            for j in np.argsort(-np.abs(x)):
                c = (J[:, j] * x[j]).reshape(-1, 3)
                e = float(np.sum(c * c))
                if e < 1e-3 * E:
                    continue
                print(f"    {controls[j]:30s} x {x[j]:6.3f} energy {e / E:.3f}, where the unit is < 10 % of "
                      f"its peak {np.sum(c[small] ** 2) / e:.2f}, Y.c {float(np.sum(Y * c)) / E:+.3f}")
        y = Y.ravel()
        print(f"  linear: muscles {cosine_nnls(J[:, muscles], y):.3f}, lids held "
              f"{cosine_nnls(held[:, muscles], y):.3f}")


if __name__ == "__main__":
    main()
