"""Print the cheek raiser's origin (templates/muscle_map.yaml, orbicularis_oculi_lower_L): the
infraorbital rim of the template skull as a smooth curve, resampled by arc length.

The rim's edge is found on vertical rays (along -z, every 0.1 cm from x = 2.0 to 5.3, every
0.02 cm in y): at each x, the y where the bone surface steps back the most (the face turning
into the orbit's floor). A quadratic y(x) is fitted to those edges (within 0.7 mm on the
template), moved ``OFFSET`` cm down onto the bone's forward face, its depth taken from rays and
smoothed by a cubic in x, and the curve from ``X0`` to ``X1`` resampled into ``N`` points of
equal arc length. Raw bone vertices (the template skull is coarse) or a straight line between
two points zigzag over the edge when projected.

Usage: python tools/cheek_rim.py
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
X0, X1, N, OFFSET = 2.2, 5.2, 6, 0.15


def rim_curve(offset: float = OFFSET, x0: float = X0, x1: float = X1, n: int = N) -> np.ndarray:
    """(n, 3) template-space points (cm) along the left infraorbital rim, ``offset`` below its edge."""
    import trimesh

    from faceforge.anatomy.skull import load_skull

    skull = load_skull(ROOT / "templates" / "skull")
    mesh = trimesh.Trimesh(*skull.cranium, process=False)

    def depth(xs, ys):
        o = np.stack([xs, ys, np.full_like(xs, 15.0)], 1)
        loc, ray, _ = mesh.ray.intersects_location(o, np.tile([0.0, 0.0, -1.0], (len(xs), 1)),
                                                   multiple_hits=False)
        z = np.full(len(xs), np.nan)
        z[ray] = loc[:, 2]
        return z

    xs, ys = np.arange(2.0, 5.31, 0.1), np.arange(1.0, 3.4, 0.02)
    edge = np.array([ys[np.nanargmin(np.diff(depth(np.full_like(ys, x), ys)))] for x in xs])
    c = np.polyfit(xs, edge, 2)
    xx = np.linspace(x0, x1, 200)
    yy = np.polyval(c, xx) - offset
    zz = np.polyval(np.polyfit(xx, depth(xx, yy), 3), xx)
    p = np.stack([xx, yy, zz], 1)
    arc = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))]
    t = np.linspace(0.0, arc[-1], n)
    return np.stack([np.interp(t, arc, p[:, d]) for d in range(3)], 1)


if __name__ == "__main__":
    print([[round(float(a), 2) for a in q] for q in rim_curve()])
