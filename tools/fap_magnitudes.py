"""Write templates/fap_magnitudes.yaml: per FAP, the largest value of each sign that the
Xface FAP files in samples/fap/ give it (FAPU). Calibration probes up to these magnitudes
(``animate.calibrate.magnitudes``) so that what users play is what is calibrated.

Usage: python tools/fap_magnitudes.py [OUT]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def magnitudes(folder: Path) -> dict:
    """FAP number -> [largest negative value or 0, largest positive value or 0] over the files."""
    from faceforge.mpeg4 import read_fap

    out = {}
    for path in sorted(folder.glob("*.fap")):
        t = read_fap(path)
        v = np.where(t.mask, t.values, 0.0)
        for k in range(v.shape[1]):
            lo, hi = float(v[:, k].min(initial=0.0)), float(v[:, k].max(initial=0.0))
            if lo or hi:
                a, b = out.get(k + 1, (0.0, 0.0))
                out[k + 1] = (min(a, lo), max(b, hi))
    return out


def main(argv=None) -> None:
    argv = sys.argv[1:] if argv is None else argv
    out = Path(argv[0]) if argv else ROOT / "templates" / "fap_magnitudes.yaml"
    table = magnitudes(ROOT / "samples" / "fap")
    lines = ["# Largest FAP values of each sign in the Xface files of samples/fap/ (FAPU), written by",
             "# tools/fap_magnitudes.py: FAP: [most negative, most positive] (0 = that sign is never used).",
             "# Calibration probes each mapped FAP up to these magnitudes (animate.calibrate.magnitudes)."]
    lines += [f"{k}: [{lo:g}, {hi:g}]" for k, (lo, hi) in sorted(table.items())]
    out.write_text("\n".join(lines) + "\n", encoding="utf-8")
    print(f"wrote {out} ({len(table)} FAPs)")


if __name__ == "__main__":
    main()
